"""A camera frame as ROS 2 messages (msg_adapters/camera.py, issue 16), read back from the
real serialised bytes: depth and colour images, CameraInfo that projects like the renderer,
an organised cloud whose points lie on the sheet and carry its material coordinates."""
import json

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import CameraInfo, Image, PointCloud2
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore
from std_msgs.msg import Header

from paper_sim_ros.core import SheetConfig, SimulationConfig, Simulator
from paper_sim_ros.core.camera import (HIT_NOTHING, HIT_PAPER, HIT_PROBE, CameraConfig,
                                       camera_to_world, intrinsics, look_at, project, render,
                                       render_simulator, with_depth_noise)
from paper_sim_ros.core.sheet import build_flat_sheet
from paper_sim_ros.msg_adapters.camera import (PIXEL_DTYPE, camera_info, color_image,
                                               depth_image, organized_cloud)
from paper_sim_ros.headless import main as headless_main
from paper_sim_ros.rerun_logger import RerunRecorder
from paper_sim_ros.rerun_replay import read_chunks

EYE = (0.3, -0.35, 0.5)
CAMERA = CameraConfig(name='oblique', width=320, height=240, position=EYE,
                      orientation=look_at(EYE, (0.0, 0.0, 0.0)))
PROBE = (0.02, -0.03, 0.05)
PROBE_RADIUS = 0.015


def scene():
    """A 65² sheet on the table (z = 0), a probe hovering over it, seen obliquely."""
    sheet = build_flat_sheet(SheetConfig(nx=65, ny=65))
    labels = np.zeros(sheet.vertex_count, np.uint16)
    labels[::7] = 1
    colors = np.full((sheet.vertex_count, 3), 240, np.uint8)
    frame = render(CAMERA, sheet.positions, sheet.triangles, sheet.material, labels, colors,
                   np.array([PROBE]), np.array([PROBE_RADIUS]), np.array([True]), None)
    header = Header(frame_id='oblique_optical_frame')
    header.stamp.sec, header.stamp.nanosec = 12, 345
    return sheet, frame, header


def round_trip(message, kind):
    return deserialize_message(serialize_message(message), kind)


def test_images_carry_the_frame_bit_for_bit_with_one_header():
    _, frame, header = scene()
    depth = round_trip(depth_image(header, frame), Image)
    color = round_trip(color_image(header, frame), Image)
    assert (depth.encoding, depth.height, depth.width, depth.step) == ('32FC1', 240, 320, 1280)
    assert (color.encoding, color.height, color.width, color.step) == ('rgb8', 240, 320, 960)
    for image in (depth, color):
        assert image.header == header and image.is_bigendian == 0
    depth_pixels = np.frombuffer(bytes(depth.data), '<f4').reshape(240, 320)
    np.testing.assert_array_equal(depth_pixels, frame.depth)  # NaN where nothing is hit
    assert np.isnan(depth_pixels).sum() == (frame.hit == HIT_NOTHING).sum() > 0
    np.testing.assert_array_equal(
        np.frombuffer(bytes(color.data), np.uint8).reshape(240, 320, 3), frame.rgb)


def test_camera_info_projects_vertices_where_the_depth_image_sees_them():
    sheet, frame, header = scene()
    info = round_trip(camera_info(header, CAMERA), CameraInfo)
    assert info.header == header and (info.width, info.height) == (320, 240)
    assert info.distortion_model == 'plumb_bob' and list(info.d) == [0.0] * 5
    k, p = np.array(info.k).reshape(3, 3), np.array(info.p).reshape(3, 4)
    np.testing.assert_array_equal(p[:, :3], k)
    np.testing.assert_array_equal(np.array(info.r).reshape(3, 3), np.eye(3))
    # P from the message maps a vertex (in the optical frame) onto the renderer's pixel
    pixels, depth = project(CAMERA, sheet.positions)
    rotation_world_from_optical = camera_to_world(CAMERA, np.eye(3)) - np.array(EYE)
    optical = (sheet.positions - np.array(EYE)) @ rotation_world_from_optical.T
    homogeneous = np.column_stack([optical, np.ones(len(optical))]) @ p.T
    np.testing.assert_allclose(homogeneous[:, :2] / homogeneous[:, 2:], pixels, atol=1e-6)
    # at the vertex's sub-pixel position the image's depth is the vertex's: 1/depth of a
    # plane is linear in pixel coordinates, so interpolate that between the 4 pixel centres
    column, row = np.floor(pixels).astype(int).T
    inside = (column >= 0) & (column < 319) & (row >= 0) & (row < 239)
    column, row, fraction, depth = column[inside], row[inside], (pixels - np.floor(pixels))[
        inside], depth[inside]
    corners = [(row, column), (row, column + 1), (row + 1, column), (row + 1, column + 1)]
    seen = np.all([frame.hit[r, c] == HIT_PAPER for r, c in corners], axis=0)
    assert seen.sum() > 1000, seen.sum()
    inverse = [1.0 / frame.depth[r, c].astype(np.float64) for r, c in corners]
    fx, fy = fraction[:, 0], fraction[:, 1]
    interpolated = 1.0 / ((1 - fy) * ((1 - fx) * inverse[0] + fx * inverse[1])
                          + fy * ((1 - fx) * inverse[2] + fx * inverse[3]))
    np.testing.assert_allclose(interpolated[seen], depth[seen], atol=1e-4)


def test_organised_cloud_lies_on_the_sheet_with_its_material_coordinates():
    sheet, frame, header = scene()
    cloud = round_trip(organized_cloud(header, CAMERA, frame), PointCloud2)
    assert cloud.header == header and (cloud.height, cloud.width) == (240, 320)
    assert cloud.point_step == 24 and cloud.row_step == 24 * 320 and not cloud.is_dense
    assert [(f.name, f.offset) for f in cloud.fields] == [
        ('x', 0), ('y', 4), ('z', 8), ('u', 12), ('v', 16), ('label', 20), ('hit', 22)]
    points = np.frombuffer(bytes(cloud.data), PIXEL_DTYPE).reshape(240, 320)
    paper = points['hit'] == HIT_PAPER
    probe = points['hit'] == HIT_PROBE
    assert paper.sum() > 5000 and probe.sum() > 100, (paper.sum(), probe.sum())
    optical = np.stack([points['x'], points['y'], points['z']], axis=-1).astype(np.float64)
    world = camera_to_world(CAMERA, optical)
    # paper pixels: on the flat sheet, within it, at the material point they show
    np.testing.assert_allclose(world[paper][:, 2], 0.0, atol=1e-3)
    np.testing.assert_allclose(points['u'][paper], world[paper][:, 0], atol=5e-4)
    np.testing.assert_allclose(points['v'][paper], world[paper][:, 1], atol=5e-4)
    assert set(np.unique(points['label'][paper])) <= {0, 1}
    assert np.any(points['label'][paper] == 1)
    # probe pixels: on the probe's sphere, no paper ground truth
    radius = np.linalg.norm(world[probe] - np.array(PROBE), axis=1)
    np.testing.assert_allclose(radius, PROBE_RADIUS, atol=1e-3)
    assert np.isnan(points['u'][probe]).all() and (points['label'][probe] == 0).all()
    # nothing hit: NaN everywhere but hit == HIT_NOTHING
    missed = points['hit'] == HIT_NOTHING
    assert missed.any() and np.isnan(optical[missed]).all()


def test_a_recording_holds_what_the_camera_saw(tmp_path):
    """RerunRecorder.log_camera: pose, pinhole, depth and colour under paper/cameras/<name>,
    read back with Rerun's own reader, the depth bit for bit."""
    simulator = Simulator(SimulationConfig(sheet=SheetConfig(nx=17, ny=17)))
    colors = np.full((simulator.sheet.vertex_count, 3), 200, np.uint8)
    path = tmp_path / 'camera.rrd'
    recorder = RerunRecorder('test', path=str(path), cameras=('oblique',))
    frames = []
    for _ in range(3):
        simulator.step_frame()
        recorder.log_frame(simulator.time, simulator)
        frames.append(render_simulator(CAMERA, simulator, colors))
        recorder.log_camera(simulator.time, simulator, CAMERA, frames[-1])
    recorder.close()
    rows: dict[str, list] = {}
    for chunk in read_chunks(str(path)):
        if chunk.entity_path.startswith('/paper/cameras/oblique'):
            batch = chunk.to_record_batch()
            for name in batch.schema.names:
                if ':' in name:
                    rows.setdefault(f'{chunk.entity_path} {name}', []).extend(
                        batch.column(name).to_pylist())
    assert len(rows['/paper/cameras/oblique/depth DepthImage:buffer']) == 3
    assert len(rows['/paper/cameras/oblique/rgb Image:buffer']) == 3
    depth = np.frombuffer(bytes(rows['/paper/cameras/oblique/depth DepthImage:buffer'][-1][0]),
                          np.float32).reshape(CAMERA.height, CAMERA.width)
    np.testing.assert_array_equal(depth, frames[-1].depth)
    (k,) = {tuple(np.ravel(value[0])) for value in
            rows['/paper/cameras/oblique Pinhole:image_from_camera']}
    np.testing.assert_allclose(np.array(k).reshape(3, 3).T, intrinsics(CAMERA))
    (translation,) = {tuple(np.ravel(value[0])) for value in
                      rows['/paper/cameras/oblique Transform3D:translation']}
    np.testing.assert_allclose(translation, EYE)


def test_depth_noise_is_seeded_of_its_size_and_keeps_misses_nan():
    _, frame, _ = scene()
    noisy = with_depth_noise(frame, 0.002, np.random.default_rng(3))
    again = with_depth_noise(frame, 0.002, np.random.default_rng(3))
    hit = np.isfinite(frame.depth)
    np.testing.assert_array_equal(np.isfinite(noisy.depth), hit)
    np.testing.assert_array_equal(noisy.depth, again.depth)
    assert abs(float(np.std(noisy.depth[hit] - frame.depth[hit])) - 0.002) < 1e-4
    np.testing.assert_array_equal(noisy.rgb, frame.rgb)
    assert with_depth_noise(frame, 0.0, np.random.default_rng(3)) is frame
    with pytest.raises(ValueError, match='noise'):
        with_depth_noise(frame, -1.0, np.random.default_rng(3))


def test_headless_recording_holds_the_cameras_and_still_replays(tmp_path):
    """headless --rrd --camera-rate: each scenario camera under paper/cameras/<name> at the
    rate, the same depth as the bag of the same run holds, and the replay is bit-identical."""
    scenario = tmp_path / 'two_cameras.yaml'
    scenario.write_text(
        'duration: 0.3\n'
        'contact: {ground_enabled: true}\n'
        'probes: [{name: finger, radius: 0.01,\n'
        '          keyframes: [[0, 0, 0, 0.03], [0.3, 0, 0, 0.005]]}]\n'
        'cameras:\n'
        '  - {name: top, position: [0.0, 0.0, 0.5], width: 80, height: 60}\n'
        '  - {name: side, position: [0.4, 0.0, 0.1], width: 64, height: 48,\n'
        '     depth_noise_stddev: 0.001}\n')
    rrd, bag, metrics = tmp_path / 'run.rrd', tmp_path / 'bag', tmp_path / 'metrics.json'
    assert headless_main(['--scenario', str(scenario), '--grid', '9', '--rrd', str(rrd),
                          '--bag', str(bag), '--camera-rate', '10',
                          '--metrics-json', str(metrics)]) == 0
    depth_rows: dict[str, list] = {}
    for chunk in read_chunks(str(rrd)):
        if chunk.entity_path.endswith('/depth'):
            batch = chunk.to_record_batch()
            depth_rows.setdefault(chunk.entity_path, []).extend(
                batch.column('DepthImage:buffer').to_pylist())
    # 0.3 s at 10 Hz: the slots t = 0, 0.1, 0.2, 0.3
    assert {entity: len(rows) for entity, rows in depth_rows.items()} == {
        '/paper/cameras/top/depth': 4, '/paper/cameras/side/depth': 4}
    recorded = np.frombuffer(bytes(depth_rows['/paper/cameras/side/depth'][-1][0]), np.float32)
    with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        (connection,) = [c for c in reader.connections
                         if c.topic == '/paper/side/depth/image_raw']
        *_, (_, _, raw) = reader.messages(connections=[connection])
        image = reader.deserialize(raw, connection.msgtype)
    np.testing.assert_array_equal(recorded, np.frombuffer(bytes(image.data), '<f4'))
    replayed = tmp_path / 'replayed.json'
    assert headless_main(['--replay', str(rrd), '--metrics-json', str(replayed)]) == 0
    assert (json.loads(replayed.read_text())['final_positions_sha256']
            == json.loads(metrics.read_text())['final_positions_sha256'])
