#!/usr/bin/env python3
"""Render the pictures of the fractal surface and the paper appearance into docs/.

    .venv/bin/python tools/render_docs_pictures.py [--out docs]
    .venv/bin/python tools/render_docs_pictures.py --measure   # the figures in the docs

- fractal_levels.png   the fractal after 1 … 6 iterations, flat shaded (paper Fig. 9)
- fractal_pipeline.png raw heights, low-passed heights, what the filter removed, and the
                       outline after side-length restoration
- shading_levels.png   texture only, full-detail, level-2 and level-4 normals (Fig. 10)
- level_seams.png      level-4 normals: the paper's bilinear patches vs the spline used
- aged_settling.png    the aged sheet dropped on a table under the Simulator (defaults)
- aged_crumpled.png    an aged sheet after random damage, shaded through the mesh changes
- printed_page.png     an image file mapped on an aged sheet (Fig. 11); its source image
                       is written as printed_page_source.png

A small software rasteriser (numba, z-buffer, Gouraud interpolation, 3× supersampling);
no OpenGL. Everything is seeded: the pictures are reproducible.
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path
import time

from numba import njit
import numpy as np
from PIL import Image, ImageDraw, ImageFont

from paper_sim_ros.core import (AppearanceConfig, ContactConfig, SheetConfig, SimulationConfig,
                                Simulator, SolverConfig, plane_deviation)
from paper_sim_ros.core.appearance import PaperAppearance, local_frames, sample_texture
from paper_sim_ros.core.fractal import (
    aged_surface, bilinear_upsample, build_aged_sheet, fractal_height_levels, fractal_heights,
    grid_exponent, lowpass_filter, outline_area, restore_side_lengths)
from paper_sim_ros.core.sheet import grid_triangles

SUPERSAMPLE = 3
BACKGROUND = np.array([0.80, 0.82, 0.85])
FIGURE_LIGHT = (1.0, 0.4, 0.45)
"""A low light (25° above the sheet) for the shading figures, so that the relief shows."""


@njit(cache=True)
def _rasterise(screen, depth, attributes, triangles, image, zbuffer):
    """Z-buffered triangles, attributes interpolated linearly in screen space
    (orthographic camera, so this is exact)."""
    height, width = zbuffer.shape
    for t in range(triangles.shape[0]):
        a, b, c = triangles[t, 0], triangles[t, 1], triangles[t, 2]
        ax, ay = screen[a, 0], screen[a, 1]
        bx, by = screen[b, 0], screen[b, 1]
        cx, cy = screen[c, 0], screen[c, 1]
        area = (bx - ax) * (cy - ay) - (cx - ax) * (by - ay)
        if abs(area) < 1e-12:
            continue
        x0 = max(int(math.floor(min(ax, bx, cx))), 0)
        x1 = min(int(math.ceil(max(ax, bx, cx))), width - 1)
        y0 = max(int(math.floor(min(ay, by, cy))), 0)
        y1 = min(int(math.ceil(max(ay, by, cy))), height - 1)
        for py in range(y0, y1 + 1):
            for px in range(x0, x1 + 1):
                sx, sy = px + 0.5, py + 0.5
                wa = ((bx - sx) * (cy - sy) - (cx - sx) * (by - sy)) / area
                wb = ((cx - sx) * (ay - sy) - (ax - sx) * (cy - sy)) / area
                wc = 1.0 - wa - wb
                if wa < -1e-9 or wb < -1e-9 or wc < -1e-9:
                    continue
                z = wa * depth[a] + wb * depth[b] + wc * depth[c]
                if z >= zbuffer[py, px]:
                    continue
                zbuffer[py, px] = z
                for k in range(attributes.shape[1]):
                    image[py, px, k] = (wa * attributes[a, k] + wb * attributes[b, k]
                                        + wc * attributes[c, k])


def view_rotation(azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    """World → camera rotation: camera looks down at ``elevation`` from ``azimuth``."""
    az, el = math.radians(azimuth_deg), math.radians(elevation_deg)
    spin = np.array([[math.cos(az), -math.sin(az), 0.0],
                     [math.sin(az), math.cos(az), 0.0],
                     [0.0, 0.0, 1.0]])
    tilt = np.array([[1.0, 0.0, 0.0],
                     [0.0, math.sin(el), math.cos(el)],
                     [0.0, -math.cos(el), math.sin(el)]])
    # camera: x right, y up on screen, z towards the viewer
    return tilt @ spin


def render(positions: np.ndarray, triangles: np.ndarray, attributes: np.ndarray,
           size: tuple[int, int], rotation: np.ndarray, extent: float,
           centre: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Image (H, W, K) of interpolated attributes and its coverage mask (H, W), after
    supersampled rasterisation and box downsampling. ``extent``: world size of the
    shorter image side."""
    width, height = size[0] * SUPERSAMPLE, size[1] * SUPERSAMPLE
    centre = positions.mean(axis=0) if centre is None else centre
    camera = (positions - centre) @ rotation.T
    scale = min(width, height) / extent
    screen = np.empty((len(positions), 2))
    screen[:, 0] = width / 2 + camera[:, 0] * scale
    screen[:, 1] = height / 2 - camera[:, 1] * scale
    depth = -camera[:, 2]
    channels = attributes.shape[1]
    image = np.zeros((height, width, channels + 1))
    zbuffer = np.full((height, width), np.inf)
    with_coverage = np.column_stack([attributes, np.ones(len(positions))])
    _rasterise(screen, depth, with_coverage, triangles.astype(np.int64), image, zbuffer)
    image = image.reshape(size[1], SUPERSAMPLE, size[0], SUPERSAMPLE, channels + 1)
    image = image.mean(axis=(1, 3))
    coverage = image[..., -1]
    values = image[..., :-1] / np.maximum(coverage, 1e-9)[..., None]
    return values, coverage


def composite(colour: np.ndarray, coverage: np.ndarray) -> np.ndarray:
    """RGB float image over the background, as uint8."""
    blended = colour * coverage[..., None] + BACKGROUND * (1 - coverage[..., None])
    return np.clip(np.rint(255 * blended), 0, 255).astype(np.uint8)


def unshared(positions: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every triangle with its own three vertices (for flat shading)."""
    return positions[triangles].reshape(-1, 3), np.arange(triangles.size).reshape(-1, 3)


def face_light(positions: np.ndarray, triangles: np.ndarray, light: np.ndarray,
               ambient: float = 0.25) -> np.ndarray:
    corner = positions[triangles]
    normal = np.cross(corner[:, 1] - corner[:, 0], corner[:, 2] - corner[:, 0])
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    return ambient + (1 - ambient) * np.abs(normal @ (light / np.linalg.norm(light)))


def label(image: np.ndarray, text: str) -> np.ndarray:
    """The image with a caption strip above it."""
    strip = Image.new('RGB', (image.shape[1], 28), (245, 245, 245))
    ImageDraw.Draw(strip).text((8, 4), text, fill=(20, 20, 20),
                               font=ImageFont.load_default(size=18))
    return np.concatenate([np.asarray(strip), image], axis=0)


def tile(panels: list[np.ndarray], columns: int, gap: int = 6) -> np.ndarray:
    rows = math.ceil(len(panels) / columns)
    height, width = panels[0].shape[:2]
    sheet = np.full((rows * height + (rows - 1) * gap, columns * width + (columns - 1) * gap, 3),
                    255, dtype=np.uint8)
    for index, panel in enumerate(panels):
        r, c = divmod(index, columns)
        sheet[r * (height + gap):r * (height + gap) + height,
              c * (width + gap):c * (width + gap) + width] = panel
    return sheet


# ---------------------------------------------------------------------------- pictures
def fractal_levels_picture(out: Path) -> None:
    """Paper Fig. 9: the surface after 1 … 6 iterations, unfiltered, flat shaded."""
    exponent, side = 6, 0.2
    levels = fractal_height_levels(exponent, 0.025, seed=4)
    n = 2 ** exponent + 1
    coordinates = np.linspace(-side / 2, side / 2, n)
    gx, gy = np.meshgrid(coordinates, coordinates)
    triangles = grid_triangles(n, n)
    rotation = view_rotation(-30, 35)
    light = np.array([1.0, -0.5, 0.9])
    panels = []
    for iterations in range(1, 7):
        positions = np.column_stack([gx.ravel(), gy.ravel(), levels[iterations].ravel()])
        vertices, faces = unshared(positions, triangles)
        shade = np.repeat(face_light(positions, triangles, light, 0.12), 3)[:, None]
        values, coverage = render(vertices, faces, shade, (420, 360), rotation, 0.30,
                                  centre=np.zeros(3))
        colour = values * np.array([0.93, 0.93, 0.95])
        panels.append(label(composite(colour, coverage),
                            f'after {iterations} iteration{"s" if iterations > 1 else ""}'))
    Image.fromarray(tile(panels, 3)).save(out / 'fractal_levels.png', optimize=True)


def height_map(field: np.ndarray, bound: float) -> np.ndarray:
    """Diverging colour map: blue (low) – white – red (high), ±bound."""
    t = np.clip(field / bound, -1, 1)[..., None]
    low, mid, high = np.array([0.2, 0.35, 0.8]), np.array([0.97, 0.97, 0.97]), \
        np.array([0.8, 0.25, 0.2])
    colour = np.where(t < 0, mid + (low - mid) * -t, mid + (high - mid) * t)
    return np.clip(np.rint(255 * colour), 0, 255).astype(np.uint8)


def fractal_pipeline_picture(out: Path) -> None:
    """Raw heights, filtered heights, and the outline after side-length restoration."""
    config = SheetConfig()
    exponent = grid_exponent(config.nx)
    amplitude = 0.01
    raw = fractal_height_levels(exponent, amplitude, seed=0)[-1]
    filtered = lowpass_filter(raw)
    bound = np.abs(raw).max()
    size = (300, 424)
    panels = []
    span = f'±{bound * 1e3:.0f} mm'
    for field, text in ((raw, f'heights, 7 iterations ({span})'),
                        (filtered, 'low-pass filtered')):
        image = Image.fromarray(height_map(field[::-1], bound)).resize(size, Image.NEAREST)
        panels.append(label(np.asarray(image), text))
    removed = raw - filtered
    removed_bound = np.abs(removed).max()
    image = Image.fromarray(height_map(removed[::-1], removed_bound)).resize(size, Image.NEAREST)
    panels.append(label(np.asarray(image), f'removed by it (±{removed_bound * 1e3:.1f} mm)'))
    # the outline: flat rectangle vs restored sheet, in-plane shift exaggerated 20×
    grid = aged_surface(config, amplitude, None, seed=0)
    flat = restore_side_lengths(np.zeros_like(filtered), config.width, config.height)
    exaggerated = flat[..., :2] + 20.0 * (grid[..., :2] - flat[..., :2])
    picture = Image.new('RGB', size, (255, 255, 255))
    draw = ImageDraw.Draw(picture)
    scale = 0.9 * min(size[0] / config.width, size[1] / config.height)

    def to_pixels(points: np.ndarray) -> list[tuple[float, float]]:
        return [(size[0] / 2 + x * scale, size[1] / 2 - y * scale) for x, y in points]

    def border(points: np.ndarray) -> np.ndarray:
        return np.concatenate([points[0, :-1], points[:-1, -1], points[-1, :0:-1],
                               points[:0:-1, 0]])

    draw.polygon(to_pixels(border(exaggerated)), fill=(235, 232, 220), outline=(40, 40, 40))
    draw.line(to_pixels(np.vstack([border(flat[..., :2]), border(flat[..., :2])[:1]])),
              fill=(200, 30, 30), width=1)
    panels.append(label(np.asarray(picture), 'outline, shift x20 (red: flat)'))
    Image.fromarray(tile(panels, 4)).save(out / 'fractal_pipeline.png', optimize=True)


def textured_render(appearance: PaperAppearance, sheet, light: np.ndarray | None,
                    size: tuple[int, int], rotation: np.ndarray, extent: float) -> np.ndarray:
    """Per pixel: interpolated vertex light × texture at interpolated uv (paper's
    multi-texturing); ``light`` None renders the texture alone (Fig. 10 a)."""
    if light is None:
        light = np.ones(sheet.vertex_count)
    attributes = np.column_stack([light, sheet.texture_coordinates()])
    values, coverage = render(sheet.positions, sheet.triangles, attributes, size, rotation,
                              extent)
    texture = sample_texture(appearance.texture_image, values[..., 1:3].reshape(-1, 2))
    colour = values[..., :1] * texture.reshape(values.shape[0], values.shape[1], 3)
    return composite(colour, coverage)


def shading_levels_picture(out: Path) -> None:
    """Paper Fig. 10: texture only; lit with full-detail, level-2 and level-4 normals."""
    config = SheetConfig(nx=129, ny=129)
    sheet = build_aged_sheet(config, 0.01, None, seed=2)
    rotation = view_rotation(-25, 40)
    size = (460, 400)
    panels = []
    cases = (('(a) texture only', None), ('(b) full-detail normals', 16),
             ('(c) level-2 normals', 2), ('(d) level-4 normals', 4))
    for text, level in cases:
        appearance = PaperAppearance(AppearanceConfig(normal_level=level or 2,
                                                      light_direction=FIGURE_LIGHT), sheet)
        light = None if level is None else appearance.vertex_light(sheet)
        panels.append(label(textured_render(appearance, sheet, light, size, rotation, 0.30),
                            text))
    Image.fromarray(tile(panels, 2)).save(out / 'shading_levels.png', optimize=True)


def level_seams_picture(out: Path) -> None:
    """Level-4 normals from the paper's bilinear patches vs the spline of
    ``level_surface``: the patch seams show as straight lines in the light."""
    config = SheetConfig(nx=129, ny=129)
    sheet = build_aged_sheet(config, 0.01, None, seed=2)
    appearance = PaperAppearance(
        AppearanceConfig(normal_level=4, light_direction=FIGURE_LIGHT), sheet)
    grid = sheet.positions.reshape(129, 129, 3)
    stride = 2 ** (7 - 4 + 1)
    bilinear = np.stack([lowpass_filter(bilinear_upsample(grid[::stride, ::stride, axis],
                                                          stride), keep_slope=True)
                         for axis in range(3)], axis=-1).reshape(-1, 3)
    _, _, normal = local_frames(bilinear, sheet.material, sheet.triangles)
    light = np.asarray(appearance.config.light_direction, dtype=float)
    light /= np.linalg.norm(light)
    ambient = appearance.config.ambient
    flat = ambient + (1 - ambient) * light[2]
    bilinear_light = (ambient + (1 - ambient) * np.abs(normal @ light)) / flat
    rotation = view_rotation(-25, 40)
    panels = [label(textured_render(appearance, sheet, bilinear_light, (460, 400), rotation,
                                    0.30), 'level 4, bilinear patches (seams)'),
              label(textured_render(appearance, sheet, appearance.vertex_light(sheet),
                                    (460, 400), rotation, 0.30), 'level 4, spline (used)')]
    Image.fromarray(tile(panels, 2)).save(out / 'level_seams.png', optimize=True)


def settling_picture(out: Path) -> None:
    """The aged sheet dropped on a table under the Simulator (SolverConfig defaults), at
    a few moments: it lands and rests on its low points, its long waves sagging."""
    sheet_config = SheetConfig()
    sheet = build_aged_sheet(sheet_config, 0.01, None, seed=2)
    simulator = Simulator(SimulationConfig(sheet=sheet_config,
                                           contact=ContactConfig(ground_enabled=True)), sheet)
    appearance = PaperAppearance(AppearanceConfig(light_direction=FIGURE_LIGHT), sheet)
    rotation = view_rotation(-25, 12)
    panels = []
    for frame in (0, 3, 30, 180):
        while simulator.frame < frame:
            simulator.step_frame()
        current = simulator.sheet
        image = textured_render(appearance, current, appearance.vertex_light(current),
                                (420, 200), rotation, 0.16)
        panels.append(label(image, f't = {simulator.time:.2f} s, off its plane '
                                   f'{plane_deviation(current.positions) * 1e3:.2f} mm RMS'))
    Image.fromarray(tile(panels, 2)).save(out / 'aged_settling.png', optimize=True)


def crumpled_picture(out: Path) -> None:
    """An aged sheet crumpled by random damage (SPEC §4.3: breaks insert vertices) and
    relaxed without gravity: the level-2 shading is carried through every mesh change."""
    sheet_config = SheetConfig()
    sheet = build_aged_sheet(sheet_config, 0.008, None, seed=3)
    simulator = Simulator(SimulationConfig(sheet=sheet_config, solver=SolverConfig(
        gravity=(0.0, 0.0, 0.0), air_damping=3.0)), sheet)
    appearance = PaperAppearance(AppearanceConfig(light_direction=FIGURE_LIGHT),
                                 simulator.initial_sheet)
    simulator.crumple(300, 1)
    for _ in range(120):
        simulator.step_frame()
    current = simulator.sheet
    image = textured_render(appearance, current, appearance.vertex_light(current),
                            (560, 540), view_rotation(-25, 45), 0.34)
    text = (f'crumpled: {current.vertex_count - sheet.vertex_count} vertices inserted, '
            f'level-2 normals')
    Image.fromarray(label(image, text)).save(out / 'aged_crumpled.png', optimize=True)


def page_image(path: Path) -> None:
    """A printed page to map on the sheet: title, text lines and a radial figure."""
    width, height = 840, 1188
    page = Image.new('RGB', (width, height), (250, 248, 240))
    draw = ImageDraw.Draw(page)
    draw.text((70, 60), 'Folded Paper', fill=(20, 20, 60), font=ImageFont.load_default(60))
    rng = np.random.default_rng(3)
    for line in range(14):
        y = 170 + 26 * line
        end = width - 70 - (rng.uniform(0, 260) if line % 5 == 4 else 0)
        x = 70.0
        while x < end:
            word = rng.uniform(20, 80)
            draw.rectangle([x, y, min(x + word, end), y + 9], fill=(70, 70, 80))
            x += word + 10
    cx, cy, radius = width / 2, 820, 250
    for k in range(48):
        angle = 2 * math.pi * k / 48
        draw.line([cx, cy, cx + radius * math.cos(angle), cy + radius * math.sin(angle)],
                  fill=(200, 60, 40) if k % 2 else (40, 90, 180), width=4)
    draw.ellipse([cx - 80, cy - 80, cx + 80, cy + 80], fill=(250, 210, 60),
                 outline=(30, 30, 30), width=4)
    page.save(path)


def printed_page_picture(out: Path) -> None:
    """Paper Fig. 11: an image file mapped on the aged sheet, level-2 shading."""
    source = out / 'printed_page_source.png'
    page_image(source)
    config = SheetConfig(nx=129, ny=129)
    sheet = build_aged_sheet(config, 0.012, None, seed=5)
    appearance = PaperAppearance(AppearanceConfig(texture_path=str(source)), sheet)
    image = textured_render(appearance, sheet, appearance.vertex_light(sheet), (560, 620),
                            view_rotation(-20, 55), 0.36)
    Image.fromarray(label(image, 'image file on an aged sheet, level-2 normals')).save(
        out / 'printed_page.png', optimize=True)


def mean_squared_laplacian(field: np.ndarray) -> float:
    laplacian = (field[2:, 1:-1] + field[:-2, 1:-1] + field[1:-1, 2:] + field[1:-1, :-2]
                 - 4.0 * field[1:-1, 1:-1])
    return float(np.mean(laplacian ** 2))


def measure() -> None:
    """Print the figures quoted in docs/fractal_and_appearance.md."""
    config = SheetConfig()
    cell_x = config.width / (config.nx - 1)
    seeds = range(10)
    for amplitude in (0.005, 0.01, 0.02):
        shrink, edge_error, span = [], [], []
        for seed in seeds:
            grid = aged_surface(config, amplitude, None, seed)
            shrink.append(100 * (1 - outline_area(grid) / (config.width * config.height)))
            along_x = np.linalg.norm(np.diff(grid, axis=1), axis=2) / cell_x
            edge_error.append(100 * np.abs(along_x - 1).max())
            span.append(1e3 * np.ptp(grid[..., 2]))
        print(f'd_max {amplitude * 1e3:4.0f} mm: height range {np.mean(span):5.1f} mm, outline '
              f'area -{np.mean(shrink):.2f} % ({min(shrink):.2f} .. {max(shrink):.2f}), '
              f'worst x-edge error {max(edge_error):.3f} %')
    ratios = [mean_squared_laplacian(lowpass_filter(fractal_heights(6, 0.01, seed)))
              / mean_squared_laplacian(fractal_heights(6, 0.01, seed)) for seed in seeds]
    print(f'Laplacian energy filtered / raw: {np.mean(ratios):.3f} '
          f'({min(ratios):.3f} .. {max(ratios):.3f})')
    for side in (65, 129):
        sheet = build_aged_sheet(SheetConfig(nx=side, ny=side), 0.01, None, 1)
        start = time.perf_counter()
        appearance = PaperAppearance(AppearanceConfig(), sheet)
        built = time.perf_counter() - start
        appearance.vertex_colors(sheet)
        batches = []
        for _ in range(30):
            start = time.perf_counter()
            for _ in range(10):
                appearance.vertex_colors(sheet)
            batches.append((time.perf_counter() - start) / 10)
        print(f'{side}x{side}: PaperAppearance() {built * 1e3:.0f} ms (first one includes '
              f'loading the numba cache), vertex_colors {min(batches) * 1e3:.2f} ms per frame '
              f'(best of 30 batches; median {np.median(batches) * 1e3:.2f} ms)')


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--out', type=Path,
                        default=Path(__file__).resolve().parent.parent / 'docs')
    parser.add_argument('--measure', action='store_true',
                        help='print the measured figures instead of rendering')
    args = parser.parse_args()
    if args.measure:
        measure()
        return
    args.out.mkdir(parents=True, exist_ok=True)
    fractal_levels_picture(args.out)
    fractal_pipeline_picture(args.out)
    shading_levels_picture(args.out)
    level_seams_picture(args.out)
    settling_picture(args.out)
    crumpled_picture(args.out)
    printed_page_picture(args.out)
    print(f'wrote pictures to {args.out}')


if __name__ == '__main__':
    main()
