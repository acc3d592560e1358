"""Paper appearance (SPEC §6): texture, intermediate-level normals, per-vertex colours."""
import numpy as np
from PIL import Image
import pytest

from paper_sim_ros.core import AppearanceConfig, Sheet, SheetConfig, vertex_normals
from paper_sim_ros.core.appearance import (
    FULL_DETAIL_LEVEL, MAX_TEXTURE_SIDE, PaperAppearance, catmull_rom_weights, level_surface,
    local_frames, normal_detail, procedural_paper_texture, sample_texture)
from paper_sim_ros.core.fractal import build_aged_sheet
from paper_sim_ros.core.sheet import build_flat_sheet
from paper_sim_ros.core.topology import check_mesh

SMALL = SheetConfig(nx=33, ny=33)


def rotation_matrix(axis, angle):
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def split_edge(sheet: Sheet, first: int, second: int) -> Sheet:
    """The sheet with a vertex inserted at the midpoint of an interior edge, the two
    triangles on it replaced by four (what a break does to the mesh, SPEC §4.1)."""
    grown = sheet.copy()
    middle = sheet.vertex_count
    grown.positions = np.vstack([sheet.positions,
                                 0.5 * (sheet.positions[first] + sheet.positions[second])])
    grown.velocities = np.vstack([sheet.velocities, np.zeros(3)])
    grown.material = np.vstack([sheet.material,
                                0.5 * (sheet.material[first] + sheet.material[second])])
    grown.vertex_mass = np.append(sheet.vertex_mass, 0.0)
    grown.pinned = np.append(sheet.pinned, False)
    triangles = []
    for triangle in sheet.triangles.tolist():
        if first in triangle and second in triangle:
            for old in (first, second):
                replaced = list(triangle)
                replaced[replaced.index(old)] = middle
                triangles.append(replaced)
        else:
            triangles.append(triangle)
    grown.triangles = np.asarray(triangles, dtype=np.int32)
    return grown


# ------------------------------------------------------------------------------ config
@pytest.mark.parametrize('field, value', [
    ('normal_level', 0), ('normal_level', FULL_DETAIL_LEVEL + 1), ('normal_level', 2.0),
    ('light_direction', (0.0, 0.0, 0.0)), ('light_direction', (1.0, float('nan'), 1.0)),
    ('light_direction', (1.0, 1.0)), ('ambient', -0.1), ('ambient', 1.5),
    ('texture_blend', 2.0), ('texture_seed', -1), ('texture_size', 8),
    ('texture_path', None)])
def test_invalid_configuration_is_refused_by_name(field, value):
    with pytest.raises(ValueError, match=field):
        AppearanceConfig(**{field: value})


def test_defaults_and_light_direction_from_a_parameter_list():
    config = AppearanceConfig()
    assert config.texture_path == '' and config.normal_level == 2
    from_yaml = AppearanceConfig(light_direction=[1, 0, 2])
    assert from_yaml.light_direction == (1.0, 0.0, 2.0)
    hash(from_yaml)
    with pytest.raises(ValueError, match='normal_level'):
        AppearanceConfig(normal_level=True)


# ------------------------------------------------------------------------------ texture
def test_procedural_texture_is_paper_coloured_structured_and_seeded():
    appearance = PaperAppearance(AppearanceConfig(), build_flat_sheet(SMALL))
    image = appearance.texture_image
    assert image.dtype == np.uint8 and image.ndim == 3 and image.shape[2] == 3
    # A4 aspect: 512 rows (along the 0.297 m side), 362 columns
    assert image.shape[:2] == (512, 362)
    mean = image.reshape(-1, 3).mean(axis=0)
    assert np.all(mean > 225), f'not paper-white: {mean}'
    assert mean[0] >= mean[2], 'paper is warm, not blue'
    assert 3.0 < image[..., 0].std() < 20.0, 'no visible structure, or too much'
    again = PaperAppearance(AppearanceConfig(), build_flat_sheet(SMALL)).texture_image
    np.testing.assert_array_equal(image, again)
    other = procedural_paper_texture(512, 362, seed=1)
    assert np.mean(np.abs(other.astype(int) - image.astype(int))) > 2.0
    with pytest.raises(ValueError):
        image[0, 0, 0] = 0  # read-only: every user sees the same texture


def test_texture_image_from_a_file(tmp_path):
    pixels = np.zeros((40, 30, 3), dtype=np.uint8)
    pixels[:, :15] = (200, 20, 20)
    pixels[:, 15:] = (20, 20, 200)
    path = tmp_path / 'page.png'
    Image.fromarray(pixels).save(path)
    sheet = build_flat_sheet(SMALL)
    appearance = PaperAppearance(AppearanceConfig(texture_path=str(path), ambient=1.0), sheet)
    np.testing.assert_array_equal(appearance.texture_image, pixels)
    colors = appearance.vertex_colors(sheet)
    left = sheet.material[:, 0] < -0.01
    right = sheet.material[:, 0] > 0.01
    assert np.all(colors[left, 0] > 150) and np.all(colors[left, 2] < 60)
    assert np.all(colors[right, 2] > 150) and np.all(colors[right, 0] < 60)


def test_transparent_images_lie_on_white_paper_and_huge_ones_are_scaled(tmp_path):
    sheet = build_flat_sheet(SMALL)
    rgba = np.zeros((20, 20, 4), dtype=np.uint8)
    rgba[:10] = (0, 0, 255, 255)
    path = tmp_path / 'cartoon.png'
    Image.fromarray(rgba, 'RGBA').save(path)
    image = PaperAppearance(AppearanceConfig(texture_path=str(path)), sheet).texture_image
    np.testing.assert_array_equal(image[:10], np.broadcast_to([0, 0, 255], (10, 20, 3)))
    np.testing.assert_array_equal(image[10:], 255, err_msg='transparent must show white paper')
    big = tmp_path / 'big.png'
    Image.new('RGB', (MAX_TEXTURE_SIDE * 2, 10), (9, 9, 9)).save(big)
    image = PaperAppearance(AppearanceConfig(texture_path=str(big)), sheet).texture_image
    assert image.shape[1] == MAX_TEXTURE_SIDE and np.all(image == 9)


def test_missing_or_unreadable_image_is_a_clear_error_at_construction(tmp_path):
    sheet = build_flat_sheet(SMALL)
    missing = tmp_path / 'nowhere.png'
    with pytest.raises(FileNotFoundError, match='nowhere.png'):
        PaperAppearance(AppearanceConfig(texture_path=str(missing)), sheet)
    broken = tmp_path / 'broken.png'
    broken.write_bytes(b'this is not an image')
    with pytest.raises(OSError, match='broken.png'):
        PaperAppearance(AppearanceConfig(texture_path=str(broken)), sheet)
    with pytest.raises(OSError, match='cannot be read'):
        PaperAppearance(AppearanceConfig(texture_path=str(tmp_path)), sheet)


def test_texture_sampling_is_bilinear_and_clamped():
    image = np.array([[[0, 0, 0], [255, 255, 255]]], dtype=np.uint8)
    samples = sample_texture(image, np.array([[0.0, 0.0], [0.25, 0.5], [1.0, 1.0],
                                              [-3.0, 7.0], [np.nan, 0.5]]))
    np.testing.assert_allclose(samples[:, 0], [0.0, 0.25, 1.0, 0.0, 0.0], atol=1e-6)


# ------------------------------------------------------------------------------ shading
def test_flat_sheet_gets_the_texture_unchanged_and_plain_white_without_it():
    sheet = build_flat_sheet(SMALL)
    plain = PaperAppearance(AppearanceConfig(texture_blend=0.0), sheet)
    np.testing.assert_array_equal(plain.vertex_colors(sheet), 255)
    textured = PaperAppearance(AppearanceConfig(), sheet)
    expected = np.rint(255 * sample_texture(textured.texture_image,
                                            sheet.texture_coordinates()))
    np.testing.assert_allclose(textured.vertex_colors(sheet), expected, atol=1)


def test_lighting_is_two_sided_lambert_relative_to_flat():
    sheet = build_flat_sheet(SMALL)
    config = AppearanceConfig(texture_blend=0.0, light_direction=(1.0, 0.0, 1.0), ambient=0.2)
    appearance = PaperAppearance(config, sheet)
    flat = 0.2 + 0.8 * np.sqrt(0.5)
    turned = sheet.copy()
    turned.positions = sheet.positions @ rotation_matrix((0, 1, 0), np.pi / 4).T
    # the normal turned 45° towards +x faces the light (or away from it): 1/flat or 0.2/flat
    light = appearance.vertex_light(turned)
    assert np.allclose(light, 1.0 / flat) or np.allclose(light, 0.2 / flat)
    upside_down = sheet.copy()
    upside_down.positions = sheet.positions @ rotation_matrix((1, 0, 0), np.pi).T
    np.testing.assert_allclose(appearance.vertex_light(upside_down), 1.0, atol=1e-12,
                               err_msg='the side the viewer sees must be lit alike')


def test_level_normals_shade_the_rest_sheet_and_are_smoother_than_full_detail():
    sheet = build_aged_sheet(SMALL, 0.01, None, seed=3)
    grid = sheet.positions.reshape(33, 33, 3)
    roughness = {}
    for level in (2, 4, FULL_DETAIL_LEVEL):
        appearance = PaperAppearance(AppearanceConfig(normal_level=level), sheet)
        normals = appearance.shading_normals(sheet)
        assert np.all(np.isfinite(normals))
        np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-12)
        if level == FULL_DETAIL_LEVEL:
            assert not appearance.uses_level_normals
            expected = vertex_normals(sheet.positions, sheet.triangles)
        else:
            assert appearance.uses_level_normals
            _, _, expected = local_frames(level_surface(grid, level).reshape(-1, 3),
                                          sheet.material, sheet.triangles)
        # on the rest shape the shading normals are exactly the level's normals
        np.testing.assert_allclose(normals, expected, atol=1e-9)
        field = normals.reshape(33, 33, 3)
        roughness[level] = float(np.mean(np.sum(np.diff(field, axis=0) ** 2, axis=2))
                                 + np.mean(np.sum(np.diff(field, axis=1) ** 2, axis=2)))
    # neighbouring normals differ less at lower levels (fewer high frequencies)
    assert roughness[2] < roughness[4] < roughness[FULL_DETAIL_LEVEL], roughness
    assert roughness[2] < 0.1 * roughness[FULL_DETAIL_LEVEL], roughness


def test_level_surface_keeps_the_lattice_and_linear_fields():
    weights = catmull_rom_weights(4, 8)
    np.testing.assert_allclose(weights.sum(axis=1), 1.0, atol=1e-14)
    np.testing.assert_allclose(weights[::8], np.eye(5), atol=1e-14)
    np.testing.assert_allclose(weights @ np.arange(5.0), np.arange(33) / 8, atol=1e-13)
    flat = build_flat_sheet(SMALL).positions.reshape(33, 33, 3)
    for level in range(1, 6):
        np.testing.assert_allclose(level_surface(flat, level), flat, atol=1e-14)
    with pytest.raises(ValueError):
        level_surface(flat, 6)


def test_shading_normals_turn_with_the_sheet():
    sheet = build_aged_sheet(SMALL, 0.01, None, seed=4)
    appearance = PaperAppearance(AppearanceConfig(normal_level=2), sheet)
    rotation = rotation_matrix((0.3, -1.0, 0.5), 1.1)
    moved = sheet.copy()
    moved.positions = sheet.positions @ rotation.T + np.array([0.3, -0.2, 0.5])
    np.testing.assert_allclose(appearance.shading_normals(moved),
                               appearance.shading_normals(sheet) @ rotation.T, atol=1e-9)


def test_shading_follows_a_fold():
    """Folding half the sheet over by 90° turns the level normals of that half with it."""
    sheet = build_aged_sheet(SMALL, 0.005, None, seed=5)
    appearance = PaperAppearance(AppearanceConfig(normal_level=2), sheet)
    before = appearance.shading_normals(sheet)
    folded = sheet.copy()
    right = sheet.material[:, 0] > 0.03
    rotation = rotation_matrix((0, 1, 0), -np.pi / 2)
    folded.positions[right] = sheet.positions[right] @ rotation.T
    after = appearance.shading_normals(folded)
    inner = right & (sheet.material[:, 0] > 0.05) & (np.abs(sheet.material[:, 1]) < 0.12)
    np.testing.assert_allclose(after[inner], before[inner] @ rotation.T, atol=0.02)
    left = sheet.material[:, 0] < 0.0
    np.testing.assert_allclose(after[left], before[left], atol=1e-9)


def test_normal_detail_is_the_relief_along_the_normal():
    sheet = build_flat_sheet(SMALL)
    turned = sheet.positions @ rotation_matrix((1, 1, 0), 0.7).T + 0.3
    np.testing.assert_allclose(normal_detail(turned, sheet.material, sheet.triangles), 0.0,
                               atol=1e-15)
    bumped = sheet.positions.copy()
    centre = 16 * 33 + 16
    bumped[centre, 2] += 1e-4
    detail = normal_detail(bumped, sheet.material, sheet.triangles)
    assert detail[centre] == pytest.approx(1e-4, rel=1e-3)
    bumped[5, 2] = np.nan
    assert np.all(np.isfinite(normal_detail(bumped, sheet.material, sheet.triangles)))


def test_a_sheet_pressed_flat_is_shaded_flat_not_with_its_relief_reversed():
    sheet = build_aged_sheet(SMALL, 0.01, None, seed=8)
    appearance = PaperAppearance(AppearanceConfig(normal_level=2), sheet)
    assert appearance.detail_presence(sheet) == pytest.approx(1.0, abs=1e-12)
    flat = sheet.copy()
    flat.positions[:] = build_flat_sheet(SMALL).positions
    assert appearance.detail_presence(flat) < 1e-9
    np.testing.assert_allclose(appearance.shading_normals(flat)[:, 2], 1.0, atol=1e-12)
    half = sheet.copy()
    half.positions = 0.5 * (sheet.positions + flat.positions)
    assert appearance.detail_presence(half) == pytest.approx(0.5, abs=0.05)
    turned = sheet.copy()
    turned.positions = sheet.positions @ rotation_matrix((1, 2, 3), 2.0).T
    assert appearance.detail_presence(turned) == pytest.approx(1.0, abs=1e-9)


def test_any_vertex_count_and_texture_coordinates_follow_the_material():
    sheet = build_aged_sheet(SMALL, 0.01, None, seed=6)
    appearance = PaperAppearance(AppearanceConfig(), sheet)
    before = appearance.vertex_colors(sheet)
    # break an interior edge: one more vertex, four triangles for two
    first, second = 16 * 33 + 16, 16 * 33 + 17
    grown = split_edge(sheet, first, second)
    problems = check_mesh(grown.triangles, grown.vertex_count, grown.positions,
                          grown.spring_vertices)
    # a valid mesh (only the springs of the new edges are missing: not this test's subject)
    assert all('have no spring' in problem for problem in problems), problems
    colors = appearance.vertex_colors(grown)
    assert colors.shape == (sheet.vertex_count + 1, 3) and colors.dtype == np.uint8
    # vertices away from the change keep their colour (±1: the relief presence, measured
    # over the whole sheet, moves a little with the new vertex)
    far = np.linalg.norm(sheet.material - sheet.material[first], axis=1) > 0.03
    np.testing.assert_allclose(colors[:-1][far], before[far], atol=1)
    # the new vertex looks like its neighbours
    assert np.all(np.abs(colors[-1].astype(int) - before[[first, second]].mean(axis=0)) < 12)
    # moving the sheet around does not move the texture on it
    moved = grown.copy()
    moved.positions = grown.positions + np.array([0.5, 0.1, 0.2])
    np.testing.assert_array_equal(appearance.vertex_colors(moved), colors)


def test_an_appearance_built_on_a_damaged_sheet_still_uses_level_normals():
    sheet = build_aged_sheet(SMALL, 0.01, None, seed=6)
    grown = split_edge(sheet, 16 * 33 + 16, 16 * 33 + 17)
    late = PaperAppearance(AppearanceConfig(), grown)
    early = PaperAppearance(AppearanceConfig(), sheet)
    assert late.uses_level_normals
    np.testing.assert_allclose(late.shading_normals(grown)[:-1], early.shading_normals(grown)[:-1],
                               atol=1e-9)


def test_sheets_that_are_not_fractal_grids_use_full_detail_normals():
    for config in (SheetConfig(nx=20, ny=30), SheetConfig(nx=33, ny=17)):
        sheet = build_flat_sheet(config)
        sheet.positions[:, 2] += 0.01 * np.sin(sheet.positions[:, 0] * 40)
        appearance = PaperAppearance(AppearanceConfig(), sheet)
        assert not appearance.uses_level_normals
        np.testing.assert_allclose(appearance.shading_normals(sheet),
                                   vertex_normals(sheet.positions, sheet.triangles),
                                   atol=1e-12)
        assert appearance.vertex_colors(sheet).shape == (sheet.vertex_count, 3)


def test_degenerate_or_non_finite_geometry_never_gives_nan():
    sheet = build_aged_sheet(SMALL, 0.01, None, seed=7)
    appearance = PaperAppearance(AppearanceConfig(), sheet)
    collapsed = sheet.copy()
    collapsed.positions[:] = 0.0
    broken = sheet.copy()
    broken.positions[5] = np.nan
    broken.positions[7] = np.inf
    for bad in (collapsed, broken):
        normals = appearance.shading_normals(bad)
        assert np.all(np.isfinite(normals))
        colors = appearance.vertex_colors(bad)
        assert colors.dtype == np.uint8 and colors.shape == (sheet.vertex_count, 3)
    bad_material = sheet.copy()
    bad_material.material[3] = np.nan
    assert appearance.vertex_colors(bad_material).shape == (sheet.vertex_count, 3)
    assert np.all(np.isfinite(appearance.shading_normals(bad_material)))
