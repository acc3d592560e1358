"""The fractal paper surface of SPEC §5 (paper §3.4, Fig. 9) and the "aged paper" sheet.

Three pieces, each usable on its own:

1. ``fractal_height_levels`` / ``fractal_heights``: on a ``(2^N + 1)²`` grid, iteration
   ``i = 0 … N`` draws a uniform random displacement in ``[-d_max / 2^i, d_max / 2^i]`` at
   the lattice vertices ``(k·2^(N−i), l·2^(N−i))``, ``k, l = 0 … 2^i``, interpolates it
   bilinearly in between and adds it to the height field. A loop, not a recursion.
2. ``lowpass_filter``: the paper's separable filter ``LOWPASS_TAPS`` in both directions.
3. ``restore_side_lengths``: walk the rows shifting vertices in x so that every cell edge
   is ``width / 2^N`` long again, then the columns in y (edge ``height / 2^N``). The
   outline seen from above shrinks and stops being a rectangle, as with real paper.

``build_aged_sheet`` chains them and builds a ``Sheet`` whose rest lengths are measured on
the displaced surface, so the waviness is the paper's own shape and survives simulation.

Decisions where the paper is silent (SPEC: "write the decision down next to the code"):
- "After L iterations" means iterations ``i = 0 … L−1`` were applied: L = 0 is flat, L = 1
  the four corners (one bilinear patch), L = N + 1 every vertex (full detail).
- One seeded ``numpy.random.Generator`` draws the levels in order, so the surface after L
  iterations is exactly the first L terms of the full surface (Fig. 9 is a prefix).
- The filter pads by reflection at the border (a constant field stays constant).
- The walks start at the centre row / column and go outwards, so the sheet stays centred
  on the origin and shrinks evenly from both sides (walking from one edge would pull the
  whole shrinkage onto the opposite edge).
- The column walk measures the full 3D edge (x offsets from the row walk included), so
  column edges are exact; row edges then lengthen slightly (the paper calls it negligible;
  ``test_fractal`` measures it).
- The aged sheet touches ``z = SheetConfig.elevation`` with its lowest vertex (it lies
  on a table at that height), instead of being centred on it.
- Any grid, not only ``(2^N + 1)²``: the filtered surface of the smallest such grid with at
  least as many vertices a side is sampled bilinearly at the sheet's vertices (corners on
  corners), then its side lengths are restored on the sheet's own grid. On a
  ``(2^N + 1)²`` grid nothing is resampled.
"""
from __future__ import annotations

import math

import numpy as np

from .config import SheetConfig
from .sheet import Sheet, build_flat_sheet, grid_material, grid_triangles, sheet_from_rest_shape

LOWPASS_TAPS = np.array([0.006, 0.061, 0.242, 0.382, 0.242, 0.061, 0.006])
"""The paper's separable low-pass filter (§3.4.1); its tensor product approximates a 7×7
Gaussian. Sums to 1."""

MAX_EDGE_SLOPE = math.sin(math.radians(60.0))
"""Restoration refuses cell edges whose height step exceeds this fraction of the cell
(steeper than 60°): the side-length walk would fold the grid over itself."""


def grid_exponent(vertices_per_side: int) -> int:
    """N such that ``vertices_per_side == 2^N + 1`` (N ≥ 1); ``ValueError`` otherwise."""
    n = int(vertices_per_side)
    exponent = (n - 1).bit_length() - 1
    if n != vertices_per_side or n < 3 or (1 << exponent) + 1 != n:
        raise ValueError(
            f'the fractal surface needs 2^N + 1 vertices a side (3, 5, 9, 17, 33, 65, 129, …), '
            f'got {vertices_per_side!r}')
    return exponent


def _check_levels(exponent: int, levels: int | None) -> int:
    if levels is None:
        return exponent + 1
    if not isinstance(levels, (int, np.integer)) or isinstance(levels, bool) \
            or not 0 <= levels <= exponent + 1:
        raise ValueError(f'levels must be None or an integer in [0, {exponent + 1}] '
                         f'(N + 1 = all iterations), got {levels!r}')
    return int(levels)


def _check_amplitude(amplitude: float) -> float:
    if not isinstance(amplitude, (int, float, np.floating)) or isinstance(amplitude, bool) \
            or not math.isfinite(amplitude) or amplitude < 0:
        raise ValueError(f'amplitude must be a finite number >= 0 [m], got {amplitude!r}')
    return float(amplitude)


def _check_seed(seed: int) -> int:
    # numpy would take None as "fresh entropy": refuse it, the surface must be reproducible
    if not isinstance(seed, (int, np.integer)) or isinstance(seed, bool) or seed < 0:
        raise ValueError(f'seed must be a non-negative integer, got {seed!r}')
    return int(seed)


def bilinear_upsample(lattice: np.ndarray, stride: int) -> np.ndarray:
    """Bilinear interpolation of a ``(m + 1, m + 1)`` lattice onto the ``(m·stride + 1)²``
    grid whose every ``stride``-th vertex is a lattice vertex (separable: rows, then
    columns)."""
    cells = lattice.shape[0] - 1
    if cells == 0:
        return lattice.copy()
    t = np.arange(cells * stride + 1) / stride
    k = np.minimum(t.astype(np.int64), cells - 1)
    f = t - k
    along_y = lattice[k] * (1.0 - f)[:, None] + lattice[k + 1] * f[:, None]
    return along_y[:, k] * (1.0 - f)[None, :] + along_y[:, k + 1] * f[None, :]


def level_displacement(exponent: int, iteration: int, bound: float,
                       rng: np.random.Generator) -> np.ndarray:
    """Iteration ``i`` of the construction alone: uniform draws in ``[-bound, bound]`` at the
    ``(2^i + 1)²`` lattice vertices of spacing ``2^(N−i)``, bilinear in between.
    ``(2^N + 1, 2^N + 1)`` array indexed ``[iy, ix]``."""
    if not 0 <= iteration <= exponent:
        raise ValueError(f'iteration must be in [0, {exponent}], got {iteration}')
    side = (1 << iteration) + 1
    lattice = rng.uniform(-bound, bound, size=(side, side))
    return bilinear_upsample(lattice, 1 << (exponent - iteration))


def fractal_height_levels(exponent: int, amplitude: float, seed: int,
                          levels: int | None = None) -> list[np.ndarray]:
    """The height field after 0, 1, …, ``levels`` iterations (``levels + 1`` arrays of shape
    ``(2^N + 1, 2^N + 1)``, indexed ``[iy, ix]``, in m). Entry 0 is flat; entry L is what
    Fig. 9 shows "after L iterations". ``levels=None`` runs all N + 1 iterations."""
    amplitude = _check_amplitude(amplitude)
    levels = _check_levels(exponent, levels)
    rng = np.random.default_rng(_check_seed(seed))
    side = (1 << exponent) + 1
    heights = np.zeros((side, side))
    result = [heights.copy()]
    for iteration in range(levels):
        heights = heights + level_displacement(exponent, iteration,
                                               amplitude / 2.0 ** iteration, rng)
        result.append(heights)
    return result


def fractal_heights(exponent: int, amplitude: float, seed: int,
                    levels: int | None = None) -> np.ndarray:
    """The height field after ``levels`` iterations (all N + 1 when None), unfiltered."""
    return fractal_height_levels(exponent, amplitude, seed, levels)[-1]


def lowpass_filter(field: np.ndarray, keep_slope: bool = False) -> np.ndarray:
    """The paper's separable low-pass filter applied along both axes of a 2D field, the
    border padded by reflection. A constant field is returned unchanged; with
    ``keep_slope`` the reflection is odd (mirrored through the border value), which also
    keeps a linear field (e.g. a coordinate) unchanged."""
    field = np.asarray(field, dtype=np.float64)
    radius = LOWPASS_TAPS.size // 2
    if min(field.shape) <= radius:
        raise ValueError(f'field must be larger than {radius} a side, got {field.shape}')
    result = field
    for axis in (0, 1):
        pad = [(0, 0), (0, 0)]
        pad[axis] = (radius, radius)
        padded = np.pad(result, pad, mode='reflect',
                        reflect_type='odd' if keep_slope else 'even')
        length = result.shape[axis]
        smoothed = np.zeros_like(result)
        for offset, weight in enumerate(LOWPASS_TAPS):
            window = [slice(None), slice(None)]
            window[axis] = slice(offset, offset + length)
            smoothed += weight * padded[tuple(window)]
        result = smoothed
    return result


def _walk_from_centre(steps: np.ndarray) -> np.ndarray:
    """Coordinates along axis 1 from the step lengths between neighbours, zero at the
    centre vertex: the walk goes outwards from the centre in both directions."""
    centre = steps.shape[1] // 2
    coordinates = np.zeros((steps.shape[0], steps.shape[1] + 1))
    coordinates[:, centre + 1:] = np.cumsum(steps[:, centre:], axis=1)
    coordinates[:, :centre] = -np.cumsum(steps[:, :centre][:, ::-1], axis=1)[:, ::-1]
    return coordinates


def _step_lengths(cell: float, offsets_squared: np.ndarray, what: str) -> np.ndarray:
    if np.any(offsets_squared > (MAX_EDGE_SLOPE * cell) ** 2):
        raise ValueError(f'the surface is too steep for side-length restoration along {what}: '
                         f'a cell edge rises more than {MAX_EDGE_SLOPE:.2f} of the cell '
                         f'({cell * 1e3:.2f} mm); use a smaller amplitude')
    return np.sqrt(cell * cell - offsets_squared)


def restore_side_lengths(heights: np.ndarray, width: float, height: float) -> np.ndarray:
    """Positions ``(ny, nx, 3)`` [m] of the height field with every cell edge restored to
    ``width / (nx − 1)`` along x (rows first) and then ``height / (ny − 1)`` along y
    (columns, measuring the whole 3D edge). Centred on the origin in x and y; z = heights."""
    heights = np.asarray(heights, dtype=np.float64)
    ny, nx = heights.shape
    cell_x = width / (nx - 1)
    cell_y = height / (ny - 1)
    # rows: shift in x so that |(dx, 0, dz)| = cell_x
    dz_row = np.diff(heights, axis=1)
    x = _walk_from_centre(_step_lengths(cell_x, dz_row ** 2, 'x'))
    # columns: shift in y so that |(dx, dy, dz)| = cell_y, dx from the row walk
    dx_column = np.diff(x, axis=0)
    dz_column = np.diff(heights, axis=0)
    y = _walk_from_centre(_step_lengths(cell_y, (dx_column ** 2 + dz_column ** 2).T, 'y')).T
    return np.stack([x, y, heights], axis=-1)


def resample(field: np.ndarray, rows: int, columns: int) -> np.ndarray:
    """Bilinear samples ``(rows, columns)`` of a 2-D field at evenly spaced points spanning
    it, corners on corners."""
    def weights(size: int, count: int):
        t = np.linspace(0.0, size - 1.0, count)
        k = np.minimum(t.astype(np.int64), size - 2)
        return k, t - k
    k, f = weights(field.shape[0], rows)
    along_rows = field[k] * (1.0 - f)[:, None] + field[k + 1] * f[:, None]
    k, f = weights(field.shape[1], columns)
    return along_rows[:, k] * (1.0 - f)[None, :] + along_rows[:, k + 1] * f[None, :]


def outline_area(grid_positions: np.ndarray) -> float:
    """Area [m²] of the sheet's outline seen from above: the polygon through the border
    vertices of a ``(ny, nx, 3)`` grid (shoelace formula)."""
    border = np.concatenate([
        grid_positions[0, :-1], grid_positions[:-1, -1], grid_positions[-1, :0:-1],
        grid_positions[:0:-1, 0]])
    x, y = border[:, 0], border[:, 1]
    return float(0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def aged_surface(config: SheetConfig, amplitude: float, levels: int | None,
                 seed: int) -> np.ndarray:
    """The aged-paper rest shape: ``(ny, nx, 3)`` positions [m], fractal heights after
    ``levels`` iterations, low-pass filtered, side lengths restored, lowest vertex at
    ``config.elevation``."""
    smallest = min(config.nx, config.ny)
    if smallest < LOWPASS_TAPS.size - 2:
        raise ValueError(f'the fractal surface needs at least {LOWPASS_TAPS.size - 2} '
                         f'vertices a side (the low-pass filter is {LOWPASS_TAPS.size} wide), '
                         f'got {smallest}')
    # on any other grid: the surface of the smallest (2^N + 1)² grid at least as fine,
    # sampled bilinearly at the sheet's vertices
    exponent = (max(config.nx, config.ny) - 2).bit_length()
    heights = lowpass_filter(fractal_heights(exponent, amplitude, seed, levels))
    if heights.shape != (config.ny, config.nx):
        heights = resample(heights, config.ny, config.nx)
    heights -= heights.min()
    grid = restore_side_lengths(heights, config.width, config.height)
    grid[..., 2] += config.elevation
    return grid


def build_aged_sheet(config: SheetConfig, amplitude: float, levels: int | None,
                     seed: int) -> Sheet:
    """An "aged paper" sheet (SPEC §5 a) at rest in its fractal shape: springs and masses are
    measured on the displaced surface. ``amplitude`` is d_max [m], the bound of the first
    (corner) iteration; ``levels`` the number of iterations (None: all N + 1). Amplitude 0
    (or 0 levels) gives exactly ``build_flat_sheet(config)``. On a grid other than
    (2^N + 1)², the surface of the next such grid, sampled at the sheet's vertices."""
    amplitude = _check_amplitude(amplitude)
    grid = aged_surface(config, amplitude, levels, seed)
    if amplitude == 0.0 or levels == 0:
        return build_flat_sheet(config)
    return sheet_from_rest_shape(config, grid.reshape(-1, 3), grid_material(config),
                                 grid_triangles(config.nx, config.ny))
