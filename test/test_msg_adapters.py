"""The message adapters on their own: exact layouts, round trips, never NaN."""
from __future__ import annotations

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import PointCloud2, PointField
from std_msgs.msg import Header
from visualization_msgs.msg import Marker, MarkerArray, UVCoordinate

from paper_sim_ros.core.appearance import AppearanceConfig, PaperAppearance
from paper_sim_ros.core.config import SheetConfig
from paper_sim_ros.core.sheet import (AUX, BEND, CREASED, HINGE, INSERTED, UNDAMAGED,
                                      build_flat_sheet, damage_labels)
from paper_sim_ros.core.topology import vertex_normals
from paper_sim_ros.msg_adapters.diagnostics import (diagnostic_array, diagnostic_status,
                                                    format_value, values_of)
from paper_sim_ros.msg_adapters.marker_cdr import CdrWriter, serialize_marker_array
from paper_sim_ros.msg_adapters.markers import (PROBE_NS, SPRING_NS, SURFACE_NS, MarkerStyle,
                                                colors_from_array, points_from_array,
                                                sheet_markers, sheet_markers_cdr)
from paper_sim_ros.msg_adapters.point_cloud import (POINT_DTYPE, create_cloud,
                                                    dense_surface_points, read_points,
                                                    sheet_points)

from ros_harness import parse_cloud

HEADER = Header(frame_id='world')


def bumped_sheet(nx: int = 5, ny: int = 4):
    sheet = build_flat_sheet(SheetConfig(nx=nx, ny=ny))
    rng = np.random.default_rng(3)
    sheet.positions[:, 2] += 0.01 * rng.standard_normal(sheet.vertex_count)
    return sheet


def random_points(count: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    positions = rng.normal(size=(count, 3))
    normals = rng.normal(size=(count, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    labels = rng.integers(0, 3, count).astype(np.uint16)
    material = rng.uniform(-0.1, 0.1, size=(count, 2))
    return positions, normals, labels, material


# ----------------------------------------------------------------------------- point cloud
def test_cloud_field_layout_is_exact():
    expected = [('x', 0, PointField.FLOAT32), ('y', 4, PointField.FLOAT32),
                ('z', 8, PointField.FLOAT32), ('normal_x', 12, PointField.FLOAT32),
                ('normal_y', 16, PointField.FLOAT32), ('normal_z', 20, PointField.FLOAT32),
                ('label', 24, PointField.UINT16), ('u', 28, PointField.FLOAT32),
                ('v', 32, PointField.FLOAT32)]
    cloud = create_cloud(HEADER, sheet_points(*random_points(10)))
    actual = [(field.name, field.offset, field.datatype) for field in cloud.fields]
    assert actual == expected
    assert all(field.count == 1 for field in cloud.fields)
    assert POINT_DTYPE.itemsize == 36
    assert (cloud.height, cloud.width, cloud.point_step, cloud.row_step) == (1, 10, 36, 360)
    assert cloud.is_bigendian is False and cloud.is_dense is True
    assert len(cloud.data) == 360


def test_cloud_round_trip_through_serialisation():
    positions, normals, labels, material = random_points(1000, seed=1)
    cloud = create_cloud(HEADER, sheet_points(positions, normals, labels, material))
    back = deserialize_message(serialize_message(cloud), PointCloud2)
    assert back == cloud
    parsed = parse_cloud(back)
    np.testing.assert_array_equal(np.stack([parsed['x'], parsed['y'], parsed['z']], 1),
                                  positions.astype(np.float32), err_msg='positions changed')
    np.testing.assert_array_equal(
        np.stack([parsed['normal_x'], parsed['normal_y'], parsed['normal_z']], 1),
        normals.astype(np.float32), err_msg='normals changed')
    np.testing.assert_array_equal(parsed['label'], labels, err_msg='labels changed')
    np.testing.assert_array_equal(np.stack([parsed['u'], parsed['v']], 1),
                                  material.astype(np.float32), err_msg='material changed')
    np.testing.assert_array_equal(read_points(back), parsed)


def test_cloud_of_no_points():
    cloud = create_cloud(HEADER, sheet_points(np.zeros((0, 3)), np.zeros((0, 3)),
                                              np.zeros(0, np.uint16), np.zeros((0, 2))))
    assert cloud.width == 0 and len(cloud.data) == 0
    assert read_points(cloud).shape == (0,)


@pytest.mark.parametrize('bad', [np.nan, np.inf, -np.inf])
def test_cloud_refuses_non_finite_input(bad):
    positions, normals, labels, material = random_points(5)
    positions[2, 1] = bad
    with pytest.raises(ValueError, match='finite'):
        sheet_points(positions, normals, labels, material)
    positions[2, 1] = 0.0
    normals[4, 0] = bad
    with pytest.raises(ValueError, match='finite'):
        sheet_points(positions, normals, labels, material)
    normals[4, 0] = 0.0
    material[1, 1] = bad
    with pytest.raises(ValueError, match='finite'):
        sheet_points(positions, normals, labels, material)


def test_cloud_refuses_mismatched_shapes():
    positions, normals, labels, material = random_points(5)
    with pytest.raises(ValueError):
        sheet_points(positions, normals[:4], labels, material)
    with pytest.raises(ValueError):
        sheet_points(positions, normals, labels, material[:, :1])
    with pytest.raises(ValueError):
        create_cloud(HEADER, np.zeros((3, 3)))


def test_read_points_checks_the_data_size():
    cloud = create_cloud(HEADER, sheet_points(*random_points(4)))
    cloud.width = 5
    with pytest.raises(ValueError, match='size'):
        read_points(cloud)


def test_dense_sampling_is_seeded_on_the_surface_with_unit_normals():
    sheet = build_flat_sheet(SheetConfig(nx=9, ny=9))
    normals = vertex_normals(sheet.positions, sheet.triangles)
    labels = np.zeros(sheet.vertex_count, np.uint16)
    labels[10] = CREASED

    def sample(seed, noise=0.0):
        return dense_surface_points(sheet.positions, normals, labels, sheet.material,
                                    sheet.triangles, 4, noise, np.random.default_rng(seed))
    first, again, other = sample(7), sample(7), sample(8)
    assert first.shape == (4 * len(sheet.triangles),)
    assert first.tobytes() == again.tobytes(), 'same seed must give the same samples'
    assert first.tobytes() != other.tobytes()
    np.testing.assert_allclose(first['z'], 0.0, atol=1e-7, err_msg='samples left the sheet')
    assert np.all(np.abs(first['x']) <= sheet.width / 2 + 1e-6)
    assert np.all(np.abs(first['y']) <= sheet.height / 2 + 1e-6)
    length = np.sqrt(first['normal_x'] ** 2 + first['normal_y'] ** 2 + first['normal_z'] ** 2)
    np.testing.assert_allclose(length, 1.0, atol=1e-6)
    assert set(np.unique(first['label'])) == {UNDAMAGED, CREASED}
    # a flat sheet's samples are at their material coordinates
    np.testing.assert_allclose(first['u'], first['x'], atol=1e-6)
    np.testing.assert_allclose(first['v'], first['y'], atol=1e-6)
    noisy = sample(7, noise=0.002)
    assert abs(float(np.std(noisy['z'])) - 0.002) < 0.0003, 'noise not of the asked size'


def test_dense_sampling_refuses_bad_options():
    sheet = build_flat_sheet(SheetConfig(nx=3, ny=3))
    normals = vertex_normals(sheet.positions, sheet.triangles)
    labels = np.zeros(sheet.vertex_count, np.uint16)
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError):
        dense_surface_points(sheet.positions, normals, labels, sheet.material,
                             sheet.triangles, 0, 0.0, rng)
    with pytest.raises(ValueError):
        dense_surface_points(sheet.positions, normals, labels, sheet.material,
                             sheet.triangles, 2, np.nan, rng)


# ---------------------------------------------------------------------------------- labels
def test_damage_labels():
    """The labels paper/points carries (core.damage_labels)."""
    sheet = build_flat_sheet(SheetConfig(nx=4, ny=4))
    initial = sheet.vertex_count
    labels = damage_labels(initial, sheet.spring_vertices, sheet.spring_kind, initial)
    assert labels.dtype == np.uint16
    np.testing.assert_array_equal(labels, UNDAMAGED)
    # a crease between 1 and 6 and a vertex inserted by a break, itself on an AUX spring
    springs = np.vstack([sheet.spring_vertices, [[1, 6], [initial, 2]]])
    kinds = np.concatenate([sheet.spring_kind, [AUX, AUX]]).astype(np.int8)
    labels = damage_labels(initial + 1, springs, kinds, initial)
    expected = np.zeros(initial + 1, np.uint16)
    expected[[1, 2, 6]] = CREASED
    expected[initial] = INSERTED
    np.testing.assert_array_equal(labels, expected)


# --------------------------------------------------------------------------------- markers
def marker_arguments(sheet, style=MarkerStyle(), delete_all=False, probes=None,
                     header=HEADER):
    colors = PaperAppearance(AppearanceConfig(), sheet).vertex_colors(sheet)  # as the node
    centers, radii, active = probes or (np.array([[0.0, 0.0, 0.05], [1.0, 1.0, 1.0]]),
                                        np.array([0.02, 0.03]), np.array([True, False]))
    return (header, sheet.positions, sheet.triangles, colors,
            sheet.spring_vertices, sheet.spring_kind, centers, radii, active, style, delete_all)


def markers_of(sheet, style=MarkerStyle(), delete_all=False, probes=None):
    return sheet_markers(*marker_arguments(sheet, style, delete_all, probes))


def by_ns(array: MarkerArray) -> dict:
    return {(marker.ns, marker.id): marker for marker in array.markers}


def test_surface_marker_is_a_valid_triangle_list():
    sheet = bumped_sheet()
    surface = by_ns(markers_of(sheet))[(SURFACE_NS, 0)]
    assert surface.type == Marker.TRIANGLE_LIST and surface.action == Marker.ADD
    assert len(surface.points) == 3 * len(sheet.triangles)
    assert len(surface.colors) == len(surface.points), 'one colour per point'
    points = np.array([[p.x, p.y, p.z] for p in surface.points])
    np.testing.assert_array_equal(points, sheet.positions[sheet.triangles.ravel()])
    assert surface.header.frame_id == 'world'
    assert (surface.scale.x, surface.scale.y, surface.scale.z) == (1.0, 1.0, 1.0)
    for color in surface.colors:
        assert 0.0 <= min(color.r, color.g, color.b) and max(color.r, color.g, color.b) <= 1.0
        assert color.a == 1.0


def test_every_marker_is_valid_for_rviz():
    sheet = bumped_sheet()
    sheet.spring_kind[:3] = AUX
    array = markers_of(sheet, MarkerStyle(bend_springs=True))
    for marker in array.markers:
        q = marker.pose.orientation
        assert abs(q.x ** 2 + q.y ** 2 + q.z ** 2 + q.w ** 2 - 1.0) < 1e-12, marker.ns
        if marker.action != Marker.ADD:
            continue
        assert marker.scale.x > 0, marker.ns
        if marker.type in (Marker.SPHERE, Marker.TRIANGLE_LIST):
            assert marker.scale.y > 0 and marker.scale.z > 0, marker.ns
        if marker.type == Marker.LINE_LIST:
            assert len(marker.points) % 2 == 0 and len(marker.points) > 0
        values = [v for p in marker.points for v in (p.x, p.y, p.z)]
        assert np.isfinite(values).all()
        assert 0 < marker.color.a <= 1.0
    markers = by_ns(array)
    for kind in (HINGE, AUX, BEND):
        line = markers[(SPRING_NS[kind], 0)]
        count = int(np.count_nonzero(sheet.spring_kind == kind))
        assert line.type == Marker.LINE_LIST and len(line.points) == 2 * count
        ends = sheet.spring_vertices[sheet.spring_kind == kind].ravel()
        np.testing.assert_array_equal([[p.x, p.y, p.z] for p in line.points],
                                      sheet.positions[ends])
    sphere = markers[(PROBE_NS, 0)]
    assert sphere.type == Marker.SPHERE and sphere.scale.x == pytest.approx(0.04)
    assert sphere.pose.position.z == pytest.approx(0.05)
    assert markers[(PROBE_NS, 1)].action == Marker.DELETE, 'an inactive probe is deleted'


def test_namespaces_and_ids_are_stable_when_the_mesh_grows():
    sheet = bumped_sheet()
    before = [(m.ns, m.id, m.type, m.action) for m in markers_of(sheet).markers]
    grown = sheet.copy()
    # one more vertex and triangle, as a break would add
    grown.positions = np.vstack([sheet.positions, sheet.positions[:2].mean(axis=0)])
    grown.triangles = np.vstack([sheet.triangles, [[0, sheet.vertex_count, 5]]]).astype(np.int32)
    after_array = markers_of(grown)
    after = [(m.ns, m.id, m.type, m.action) for m in after_array.markers]
    assert after == before
    assert len(by_ns(after_array)[(SURFACE_NS, 0)].points) == 3 * len(grown.triangles)


def test_no_springs_of_a_kind_is_a_delete_not_an_empty_line_list():
    markers = by_ns(markers_of(bumped_sheet()))
    assert markers[(SPRING_NS[AUX], 0)].action == Marker.DELETE
    assert markers[(SPRING_NS[BEND], 0)].action == Marker.DELETE, 'bend springs off by default'


def test_delete_all_comes_first_after_reset():
    array = markers_of(bumped_sheet(), delete_all=True)
    assert array.markers[0].action == Marker.DELETEALL
    assert all(m.action != Marker.DELETEALL for m in array.markers[1:])
    assert all(m.action != Marker.DELETEALL for m in markers_of(bumped_sheet()).markers)


def test_marker_array_round_trip_through_serialisation():
    array = markers_of(bumped_sheet(), delete_all=True)
    assert deserialize_message(serialize_message(array), MarkerArray) == array


def assert_same_but_padding(ours: bytes, padding: list, reference: bytes) -> None:
    """rmw_fastrtps leaves CDR padding bytes uninitialised: compare all the others."""
    assert len(ours) == len(reference), f'{len(ours)} bytes, rclpy writes {len(reference)}'
    mask = np.ones(len(ours), dtype=bool)
    for start, end in padding:
        assert ours[start:end] == bytes(end - start), 'our padding is not zero'
        mask[start:end] = False
    mine = np.frombuffer(ours, np.uint8)[mask]
    theirs = np.frombuffer(reference, np.uint8)[mask]
    differ = np.flatnonzero(mine != theirs)
    assert differ.size == 0, \
        f'{differ.size} bytes differ, first at {np.flatnonzero(mask)[differ[0]]}'


@pytest.mark.parametrize('grid, style, delete_all, probes', [
    (3, MarkerStyle(), False, None),
    (5, MarkerStyle(bend_springs=True, hinge_springs=False), True, None),
    (9, MarkerStyle(aux_springs=False), False, (np.zeros((0, 3)), np.zeros(0),
                                                np.zeros(0, bool))),
    (17, MarkerStyle(), True, (np.ones((3, 3)), np.full(3, 0.01), np.array([0, 1, 1], bool))),
])
def test_cdr_markers_are_the_bytes_rclpy_serialises(grid, style, delete_all, probes):
    sheet = bumped_sheet(grid, grid + 1)
    sheet.spring_kind[[0, 7]] = AUX
    header = Header(frame_id='paper_frame_with_odd_length')
    header.stamp.sec, header.stamp.nanosec = 1234, 567
    arguments = marker_arguments(sheet, style, delete_all, probes, header)
    writer = CdrWriter()
    ours = sheet_markers_cdr(*arguments, writer=writer)
    message = sheet_markers(*arguments)
    assert_same_but_padding(ours, writer.padding, serialize_message(message))
    assert deserialize_message(ours, MarkerArray) == message


def test_cdr_writer_handles_every_marker_field():
    marker = Marker(ns='ns\u00e9', id=-3, type=Marker.TEXT_VIEW_FACING, text='hello',
                    texture_resource='embedded://tex', mesh_resource='package://m.dae',
                    mesh_use_embedded_materials=True, frame_locked=True)
    marker.texture.format = 'png'
    marker.texture.data = [1, 2, 3]
    marker.mesh_file.filename = 'm.dae'
    marker.mesh_file.data = [9] * 5
    marker.lifetime.sec, marker.lifetime.nanosec = 2, 5
    marker.uv_coordinates = [UVCoordinate(u=0.25, v=0.5)]
    marker.points = points_from_array(np.array([[1.0, 2.0, 3.0]]))
    marker.colors = colors_from_array(np.array([[10, 20, 30]], np.uint8))
    writer = CdrWriter()
    ours = serialize_marker_array([(marker, None, None), (Marker(), None, None)], writer)
    message = MarkerArray(markers=[marker, Marker()])
    assert_same_but_padding(ours, writer.padding, serialize_message(message))
    assert deserialize_message(ours, MarkerArray) == message


@pytest.mark.parametrize('bad', [np.nan, np.inf])
def test_cdr_markers_refuse_non_finite_positions(bad):
    sheet = bumped_sheet()
    arguments = marker_arguments(sheet)
    sheet.positions[0, 0] = bad
    with pytest.raises(ValueError, match='finite'):
        sheet_markers_cdr(*arguments)


@pytest.mark.parametrize('bad', [np.nan, np.inf])
def test_markers_refuse_non_finite_positions(bad):
    sheet = bumped_sheet()
    sheet.positions[3, 2] = bad
    colors = np.zeros((sheet.vertex_count, 3), np.uint8)
    with pytest.raises(ValueError, match='finite'):
        sheet_markers(HEADER, sheet.positions, sheet.triangles, colors, sheet.spring_vertices,
                      sheet.spring_kind, np.zeros((0, 3)), np.zeros(0), np.zeros(0, bool))


def test_markers_refuse_out_of_range_indices_and_colour_counts():
    sheet = bumped_sheet()
    with pytest.raises(ValueError, match='colour'):
        sheet_markers(HEADER, sheet.positions, sheet.triangles, np.zeros((2, 3), np.uint8),
                      sheet.spring_vertices, sheet.spring_kind, np.zeros((0, 3)), np.zeros(0),
                      np.zeros(0, bool))
    triangles = sheet.triangles.copy()
    triangles[0, 0] = sheet.vertex_count
    with pytest.raises(ValueError, match='range'):
        sheet_markers(HEADER, sheet.positions, triangles,
                      np.zeros((sheet.vertex_count, 3), np.uint8), sheet.spring_vertices,
                      sheet.spring_kind, np.zeros((0, 3)), np.zeros(0), np.zeros(0, bool))


def test_point_and_colour_lists():
    positions = np.array([[1.0, 2.0, 3.0], [-1.5, 0.0, 1e-9]])
    points = points_from_array(positions)
    assert [(p.x, p.y, p.z) for p in points] == [tuple(row) for row in positions.tolist()]
    colors = colors_from_array(np.array([[255, 0, 51]], np.uint8), alpha=0.5)
    assert (colors[0].r, colors[0].g, colors[0].a) == (1.0, 0.0, 0.5)
    assert colors[0].b == pytest.approx(0.2)
    assert colors_from_array(np.array([[np.nan, 2.0, -1.0]]))[0].r == 0.0


def test_marker_style_refuses_bad_values():
    with pytest.raises(ValueError):
        MarkerStyle(hinge_width=0.0)
    with pytest.raises(ValueError):
        MarkerStyle(aux_color=(1.0, 0.0, 0.0))


# ----------------------------------------------------------------------------- diagnostics
def test_diagnostics_round_trip():
    status = diagnostic_status('paper_sim: simulation', '/paper_sim', DiagnosticStatus.WARN,
                               'behind', {'vertices': 289, 'real_time_factor': 0.98765432,
                                          'nan_rolled_back': False, 'recording': ''})
    array = diagnostic_array(HEADER.stamp, [status])
    back = deserialize_message(serialize_message(array), type(array))
    assert back == array
    assert back.status[0].level == DiagnosticStatus.WARN
    assert values_of(back.status[0]) == {'vertices': '289', 'real_time_factor': '0.987654',
                                         'nan_rolled_back': 'false', 'recording': ''}
    assert format_value(float('nan')) == 'nan'
    with pytest.raises(ValueError):
        diagnostic_status('x', 'y', b'\x07', '', {})
