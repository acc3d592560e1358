"""The virtual camera of core/camera.py (issue 16): depth on the surface, vertices where P
puts them, material coordinates, probes and folds occluding, NaN where rays miss."""
import math

import numpy as np
import pytest

from paper_sim_ros.core import SheetConfig
from paper_sim_ros.core.camera import (HIT_NOTHING, HIT_PAPER, HIT_PROBE, HIT_TABLE,
                                       PROBE_COLOR, CameraConfig, back_project,
                                       camera_to_world, look_at, project, projection_matrix,
                                       render, world_to_camera)
from paper_sim_ros.core.sheet import build_flat_sheet

AMPLITUDE = 0.01  # m
WAVELENGTH = 0.2  # m


def surface_height(x, y):
    """The analytic height field of the bent test sheet."""
    return AMPLITUDE * np.sin(2 * np.pi * x / WAVELENGTH) * np.cos(np.pi * y / 0.297)


def bent_sheet():
    sheet = build_flat_sheet(SheetConfig(nx=65, ny=65))
    sheet.positions[:, 2] = surface_height(sheet.positions[:, 0], sheet.positions[:, 1])
    return sheet


DOWN = CameraConfig(name='down', position=(0.0, 0.0, 0.5),
                    orientation=look_at((0.0, 0.0, 0.5), (0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0)))
OBLIQUE_EYE = (0.25, -0.3, 0.3)
OBLIQUE = CameraConfig(name='oblique', position=OBLIQUE_EYE,
                       orientation=look_at(OBLIQUE_EYE, (0.0, 0.0, 0.0)))


def shoot(config, sheet, probes=((0.0, 0.0, 10.0),), radii=(0.0,), active=(False,),
          table_height=None, labels=None):
    labels = np.zeros(sheet.vertex_count, np.uint16) if labels is None else labels
    colors = np.full((sheet.vertex_count, 3), 250, np.uint8)
    return render(config, sheet.positions, sheet.triangles, sheet.material, labels, colors,
                  np.array(probes, float), np.array(radii, float), np.array(active, bool),
                  table_height)


@pytest.mark.parametrize('config', [DOWN, OBLIQUE], ids=lambda c: c.name)
def test_depth_lies_on_the_surface(config):
    sheet = bent_sheet()
    frame = shoot(config, sheet)
    paper = frame.hit == HIT_PAPER
    assert paper.sum() > 10000, f'only {paper.sum()} paper pixels'
    world = camera_to_world(config, back_project(config, frame.depth))[paper]
    np.testing.assert_allclose(world[:, 2], surface_height(world[:, 0], world[:, 1]),
                               atol=1e-3, err_msg='back-projected depth off the surface')
    # the material coordinates of a height-field sheet are its x, y
    np.testing.assert_allclose(frame.u[paper], world[:, 0], atol=2e-4, err_msg='u != x')
    np.testing.assert_allclose(frame.v[paper], world[:, 1], atol=2e-4, err_msg='v != y')


@pytest.mark.parametrize('config', [DOWN, OBLIQUE], ids=lambda c: c.name)
def test_vertices_project_where_their_depth_is(config):
    sheet = bent_sheet()
    frame = shoot(config, sheet)
    camera = world_to_camera(config, sheet.positions)
    homogeneous = np.column_stack([camera, np.ones(sheet.vertex_count)]) @ (
        projection_matrix(config).T)
    pixels, depth = homogeneous[:, :2] / homogeneous[:, 2:], camera[:, 2]
    np.testing.assert_allclose(project(config, sheet.positions)[0], pixels, atol=1e-9)
    nx = 65
    ix, iy = np.arange(sheet.vertex_count) % nx, np.arange(sheet.vertex_count) // nx
    interior = (ix > 0) & (ix < nx - 1) & (iy > 0) & (iy < nx - 1)
    column, row = np.rint(pixels[:, 0]).astype(int), np.rint(pixels[:, 1]).astype(int)
    inside = interior & (column >= 0) & (column < config.width) & (row >= 0) & (
        row < config.height)
    assert inside.sum() > 1000
    seen = frame.depth[row[inside], column[inside]]
    assert np.all(frame.hit[row[inside], column[inside]] == HIT_PAPER)
    np.testing.assert_allclose(seen, depth[inside], atol=1e-3,
                               err_msg='depth at the projected vertex != its depth')


def test_probe_occludes_the_paper():
    sheet = bent_sheet()
    frame = shoot(DOWN, sheet, probes=[(0.0, 0.0, 0.1)], radii=[0.02], active=[True])
    row, column = 240, 320  # the principal point is between pixels: look at its neighbours
    block = np.s_[row - 1:row + 1, column - 1:column + 1]
    assert np.all(frame.hit[block] == HIT_PROBE), frame.hit[block]
    np.testing.assert_allclose(frame.depth[block], 0.5 - 0.1 - 0.02, atol=1e-3)
    assert np.all(np.isnan(frame.u[block]))
    # the silhouette: a disc of the probe's angular radius, paper around it
    radius_pixels = DOWN.focal_x * math.tan(math.asin(0.02 / 0.4))
    rows, columns = np.mgrid[0:DOWN.height, 0:DOWN.width]
    distance = np.hypot(columns - DOWN.principal_x, rows - DOWN.principal_y)
    assert np.all(frame.hit[distance < radius_pixels - 1] == HIT_PROBE)
    ring = (distance > radius_pixels + 1) & (distance < radius_pixels + 5)
    assert np.all(frame.hit[ring] == HIT_PAPER)
    inactive = shoot(DOWN, sheet, probes=[(0.0, 0.0, 0.1)], radii=[0.02], active=[False])
    assert np.all(inactive.hit[block] == HIT_PAPER)


def rays_meeting_probes(config, centres, radii):
    """Per pixel, whether its ray meets one of the spheres ``centres`` (world) / ``radii``
    in front of the near plane: the ray-sphere test over every pixel, in numpy."""
    rows, columns = np.mgrid[0:config.height, 0:config.width].astype(float)
    ray_x = (columns - config.principal_x) / config.focal_x
    ray_y = (rows - config.principal_y) / config.focal_y
    ray_squared = ray_x * ray_x + ray_y * ray_y + 1.0
    met = np.zeros(rows.shape, bool)
    for centre, radius in zip(world_to_camera(config, np.array(centres, float)), radii):
        along = ray_x * centre[0] + ray_y * centre[1] + centre[2]
        discriminant = along * along - ray_squared * (centre @ centre - radius ** 2)
        root = np.sqrt(np.maximum(discriminant, 0.0))
        far = (along + root) / ray_squared
        met |= (discriminant >= 0) & (far > config.near)
    return met


@pytest.mark.parametrize('centres, radii', [
    ([(0.0, 0.0, 0.05)], [0.01]),  # in the middle of the view
    ([(0.17, -0.05, 0.02)], [0.03]),  # across the image's edge
    ([(0.25, -0.3, 0.3)], [0.05]),  # around the camera: it fills the image
    ([(0.2398, -0.2878, 0.2878)], [0.015]),  # across the near plane
    ([(0.5, -0.6, 0.6)], [0.05]),  # behind the camera
    ([(0.02, 0.02, 0.03), (0.03, 0.01, 0.05)], [0.02, 0.015]),  # overlapping
], ids=['middle', 'edge', 'around', 'near plane', 'behind', 'two'])
def test_a_probe_shows_exactly_where_rays_meet_it(centres, radii):
    """The render casts rays at a probe only over the pixels its silhouette can cover:
    every pixel whose ray meets it shows it, wherever it is about the camera."""
    sheet = build_flat_sheet(SheetConfig(nx=9, ny=9))
    sheet.positions[:, 2] -= 1.0  # out of the way, below the probes
    frame = shoot(OBLIQUE, sheet, probes=centres, radii=radii, active=[True] * len(radii))
    met = rays_meeting_probes(OBLIQUE, centres, radii)
    assert np.array_equal(frame.hit == HIT_PROBE, met), np.sum((frame.hit == HIT_PROBE) != met)
    assert np.all(np.isfinite(frame.depth[met]))
    assert np.all(frame.rgb[met] == PROBE_COLOR)


def folded_sheet(gap=0.005):
    """The flat sheet with its x > 0 half folded back over the x < 0 half, a semicircular
    hinge of diameter ``gap`` at x = 0; material x of the upper layer is pi·r − x."""
    sheet = build_flat_sheet(SheetConfig(nx=65, ny=65))
    radius = gap / 2
    x = sheet.material[:, 0]
    angle = np.clip(x / radius, 0.0, np.pi)
    positions = sheet.positions
    positions[:, 0] = np.where(x <= 0, x, np.where(x < np.pi * radius, radius * np.sin(angle),
                                                   -(x - np.pi * radius)))
    positions[:, 2] = np.where(x <= 0, 0.0, radius - radius * np.cos(angle))
    return sheet


def test_folded_flap_hides_the_layer_below():
    sheet = folded_sheet()
    labels = np.where(sheet.material[:, 0] > 0, 2, 1).astype(np.uint16)
    frame = shoot(DOWN, sheet, labels=labels)
    world = camera_to_world(DOWN, back_project(DOWN, frame.depth))
    covered = (frame.hit == HIT_PAPER) & (world[..., 0] < -0.01) & (world[..., 0] > -0.08)
    assert covered.sum() > 1000
    np.testing.assert_allclose(world[covered][:, 2], 0.005, atol=1e-3,
                               err_msg='the camera sees below the flap')
    np.testing.assert_allclose(frame.u[covered], np.pi * 0.0025 - world[covered][:, 0],
                               atol=2e-4, err_msg="not the upper layer's material")
    assert np.all(frame.label[covered] == 2)
    # the lower layer's vertices there are occluded: the image is 5 mm nearer than them
    pixels, depth = project(DOWN, sheet.positions)
    lower = (sheet.material[:, 0] < -0.02) & (sheet.material[:, 0] > -0.07)
    column, row = np.rint(pixels[lower]).astype(int).T
    np.testing.assert_allclose(depth[lower] - frame.depth[row, column], 0.005, atol=1e-3)


def test_nan_exactly_where_rays_miss():
    sheet = bent_sheet()
    wide = CameraConfig(horizontal_fov=1.2, orientation=DOWN.orientation)
    frame = shoot(wide, sheet)
    missed = frame.hit == HIT_NOTHING
    assert missed[0, 0] and missed[-1, -1] and frame.hit[240, 320] == HIT_PAPER
    np.testing.assert_array_equal(np.isnan(frame.depth), missed)
    np.testing.assert_array_equal(np.isnan(frame.u), missed)
    assert np.all(frame.rgb[missed] == 0) and np.all(frame.label[missed] == 0)
    on_table = shoot(wide, sheet, table_height=-0.02)
    assert not np.isnan(on_table.depth).any()
    np.testing.assert_array_equal(on_table.hit == HIT_TABLE, missed)
    np.testing.assert_allclose(on_table.depth[missed], 0.52, atol=1e-5)


@pytest.mark.parametrize('fields, message', [
    ({'width': 0}, 'width'),
    ({'horizontal_fov': math.pi}, 'horizontal_fov'),
    ({'horizontal_fov': float('nan')}, 'horizontal_fov'),
    ({'position': (0.0, float('inf'), 0.0)}, 'position'),
    ({'orientation': (0.0, 0.0, 0.0, float('nan'))}, 'orientation'),
    ({'orientation': (0.0, 0.0, 0.0, 0.0)}, 'orientation'),
    ({'near': 0.0}, 'near'),
])
def test_bad_config_is_refused(fields, message):
    with pytest.raises(ValueError, match=message):
        CameraConfig(**fields)


def test_look_at_refuses_a_view_along_up():
    with pytest.raises(ValueError, match='parallel to up'):
        look_at((0.0, 0.0, 1.0), (0.0, 0.0, 0.0))
