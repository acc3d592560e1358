"""Paper appearance (SPEC §6, paper §3.4.2, Fig. 10–11): per-vertex shaded, textured colours.

The surface is rendered white, lit, and blended (modulated) with a paper texture sampled
at the vertices' texture coordinates. As in the paper's Fig. 10 (c, d), the light does not
see the full-detail fractal bumps but the normals of an intermediate, low-resolution level
of the surface.

How the intermediate-level normals follow a deforming, even a damaged, sheet: at
construction the rest shape (the sheet given, on a ``(2^N + 1)²`` grid) is resampled on
the lattice of fractal level L (every ``2^(N−L+1)``-th vertex), interpolated back to the
full grid (C¹ spline, see ``level_surface``) and low-pass filtered: the surface at the
resolution of "L iterations" (the random draws themselves are not known from a ``Sheet``;
this is the same resolution, taken from the shape). Each vertex stores the level-L
normal in its own local frame (the material x direction, the normal, and their cross
product) of the full-detail rest shape, on a grid over the material. Every frame, that
stored tilt is applied to the current local frame, looked up bilinearly at each vertex's
material coordinates, so it rotates with the sheet, follows folds, and covers vertices
that damage inserts.
The tilt removes the fine relief of the rest shape from the light; where the sheet has
lost that relief (pressed flat), removing it again would paint the relief in reverse, so
the tilt is scaled by how much of the relief is still there (``detail_presence``: 1 at
rest and under rigid motion, 0 when flat).
A sheet given after damage works too: its first n² vertices are still the grid (damage
appends the vertices it inserts), and their current shape is taken as the rest shape.
On sheets that are not such a grid (or with ``normal_level`` above N), the current
full-detail normals shade.

Decisions where the paper is silent:
- Lighting is two-sided Lambert with an ambient term, ``ambient + (1 − ambient)·|n·l|``:
  paper is thin and the side the viewer sees is the side the light reaches (a flap folded
  over faces up even though its mesh normal faces down). It is divided by the brightness of
  a sheet lying flat, so flat paper keeps the texture's own white (an exposure set for
  the table) and the light only adds relief; colours above white clip.
- "Blend" is modulation (OpenGL ``GL_MODULATE``): colour = lit × texture; ``texture_blend``
  mixes the texture with white first (0: plain white paper).
- Texture rows run from the sheet's top edge (v = 0, material y = +height/2) downwards.
"""
from __future__ import annotations

from dataclasses import dataclass
import math
import os

import numpy as np
from numba import njit

from .fractal import grid_exponent, lowpass_filter
from .sheet import Sheet, grid_triangles

MAX_TEXTURE_SIDE = 4096
"""Image files with a longer side are scaled down to it when loaded (memory, and the
texture is sent to Rerun)."""

FULL_DETAIL_LEVEL = 16
"""A ``normal_level`` at least this high always shades with the full-detail normals."""


def _require(condition: bool, message: str) -> None:
    if not condition:
        raise ValueError(message)


@dataclass(frozen=True)
class AppearanceConfig:
    """How the sheet looks (SPEC §6)."""

    texture_path: str = ''
    """Image file (any format Pillow reads) mapped onto the sheet; '' for the procedural
    paper texture."""
    normal_level: int = 2
    """Fractal level (iterations) whose normals light the surface (paper Fig. 10 c: 2,
    d: 4); ``FULL_DETAIL_LEVEL`` or any value above the grid's N: full-detail normals."""
    light_direction: tuple = (0.6, 0.8, 0.7)
    """Direction towards the light (need not be unit length), in the sheet's frame."""
    ambient: float = 0.3
    """Share of the brightness that does not depend on the light, in [0, 1]."""
    texture_blend: float = 1.0
    """0: plain white paper, 1: the full texture, in between: mixed with white."""
    texture_seed: int = 0
    """Seed of the procedural texture."""
    texture_size: int = 512
    """Pixels along the longer side of the procedural texture."""

    def __post_init__(self) -> None:
        _require(isinstance(self.texture_path, str),
                 f'texture_path must be a string, got {self.texture_path!r}')
        _require(isinstance(self.normal_level, int) and not isinstance(self.normal_level, bool)
                 and 1 <= self.normal_level <= FULL_DETAIL_LEVEL,
                 f'normal_level must be an integer in [1, {FULL_DETAIL_LEVEL}], '
                 f'got {self.normal_level!r}')
        try:
            light = tuple(float(c) for c in self.light_direction)
        except (TypeError, ValueError):
            light = ()
        _require(len(light) == 3 and all(math.isfinite(c) for c in light)
                 and math.hypot(*light) > 1e-9,
                 f'light_direction must be three finite numbers, not all zero, '
                 f'got {self.light_direction!r}')
        object.__setattr__(self, 'light_direction', light)
        for name in ('ambient', 'texture_blend'):
            value = getattr(self, name)
            _require(isinstance(value, (int, float)) and math.isfinite(value)
                     and 0.0 <= value <= 1.0, f'{name} must be in [0, 1], got {value!r}')
        _require(isinstance(self.texture_seed, int) and 0 <= self.texture_seed < 2**63,
                 f'texture_seed must be a non-negative integer, got {self.texture_seed!r}')
        _require(isinstance(self.texture_size, int) and 16 <= self.texture_size <= 2048,
                 f'texture_size must be an integer in [16, 2048], got {self.texture_size!r}')


# ------------------------------------------------------------------------------ textures
def _smooth_noise(rng: np.random.Generator, rows: int, columns: int, exponent: float,
                  cutoff: float) -> np.ndarray:
    """Zero-mean, unit-deviation noise with a 1/f^exponent spectrum above ``cutoff``
    cycles per image (Fourier-filtered white noise; periodic)."""
    spectrum = np.fft.rfft2(rng.standard_normal((rows, columns)))
    fy = np.fft.fftfreq(rows)[:, None] * rows
    fx = np.fft.rfftfreq(columns)[None, :] * columns
    frequency = np.sqrt(fx * fx + fy * fy)
    spectrum *= np.where(frequency > cutoff, 1.0, 0.0) / np.maximum(frequency, 1.0) ** exponent
    field = np.fft.irfft2(spectrum, s=(rows, columns))
    return (field - field.mean()) / max(float(field.std()), 1e-12)


def _fibres(rng: np.random.Generator, rows: int, columns: int) -> np.ndarray:
    """Density of short, gently curved fibres: (rows, columns), about 1 on a fibre."""
    scale = max(rows, columns) / 512.0
    count = int(6000 * scale * scale)
    samples = 32
    length = rng.uniform(5.0, 25.0, count) * scale
    heading = rng.uniform(0.0, math.pi, count)
    bend = rng.normal(0.0, 1.0, count)
    t = np.linspace(-0.5, 0.5, samples)[None, :]
    angle = heading[:, None] + bend[:, None] * t
    step = (length / samples)[:, None]
    x = np.cumsum(step * np.cos(angle), axis=1) + rng.uniform(0, columns, count)[:, None]
    y = np.cumsum(step * np.sin(angle), axis=1) + rng.uniform(0, rows, count)[:, None]
    weight = np.repeat(rng.uniform(0.2, 1.0, count), samples)
    index = (np.mod(np.rint(y).astype(np.int64), rows) * columns
             + np.mod(np.rint(x).astype(np.int64), columns)).ravel()
    density = np.bincount(index, weights=weight, minlength=rows * columns)
    return np.minimum(density.reshape(rows, columns), 1.5)


def procedural_paper_texture(rows: int, columns: int, seed: int) -> np.ndarray:
    """A generated paper texture, (rows, columns, 3) uint8: warm off-white with the
    formation of real paper (uneven fibre density: flocs of a few mm, faint large clouds),
    scattered fibres and fine grain. Periodic, seeded, no files."""
    rng = np.random.default_rng(seed)
    flocs = _smooth_noise(rng, rows, columns, 1.0, max(rows, columns) / 24.0)
    clouds = _smooth_noise(rng, rows, columns, 2.0, 1.0)
    grain = _smooth_noise(rng, rows, columns, 0.0, 0.0)
    fibres = _fibres(rng, rows, columns)
    brightness = 1.0 + 0.018 * flocs + 0.012 * clouds + 0.008 * grain - 0.035 * fibres
    tint = np.array([0.975, 0.965, 0.935])
    image = brightness[..., None] * tint[None, None, :]
    return np.clip(np.rint(255.0 * image), 0, 255).astype(np.uint8)


def load_texture_image(path: str) -> np.ndarray:
    """An image file as (H, W, 3) uint8: transparent parts on white paper, images with a
    side longer than ``MAX_TEXTURE_SIDE`` scaled down to it. A missing file raises
    ``FileNotFoundError``, an unreadable one ``OSError``, each naming the path."""
    from PIL import Image, UnidentifiedImageError

    path = os.path.expanduser(path)
    try:
        with Image.open(path) as image:
            image.load()
            if max(image.size) > MAX_TEXTURE_SIDE:
                image.thumbnail((MAX_TEXTURE_SIDE, MAX_TEXTURE_SIDE), Image.LANCZOS)
            if 'A' in image.getbands() or 'transparency' in image.info:
                rgba = image.convert('RGBA')
                white = Image.new('RGBA', rgba.size, (255, 255, 255, 255))
                image = Image.alpha_composite(white, rgba)
            pixels = np.asarray(image.convert('RGB'), dtype=np.uint8)
    except FileNotFoundError as error:
        raise FileNotFoundError(f'texture image {path!r} does not exist') from error
    except (UnidentifiedImageError, Image.DecompressionBombError, OSError,
            ValueError) as error:
        raise OSError(f'texture image {path!r} cannot be read as an image: {error}') from error
    if pixels.ndim != 3 or pixels.shape[0] < 1 or pixels.shape[1] < 1:
        raise OSError(f'texture image {path!r} has no pixels')
    return pixels.copy()


# ------------------------------------------------------------------------------ kernels
@njit(cache=True)
def _frames_kernel(positions: np.ndarray, material: np.ndarray, triangles: np.ndarray,
                   tangent: np.ndarray, bitangent: np.ndarray, normal: np.ndarray,
                   neighbours: np.ndarray, detail: np.ndarray) -> None:
    """Fills the per-vertex frames of ``local_frames`` and the relief of ``normal_detail``
    (``tangent``, ``normal`` and ``neighbours`` (V, 4: sum of neighbour positions, count)
    zeroed by the caller): one pass over the triangles, one over the vertices."""
    for t in range(triangles.shape[0]):
        i, j, k = triangles[t, 0], triangles[t, 1], triangles[t, 2]
        e1x = positions[j, 0] - positions[i, 0]
        e1y = positions[j, 1] - positions[i, 1]
        e1z = positions[j, 2] - positions[i, 2]
        e2x = positions[k, 0] - positions[i, 0]
        e2y = positions[k, 1] - positions[i, 1]
        e2z = positions[k, 2] - positions[i, 2]
        nx = e1y * e2z - e1z * e2y
        ny = e1z * e2x - e1x * e2z
        nz = e1x * e2y - e1y * e2x
        # ∂x/∂u = (e1·d − e2·c) / det for material edges (a, c), (b, d); weighted by the
        # material area |det| / 2 the division disappears
        c = material[j, 1] - material[i, 1]
        d = material[k, 1] - material[i, 1]
        det = (material[j, 0] - material[i, 0]) * d - (material[k, 0] - material[i, 0]) * c
        w = 0.5 if det > 0.0 else -0.5
        ux = (e1x * d - e2x * c) * w
        uy = (e1y * d - e2y * c) * w
        uz = (e1z * d - e2z * c) * w
        for v in (i, j, k):
            normal[v, 0] += nx
            normal[v, 1] += ny
            normal[v, 2] += nz
            tangent[v, 0] += ux
            tangent[v, 1] += uy
            tangent[v, 2] += uz
            # the other two corners are neighbours of v: all three, minus v
            for axis in range(3):
                neighbours[v, axis] += positions[i, axis] + positions[j, axis] \
                    + positions[k, axis] - positions[v, axis]
            neighbours[v, 3] += 2.0
    for v in range(positions.shape[0]):
        nx, ny, nz = normal[v, 0], normal[v, 1], normal[v, 2]
        length = math.sqrt(nx * nx + ny * ny + nz * nz)
        if not length > 1e-30 or not length < math.inf:
            nx, ny, nz, length = 0.0, 0.0, 1.0, 1.0
        nx, ny, nz = nx / length, ny / length, nz / length
        tx, ty, tz = tangent[v, 0], tangent[v, 1], tangent[v, 2]
        along = tx * nx + ty * ny + tz * nz
        tx, ty, tz = tx - along * nx, ty - along * ny, tz - along * nz
        length = math.sqrt(tx * tx + ty * ty + tz * tz)
        if not length > 1e-30 or not length < math.inf:
            # any direction orthogonal to the normal
            if abs(nx) < 0.9:
                tx, ty, tz = 1.0 - nx * nx, -nx * ny, -nx * nz
            else:
                tx, ty, tz = -ny * nx, 1.0 - ny * ny, -ny * nz
            length = math.sqrt(tx * tx + ty * ty + tz * tz)
        tx, ty, tz = tx / length, ty / length, tz / length
        normal[v, 0], normal[v, 1], normal[v, 2] = nx, ny, nz
        tangent[v, 0], tangent[v, 1], tangent[v, 2] = tx, ty, tz
        bitangent[v, 0] = ny * tz - nz * ty
        bitangent[v, 1] = nz * tx - nx * tz
        bitangent[v, 2] = nx * ty - ny * tx
        relief = 0.0
        if neighbours[v, 3] > 0.0:
            for axis in range(3):
                relief += (positions[v, axis] - neighbours[v, axis] / neighbours[v, 3]) \
                    * normal[v, axis]
        detail[v] = relief if abs(relief) < math.inf else 0.0  # NaN and ±inf: no relief


@njit(cache=True)
def _bilinear_kernel(grid: np.ndarray, x: np.ndarray, y: np.ndarray, out: np.ndarray) -> None:
    """out[v] = grid bilinearly sampled at column x[v], row y[v] (clamped to the grid;
    NaN coordinates sample the first cell)."""
    rows, columns = grid.shape[0], grid.shape[1]
    for v in range(x.shape[0]):
        gx = min(max(x[v], 0.0), columns - 1.0) if x[v] == x[v] else 0.0
        gy = min(max(y[v], 0.0), rows - 1.0) if y[v] == y[v] else 0.0
        x0 = min(int(gx), max(columns - 2, 0))
        y0 = min(int(gy), max(rows - 2, 0))
        x1 = min(x0 + 1, columns - 1)
        y1 = min(y0 + 1, rows - 1)
        fx = gx - x0
        fy = gy - y0
        for channel in range(grid.shape[2]):
            top = grid[y0, x0, channel] * (1.0 - fx) + grid[y0, x1, channel] * fx
            bottom = grid[y1, x0, channel] * (1.0 - fx) + grid[y1, x1, channel] * fx
            out[v, channel] = top * (1.0 - fy) + bottom * fy


@njit(cache=True)
def _apply_tilt_kernel(tilt: np.ndarray, presence: float, tangent: np.ndarray,
                       bitangent: np.ndarray, normal: np.ndarray, out: np.ndarray) -> None:
    """out[v] = the tilt of vertex v (columns 0–2: components along its tangent, bitangent
    and normal), its tangential part scaled by ``presence``, in the vertex's current frame,
    normalised (the plain normal where degenerate)."""
    for v in range(tilt.shape[0]):
        a, b = presence * tilt[v, 0], presence * tilt[v, 1]
        c = math.sqrt(max(0.0, 1.0 - a * a - b * b))
        if tilt[v, 2] < 0.0:
            c = -c
        ox = a * tangent[v, 0] + b * bitangent[v, 0] + c * normal[v, 0]
        oy = a * tangent[v, 1] + b * bitangent[v, 1] + c * normal[v, 1]
        oz = a * tangent[v, 2] + b * bitangent[v, 2] + c * normal[v, 2]
        length = math.sqrt(ox * ox + oy * oy + oz * oz)
        if length > 1e-12 and length < math.inf:
            out[v, 0], out[v, 1], out[v, 2] = ox / length, oy / length, oz / length
        else:
            out[v, 0], out[v, 1], out[v, 2] = normal[v, 0], normal[v, 1], normal[v, 2]


@njit(cache=True)
def _colour_kernel(image: np.ndarray, columns: np.ndarray, rows: np.ndarray,
                   light: np.ndarray, blend: float, ambient: float, out: np.ndarray) -> None:
    """out[v] = light[v] × (blend·texel + 1 − blend) × 255, the texel bilinear at
    (columns[v], rows[v]), rounded and clamped to uint8; a non-finite light counts as
    ``ambient``."""
    texel = np.empty((1, 3))
    for v in range(light.shape[0]):
        _bilinear_kernel(image, columns[v:v + 1], rows[v:v + 1], texel)
        brightness = light[v] if abs(light[v]) < math.inf else ambient
        for channel in range(3):
            value = brightness * (blend * texel[0, channel] + (1.0 - blend) * 255.0)
            out[v, channel] = np.uint8(min(max(value + 0.5, 0.0), 255.0))


def bilinear_sample(grid: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """(V, K) float64 samples of a (rows, columns, K) grid (uint8, float32 or float64) at
    fractional column ``x`` and row ``y`` (clamped to the grid)."""
    if grid.dtype not in (np.uint8, np.float32, np.float64):
        grid = grid.astype(np.float64)
    out = np.empty((x.shape[0], grid.shape[2]))
    _bilinear_kernel(np.ascontiguousarray(grid), np.ascontiguousarray(x, dtype=np.float64),
                     np.ascontiguousarray(y, dtype=np.float64), out)
    return out


def sample_texture(image: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear samples (V, 3) in [0, 1] of a uint8 ``image`` at texture coordinates ``uv``
    (u along columns, v along rows from the top; clamped to [0, 1])."""
    rows, columns = image.shape[:2]
    uv = np.asarray(uv, dtype=np.float64)
    samples = bilinear_sample(image, uv[:, 0] * (columns - 1), uv[:, 1] * (rows - 1))
    return samples * (1.0 / 255.0)


def _frames_and_detail(positions: np.ndarray, material: np.ndarray, triangles: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    vertex_count = positions.shape[0]
    tangent, bitangent, normal = (np.zeros((vertex_count, 3)) for _ in range(3))
    detail = np.empty(vertex_count)
    _frames_kernel(np.ascontiguousarray(positions, dtype=np.float64),
                   np.ascontiguousarray(material, dtype=np.float64),
                   np.ascontiguousarray(triangles, dtype=np.int64), tangent, bitangent,
                   normal, np.zeros((vertex_count, 4)), detail)
    return tangent, bitangent, normal, detail


def local_frames(positions: np.ndarray, material: np.ndarray,
                 triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-vertex orthonormal frames ``(tangent, bitangent, normal)``, each (V, 3): the
    area-weighted normal, the material x direction (∂x/∂u of the deformation, area
    weighted) made orthogonal to it, and their cross product. Never NaN for finite input;
    a vertex without area gets +z and a tangent orthogonal to it."""
    return _frames_and_detail(positions, material, triangles)[:3]


def normal_detail(positions: np.ndarray, material: np.ndarray,
                  triangles: np.ndarray) -> np.ndarray:
    """(V,) [m]: each vertex's offset along its normal (``local_frames``) from the mean of
    its triangle neighbours — the finest relief of the surface (0 on a plane; a smooth
    bend of curvature κ adds only about κ·cell²/2). 0 where not finite."""
    return _frames_and_detail(positions, material, triangles)[3]


def _grid_side(sheet: Sheet) -> int | None:
    """n if the sheet's first n² vertices are an n × n grid (n = 2^N + 1) in
    ``grid_material`` order (vertices that damage inserted follow them), else None."""
    tolerance = 1e-9 * max(sheet.width, sheet.height)
    for exponent in range(10, 0, -1):
        side = (1 << exponent) + 1
        if side * side > sheet.vertex_count:
            continue
        gx, gy = np.meshgrid(np.linspace(-sheet.width / 2, sheet.width / 2, side),
                             np.linspace(-sheet.height / 2, sheet.height / 2, side))
        expected = np.stack([gx.ravel(), gy.ravel()], axis=1)
        if np.allclose(sheet.material[:side * side], expected, rtol=0.0, atol=tolerance):
            return side
    return None


def catmull_rom_weights(cells: int, stride: int) -> np.ndarray:
    """((cells·stride + 1), cells + 1) weights of the C¹ Catmull–Rom spline through
    ``cells + 1`` equally spaced samples, the ends extrapolated linearly (so a linear
    function is reproduced exactly)."""
    t = np.arange(cells * stride + 1) / stride
    segment = np.minimum(t.astype(np.int64), cells - 1)
    f = t - segment
    f2, f3 = f * f, f * f * f
    basis = np.stack([-0.5 * f3 + f2 - 0.5 * f, 1.5 * f3 - 2.5 * f2 + 1.0,
                      -1.5 * f3 + 2.0 * f2 + 0.5 * f, 0.5 * f3 - 0.5 * f2], axis=1)
    # samples −1 and cells + 1 are linear extrapolations of their neighbours
    extended = np.zeros((cells + 3, cells + 1))
    extended[1:-1] = np.eye(cells + 1)
    extended[0, 0], extended[0, 1] = 2.0, -1.0
    extended[-1, -1], extended[-1, -2] = 2.0, -1.0
    weights = np.zeros((t.size, cells + 1))
    for k in range(4):
        weights += basis[:, k:k + 1] * extended[segment + k]
    return weights


def level_surface(grid_positions: np.ndarray, level: int) -> np.ndarray:
    """The ``(n, n, 3)`` grid surface at the resolution of fractal level ``level``: sampled
    on the lattice of iteration ``level − 1`` (spacing ``2^(N−level+1)``), interpolated
    back with a C¹ Catmull–Rom spline and low-pass filtered (keeping linear trends at the
    border).

    Decision: the paper's intermediate surface is bilinear between the lattice vertices,
    but the seams of bilinear patches show in the shading as straight light/dark lines
    along the lattice (rendered for comparison by tools/render_docs_pictures.py); the
    spline keeps the level's resolution without the seams."""
    exponent = grid_exponent(grid_positions.shape[0])
    if not 1 <= level <= exponent:
        raise ValueError(f'level must be in [1, {exponent}], got {level}')
    stride = 1 << (exponent - level + 1)
    coarse = grid_positions[::stride, ::stride]
    weights = catmull_rom_weights(coarse.shape[0] - 1, stride)
    return np.stack([lowpass_filter(weights @ coarse[..., axis] @ weights.T, keep_slope=True)
                     for axis in range(3)], axis=-1)


# ------------------------------------------------------------------------------ appearance
class PaperAppearance:
    """Texture and shading of one sheet; ``vertex_colors`` runs every published frame."""

    def __init__(self, config: AppearanceConfig, sheet: Sheet) -> None:
        self.config = config
        if config.texture_path:
            self._texture = load_texture_image(config.texture_path)
        else:
            longer = config.texture_size
            ratio = sheet.height / sheet.width
            rows = longer if ratio >= 1 else max(16, int(round(longer * ratio)))
            columns = max(16, int(round(longer / ratio))) if ratio >= 1 else longer
            self._texture = procedural_paper_texture(rows, columns, config.texture_seed)
        self._texture.setflags(write=False)
        light = np.asarray(config.light_direction, dtype=np.float64)
        self._light = light / np.linalg.norm(light)
        self._flat_light = config.ambient + (1.0 - config.ambient) * abs(self._light[2])
        self._width = sheet.width
        self._height = sheet.height
        self._tilt_grid = self._level_tilt(sheet)

    @property
    def texture_image(self) -> np.ndarray:
        """The texture, (H, W, 3) uint8, row 0 at the sheet's top edge (read-only)."""
        return self._texture

    @property
    def uses_level_normals(self) -> bool:
        """True when the intermediate-level normals shade (a fractal-grid sheet)."""
        return self._tilt_grid is not None

    def _level_tilt(self, sheet: Sheet) -> np.ndarray | None:
        """(n, n, 4): per grid vertex, the level-L normal in the full-detail rest frame
        (3 channels) and the rest shape's fine relief ``normal_detail`` (1 channel); None
        when the full-detail normals are to shade."""
        side = _grid_side(sheet)
        if side is None or self.config.normal_level > grid_exponent(side):
            return None
        count = side * side
        grid = np.nan_to_num(sheet.positions[:count]).reshape(side, side, 3)
        material = sheet.material[:count]
        coarse = level_surface(grid, self.config.normal_level).reshape(-1, 3)
        triangles = grid_triangles(side, side)
        _, _, level_normal = local_frames(coarse, material, triangles)
        tangent, bitangent, normal = local_frames(grid.reshape(-1, 3), material, triangles)
        tilt = np.stack([np.sum(level_normal * frame, axis=1)
                         for frame in (tangent, bitangent, normal)]
                        + [normal_detail(grid.reshape(-1, 3), material, triangles)], axis=1)
        return tilt.reshape(side, side, 4)

    def _looked_up(self, sheet: Sheet) -> np.ndarray:
        """(V, 4): the stored tilt and rest relief at each vertex's material coordinates."""
        cells = self._tilt_grid.shape[0] - 1
        material = np.asarray(sheet.material, dtype=np.float64)
        return bilinear_sample(self._tilt_grid, (material[:, 0] / self._width + 0.5) * cells,
                               (material[:, 1] / self._height + 0.5) * cells)

    @staticmethod
    def _presence(rest: np.ndarray, now: np.ndarray) -> float:
        spread = math.sqrt(float(np.mean(rest * rest)))
        if not spread > 1e-12:
            return 1.0
        kept = np.abs(now - rest) <= 4.0 * spread
        # elementwise sums, not np.dot: a BLAS call can stall for milliseconds when its
        # threads compete with the simulation for the cores
        slope = float(np.sum(now[kept] * rest[kept])) \
            / max(float(np.sum(rest[kept] * rest[kept])), 1e-300)
        return min(max(slope, 0.0), 1.0) if math.isfinite(slope) else 0.0

    def detail_presence(self, sheet: Sheet) -> float:
        """How much of the rest shape's fine relief the sheet still has, in [0, 1]: the
        regression slope of its current ``normal_detail`` on the rest one, over the vertices
        where the two differ by less than 4 rms of the rest relief (a crease, far larger,
        does not count). 1 at rest and under any rigid motion, 0 once pressed flat
        (0 when the sheet has no level normals)."""
        if self._tilt_grid is None:
            return 0.0
        now = normal_detail(sheet.positions, sheet.material, sheet.triangles)
        return self._presence(self._looked_up(sheet)[:, 3], now)

    def shading_normals(self, sheet: Sheet) -> np.ndarray:
        """(V, 3) unit normals that light the sheet: the intermediate-level normals carried
        by the current geometry, to the extent the sheet still has the rest shape's fine
        relief (``detail_presence``), or the full-detail normals. Never NaN."""
        tangent, bitangent, normal, now = _frames_and_detail(sheet.positions, sheet.material,
                                                             sheet.triangles)
        if self._tilt_grid is None:
            return normal
        looked_up = self._looked_up(sheet)
        presence = self._presence(looked_up[:, 3], now)
        shaded = np.empty_like(normal)
        _apply_tilt_kernel(looked_up, presence, tangent, bitangent, normal, shaded)
        return shaded

    def vertex_light(self, sheet: Sheet) -> np.ndarray:
        """(V,) brightness of the white surface: two-sided Lambert with ``shading_normals``
        plus ambient, relative to a sheet lying flat (normal +z), which shows its texture
        unchanged (1.0); slopes facing the light are brighter (up to 1/flat), slopes
        facing away darker (down to ambient/flat)."""
        ambient = self.config.ambient
        normals = self.shading_normals(sheet)
        light = self._light
        facing = normals[:, 0] * light[0] + normals[:, 1] * light[1] + normals[:, 2] * light[2]
        lit = ambient + (1.0 - ambient) * np.abs(facing)
        return lit / self._flat_light

    def vertex_colors(self, sheet: Sheet) -> np.ndarray:
        """(V, 3) uint8 colours: the white surface lit (``vertex_light``), modulated by the
        texture at the vertices' texture coordinates. Works for any vertex count; never
        NaN."""
        image = self._texture
        material = np.asarray(sheet.material, dtype=np.float64)
        # texture coordinates as Sheet.texture_coordinates, in pixels
        columns = (material[:, 0] / sheet.width + 0.5) * (image.shape[1] - 1)
        rows = (0.5 - material[:, 1] / sheet.height) * (image.shape[0] - 1)
        colors = np.empty((sheet.vertex_count, 3), dtype=np.uint8)
        _colour_kernel(image, columns, rows, self.vertex_light(sheet),
                       float(self.config.texture_blend), float(self.config.ambient), colors)
        return colors
