"""A virtual pinhole camera that renders the sheet, the probes and the table (issue 16).

The camera follows ROS conventions: its pose is the pose of its *optical* frame in the
world frame (REP 103 optical frame: z forward, x right, y down), its intrinsics are those
of ``sensor_msgs/CameraInfo`` without distortion (pixel centres at integer pixel
coordinates, as OpenCV and ``image_geometry`` use), and a depth image holds metres along
the optical axis, NaN where the ray hits nothing (REP 118).

Rendering is two passes over flat arrays, both numba kernels:

- ``_raster_kernel``: a z-buffer over the paper's triangles (bounding box per triangle,
  edge functions, perspective-correct barycentric weights). A triangle with any vertex at
  or behind the near plane (``CameraConfig.near``) is skipped whole, not clipped: the
  camera is meant to look at the sheet from outside it.
- ``_shade_kernel``: per pixel, the ray is cast against the table (the infinite plane
  z = ``table_height``, seen from both sides) and the probes (spheres; each only over the
  pixels its silhouette can cover) and the nearest of paper, probe and table wins; the
  paper's depth, material coordinates, colour and damage label are interpolated with the
  stored weights. Paper wins a tie with the table within ``PAPER_OVER_TABLE`` (a sheet
  lying on the table shows, not the table).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
import math

import numpy as np
from numba import njit

HIT_NOTHING = 0
"""``CameraFrame.hit``: the ray misses everything."""
HIT_PAPER = 1
"""``CameraFrame.hit``: the ray hits the sheet."""
HIT_PROBE = 2
"""``CameraFrame.hit``: the ray hits a probe."""
HIT_TABLE = 3
"""``CameraFrame.hit``: the ray hits the table."""

PROBE_COLOR = (200, 70, 60)
"""RGB of a probe (plain, unshaded)."""
TABLE_COLOR = (128, 128, 128)
"""RGB of the table (plain grey)."""
PAPER_OVER_TABLE = 1.0e-4
"""Depth margin [m] by which paper behind the table's plane still shows in front of it."""


def _require(condition: bool, message: str) -> None:
    if not condition:
        raise ValueError(message)


def _finite_vector(name: str, value, size: int) -> tuple:
    try:
        vector = tuple(float(x) for x in value)
    except (TypeError, ValueError):
        raise ValueError(f'{name} must be {size} finite numbers, got {value!r}') from None
    _require(len(vector) == size and all(math.isfinite(x) for x in vector),
             f'{name} must be {size} finite numbers, got {value!r}')
    return vector


@dataclass(frozen=True)
class CameraConfig:
    """A pinhole camera without distortion. Units SI; angles in radians."""

    name: str = 'camera'
    """Name of the camera (its frame id is the caller's business)."""
    width: int = 640
    """Image width [pixels]."""
    height: int = 480
    """Image height [pixels]."""
    horizontal_fov: float = 1.0
    """Horizontal field of view [rad], in (0, π); gives fx when fx is not set."""
    position: tuple = (0.0, 0.0, 0.5)
    """Origin of the optical frame in the world frame [m]."""
    orientation: tuple = (1.0, 0.0, 0.0, 0.0)
    """Orientation (x, y, z, w) of the optical frame in the world frame; normalised on use.
    The default looks straight down (optical z = world −z) with image right = world +x."""
    fx: float | None = None
    """Focal length [pixels] along x; default (width / 2) / tan(horizontal_fov / 2)."""
    fy: float | None = None
    """Focal length [pixels] along y; default fx (square pixels)."""
    cx: float | None = None
    """Principal point x [pixels]; default (width − 1) / 2, the image centre."""
    cy: float | None = None
    """Principal point y [pixels]; default (height − 1) / 2."""
    near: float = 0.01
    """Near plane [m]: nothing closer along the optical axis is drawn."""

    def __post_init__(self) -> None:
        _require(isinstance(self.name, str), f'name must be a string, got {self.name!r}')
        for name in ('width', 'height'):
            value = getattr(self, name)
            _require(isinstance(value, int) and not isinstance(value, bool)
                     and 1 <= value <= 16384,
                     f'{name} must be an integer in [1, 16384] pixels, got {value!r}')
        fov = self.horizontal_fov
        _require(isinstance(fov, (int, float)) and math.isfinite(fov) and 0 < fov < math.pi,
                 f'horizontal_fov must be in (0, pi) rad, got {fov!r}')
        object.__setattr__(self, 'position', _finite_vector('position', self.position, 3))
        orientation = _finite_vector('orientation', self.orientation, 4)
        _require(math.sqrt(sum(q * q for q in orientation)) > 1e-9,
                 f'orientation must be a non-zero quaternion (x, y, z, w), got {orientation}')
        object.__setattr__(self, 'orientation', orientation)
        for name in ('fx', 'fy', 'cx', 'cy'):
            value = getattr(self, name)
            _require(value is None or (isinstance(value, (int, float))
                                       and math.isfinite(value)),
                     f'{name} must be None or a finite number, got {value!r}')
        for name in ('fx', 'fy'):
            value = getattr(self, name)
            _require(value is None or value > 0, f'{name} must be > 0 pixels, got {value!r}')
        _require(isinstance(self.near, (int, float)) and math.isfinite(self.near)
                 and self.near > 0, f'near must be a finite number > 0 m, got {self.near!r}')

    @property
    def optical_frame(self) -> str:
        """The frame id of its messages: ``<name>_optical_frame`` (REP 103)."""
        return f'{self.name}_optical_frame'

    @property
    def focal_x(self) -> float:
        """fx [pixels]."""
        if self.fx is not None:
            return float(self.fx)
        return 0.5 * self.width / math.tan(0.5 * self.horizontal_fov)

    @property
    def focal_y(self) -> float:
        """fy [pixels]."""
        return float(self.fy) if self.fy is not None else self.focal_x

    @property
    def principal_x(self) -> float:
        """cx [pixels]."""
        return float(self.cx) if self.cx is not None else 0.5 * (self.width - 1)

    @property
    def principal_y(self) -> float:
        """cy [pixels]."""
        return float(self.cy) if self.cy is not None else 0.5 * (self.height - 1)


@dataclass
class CameraFrame:
    """One rendered frame; every image is (H, W), row-major, row 0 at the top."""

    depth: np.ndarray
    """(H, W) float32 [m] along the optical axis; NaN where nothing is hit (REP 118)."""
    rgb: np.ndarray
    """(H, W, 3) uint8; black where nothing is hit."""
    u: np.ndarray
    """(H, W) float32 [m]: material x (``Sheet.material[:, 0]``) of the paper point seen;
    NaN where the pixel does not show paper."""
    v: np.ndarray
    """(H, W) float32 [m]: material y of the paper point seen; NaN where not paper."""
    label: np.ndarray
    """(H, W) uint16: damage label of the hit triangle's vertex of largest
    (perspective-correct) barycentric weight; 0 where not paper."""
    hit: np.ndarray
    """(H, W) uint8: HIT_NOTHING, HIT_PAPER, HIT_PROBE or HIT_TABLE."""


def quaternion_to_matrix(quaternion) -> np.ndarray:
    """3×3 rotation of the unit quaternion (x, y, z, w) (normalised here)."""
    x, y, z, w = np.asarray(quaternion, dtype=np.float64) / np.linalg.norm(quaternion)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def matrix_to_quaternion(rotation: np.ndarray) -> tuple:
    """The unit quaternion (x, y, z, w), w >= 0, of a 3×3 rotation matrix."""
    m = np.asarray(rotation, dtype=np.float64)
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    if trace > 0:
        s = 2.0 * math.sqrt(1.0 + trace)
        q = ((m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, s / 4)
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = (s / 4, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s)
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = ((m[0, 1] + m[1, 0]) / s, s / 4, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s)
    else:
        s = 2.0 * math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = ((m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, s / 4, (m[1, 0] - m[0, 1]) / s)
    q = np.array(q) / np.linalg.norm(q)
    if q[3] < 0:
        q = -q
    return tuple(float(c) for c in q)


def look_at(eye, target, up=(0.0, 0.0, 1.0)) -> tuple:
    """Orientation (x, y, z, w) of an optical frame at ``eye`` looking at ``target``: z
    towards the target, x right, y down, with ``up`` pointing up in the image. Raises
    ValueError when eye and target coincide or the view is parallel to ``up``."""
    eye = np.array(_finite_vector('eye', eye, 3))
    forward = np.array(_finite_vector('target', target, 3)) - eye
    up = np.array(_finite_vector('up', up, 3))
    _require(np.linalg.norm(forward) > 1e-12, 'look_at: eye and target coincide')
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, up)
    _require(np.linalg.norm(right) > 1e-9 * max(np.linalg.norm(up), 1e-300),
             'look_at: the view direction is parallel to up; choose another up vector')
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    return matrix_to_quaternion(np.column_stack([right, down, forward]))


def camera_rotation(config: CameraConfig) -> np.ndarray:
    """3×3 rotation from the optical frame to the world frame (world = R p + position)."""
    return quaternion_to_matrix(config.orientation)


def intrinsics(config: CameraConfig) -> np.ndarray:
    """The 3×3 camera matrix K of CameraInfo (row-major: fx 0 cx, 0 fy cy, 0 0 1)."""
    return np.array([[config.focal_x, 0.0, config.principal_x],
                     [0.0, config.focal_y, config.principal_y],
                     [0.0, 0.0, 1.0]])


def projection_matrix(config: CameraConfig) -> np.ndarray:
    """The 3×4 projection matrix P of CameraInfo for a monocular camera: [K | 0]. It maps
    points in the optical frame to homogeneous pixel coordinates."""
    return np.hstack([intrinsics(config), np.zeros((3, 1))])


def world_to_camera(config: CameraConfig, points: np.ndarray) -> np.ndarray:
    """(..., 3) world points [m] in the optical frame."""
    rotation = camera_rotation(config)
    return (np.asarray(points, dtype=np.float64) - np.array(config.position)) @ rotation


def camera_to_world(config: CameraConfig, points: np.ndarray) -> np.ndarray:
    """(..., 3) optical-frame points [m] in the world frame (NaN stays NaN)."""
    rotation = camera_rotation(config)
    return np.asarray(points, dtype=np.float64) @ rotation.T + np.array(config.position)


def project(config: CameraConfig, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World points (N, 3) → pixel coordinates (N, 2) (column, row; integers at pixel
    centres) through P, and their depth (N,) [m] along the optical axis."""
    camera = world_to_camera(config, points)
    homogeneous = np.column_stack([camera, np.ones(len(camera))]) @ projection_matrix(config).T
    return homogeneous[:, :2] / homogeneous[:, 2:3], camera[:, 2]


def back_project(config: CameraConfig, depth: np.ndarray) -> np.ndarray:
    """(H, W) depth [m] along the optical axis → (H, W, 3) float64 points in the optical
    frame; NaN where the depth is NaN."""
    depth = np.asarray(depth, dtype=np.float64)
    _require(depth.shape == (config.height, config.width),
             f'depth must be ({config.height}, {config.width}), got {depth.shape}')
    columns = np.arange(config.width, dtype=np.float64)
    rows = np.arange(config.height, dtype=np.float64)
    points = np.empty(depth.shape + (3,))
    points[..., 0] = depth * ((columns[None, :] - config.principal_x) / config.focal_x)
    points[..., 1] = depth * ((rows[:, None] - config.principal_y) / config.focal_y)
    points[..., 2] = depth
    return points


@njit(cache=True)
def _raster_kernel(positions, triangles, rotation, translation, fx, fy, cx, cy, near,
                   depth_buffer, triangle_buffer, weight_buffer):
    """Z-buffer the triangles. ``depth_buffer`` (H, W) must start at +inf; writes the depth
    [m], the triangle index and its perspective-correct barycentric weights (H, W, 3) of
    the nearest triangle at every pixel centre it covers. Skips any triangle with a vertex
    at or behind ``near``, and triangles seen edge-on."""
    height = depth_buffer.shape[0]
    width = depth_buffer.shape[1]
    vertex_count = positions.shape[0]
    camera = np.empty((vertex_count, 3))
    screen = np.empty((vertex_count, 2))
    for i in range(vertex_count):
        dx = positions[i, 0] - translation[0]
        dy = positions[i, 1] - translation[1]
        dz = positions[i, 2] - translation[2]
        # optical frame = Rᵀ (p - position)
        for k in range(3):
            camera[i, k] = rotation[0, k] * dx + rotation[1, k] * dy + rotation[2, k] * dz
        z = camera[i, 2]
        if z > near:
            screen[i, 0] = fx * camera[i, 0] / z + cx
            screen[i, 1] = fy * camera[i, 1] / z + cy
        else:
            screen[i, 0] = 0.0
            screen[i, 1] = 0.0
    for t in range(triangles.shape[0]):
        a = triangles[t, 0]
        b = triangles[t, 1]
        c = triangles[t, 2]
        za = camera[a, 2]
        zb = camera[b, 2]
        zc = camera[c, 2]
        if za <= near or zb <= near or zc <= near:
            continue
        ax = screen[a, 0]
        ay = screen[a, 1]
        bx = screen[b, 0]
        by = screen[b, 1]
        qx = screen[c, 0]
        qy = screen[c, 1]
        area = (bx - ax) * (qy - ay) - (by - ay) * (qx - ax)
        if abs(area) < 1e-12:
            continue
        inverse_area = 1.0 / area
        column_low = max(int(math.ceil(min(ax, bx, qx))), 0)
        column_high = min(int(math.floor(max(ax, bx, qx))), width - 1)
        row_low = max(int(math.ceil(min(ay, by, qy))), 0)
        row_high = min(int(math.floor(max(ay, by, qy))), height - 1)
        inverse_za = 1.0 / za
        inverse_zb = 1.0 / zb
        inverse_zc = 1.0 / zc
        for row in range(row_low, row_high + 1):
            py = float(row)
            for column in range(column_low, column_high + 1):
                px = float(column)
                # screen-space barycentric weights; inside when all are >= 0
                wa = ((bx - px) * (qy - py) - (by - py) * (qx - px)) * inverse_area
                wb = ((qx - px) * (ay - py) - (qy - py) * (ax - px)) * inverse_area
                wc = 1.0 - wa - wb
                if wa < -1e-9 or wb < -1e-9 or wc < -1e-9:
                    continue
                # 1/z is affine in screen space: perspective-correct depth and weights
                inverse_depth = wa * inverse_za + wb * inverse_zb + wc * inverse_zc
                depth = 1.0 / inverse_depth
                if depth < depth_buffer[row, column]:
                    depth_buffer[row, column] = depth
                    triangle_buffer[row, column] = t
                    weight_buffer[row, column, 0] = wa * inverse_za * depth
                    weight_buffer[row, column, 1] = wb * inverse_zb * depth
                    weight_buffer[row, column, 2] = wc * inverse_zc * depth


@njit(cache=True)
def _tangent_slopes(centre_x, centre_z, radius):
    """The slopes m of the two lines x = m z through the optical centre that touch a sphere
    seen in front of the camera (its section by the plane of x and z: the disk of
    ``radius`` around (centre_x, centre_z), centre_z > radius): the range of x / z over it."""
    reach = radius * math.sqrt(centre_x * centre_x + centre_z * centre_z - radius * radius)
    depth_squared = centre_z * centre_z - radius * radius
    return ((centre_x * centre_z - reach) / depth_squared,
            (centre_x * centre_z + reach) / depth_squared)


@njit(cache=True)
def _probe_pixel_boxes(probe_centers, probe_radii, probe_active, fx, fy, cx, cy, near,
                       height, width):
    """Per probe, the rows and columns (first row, last row, first column, last column) that
    can see it: its silhouette's bounds widened by a pixel, the whole image for a probe not
    wholly beyond the near plane, none for an inactive one. The ray test runs only there."""
    boxes = np.zeros((probe_radii.shape[0], 4), dtype=np.int64)
    for p in range(probe_radii.shape[0]):
        if not probe_active[p]:
            boxes[p, 1] = -1  # rows 0 to -1: none
            continue
        radius = probe_radii[p]
        centre_z = probe_centers[p, 2]
        boxes[p, 1] = height - 1
        boxes[p, 3] = width - 1
        if centre_z - radius <= near:
            continue
        # clamped as floats: a sphere grazing the near plane far off the axis has slopes
        # no integer holds
        low, high = _tangent_slopes(probe_centers[p, 1], centre_z, radius)
        boxes[p, 0] = int(max(math.floor(fy * low + cy) - 1.0, 0.0))
        boxes[p, 1] = int(min(math.ceil(fy * high + cy) + 1.0, height - 1.0))
        low, high = _tangent_slopes(probe_centers[p, 0], centre_z, radius)
        boxes[p, 2] = int(max(math.floor(fx * low + cx) - 1.0, 0.0))
        boxes[p, 3] = int(min(math.ceil(fx * high + cx) + 1.0, width - 1.0))
    return boxes


@njit(cache=True, error_model='numpy')
def _shade_kernel(depth_buffer, triangle_buffer, weight_buffer, triangles, material, labels,
                  colors, probe_centers, probe_radii, probe_active, table_enabled,
                  table_offset, table_direction, fx, fy, cx, cy, near, paper_over_table,
                  probe_color, table_color, depth, rgb, u, v, label, hit):
    """Per pixel: nearest of the rastered paper, the probes (centres in the optical frame)
    and the table (world z of the ray point at depth s is position_z + s · table_direction ·
    (x', y', 1), with table_offset = table_height − position_z), then the outputs. Paper and
    table first over the whole image, then each probe over the pixels that can see it
    (``depth_buffer`` keeps the nearest depth so far)."""
    height = depth_buffer.shape[0]
    width = depth_buffer.shape[1]
    nan = np.float32(np.nan)
    table_depth = np.full(width, np.nan)
    ray_x = np.empty(width)
    for column in range(width):
        ray_x[column] = (column - cx) / fx
    for row in range(height):
        ry = (row - cy) / fy
        if table_enabled:
            row_term = table_direction[1] * ry
            # a loop the compiler vectorises: a ray along the plane gets ±inf or NaN
            for column in range(width):
                table_depth[column] = table_offset / (
                    table_direction[0] * ray_x[column] + row_term + table_direction[2])
        for column in range(width):
            # ray: s · (rx, ry, 1), s = depth along the optical axis
            best = np.inf
            kind = 0
            s = table_depth[column]
            if near < s < np.inf:
                best = s
                kind = 3
            paper = depth_buffer[row, column]
            if paper < best + paper_over_table:
                best = paper
                kind = 1
            depth_buffer[row, column] = best
            hit[row, column] = kind
            if kind == 0:
                depth[row, column] = nan
                u[row, column] = nan
                v[row, column] = nan
                label[row, column] = 0
                for k in range(3):
                    rgb[row, column, k] = 0
                continue
            depth[row, column] = best
            if kind == 3:
                u[row, column] = nan
                v[row, column] = nan
                label[row, column] = 0
                for k in range(3):
                    rgb[row, column, k] = table_color[k]
                continue
            t = triangle_buffer[row, column]
            material_x = 0.0
            material_y = 0.0
            red = 0.0
            green = 0.0
            blue = 0.0
            largest = -1.0
            nearest = 0
            for corner in range(3):
                vertex = triangles[t, corner]
                weight = weight_buffer[row, column, corner]
                material_x += weight * material[vertex, 0]
                material_y += weight * material[vertex, 1]
                red += weight * colors[vertex, 0]
                green += weight * colors[vertex, 1]
                blue += weight * colors[vertex, 2]
                if weight > largest:
                    largest = weight
                    nearest = vertex
            u[row, column] = material_x
            v[row, column] = material_y
            label[row, column] = labels[nearest]
            rgb[row, column, 0] = min(max(int(red + 0.5), 0), 255)
            rgb[row, column, 1] = min(max(int(green + 0.5), 0), 255)
            rgb[row, column, 2] = min(max(int(blue + 0.5), 0), 255)
    boxes = _probe_pixel_boxes(probe_centers, probe_radii, probe_active, fx, fy, cx, cy, near,
                               height, width)
    for p in range(probe_radii.shape[0]):
        centre_squared = (probe_centers[p, 0] ** 2 + probe_centers[p, 1] ** 2
                          + probe_centers[p, 2] ** 2)
        for row in range(boxes[p, 0], boxes[p, 1] + 1):
            ry = (row - cy) / fy
            for column in range(boxes[p, 2], boxes[p, 3] + 1):
                rx = ray_x[column]
                ray_squared = rx * rx + ry * ry + 1.0
                along = rx * probe_centers[p, 0] + ry * probe_centers[p, 1] + probe_centers[p, 2]
                discriminant = along * along - ray_squared * (centre_squared
                                                              - probe_radii[p] ** 2)
                if discriminant < 0.0:
                    continue
                root = math.sqrt(discriminant)
                s = (along - root) / ray_squared
                if s <= near:
                    s = (along + root) / ray_squared
                if not near < s < depth_buffer[row, column]:
                    continue
                depth_buffer[row, column] = s
                hit[row, column] = 2
                depth[row, column] = s
                u[row, column] = nan
                v[row, column] = nan
                label[row, column] = 0
                for k in range(3):
                    rgb[row, column, k] = probe_color[k]


def render(config: CameraConfig, sheet_positions: np.ndarray, triangles: np.ndarray,
           vertex_material_uv: np.ndarray, vertex_labels: np.ndarray,
           vertex_colors: np.ndarray, probe_centers: np.ndarray, probe_radii: np.ndarray,
           probe_active: np.ndarray, table_height: float | None) -> CameraFrame:
    """Render the sheet (``Sheet.positions``, ``triangles``, ``material``, the labels of
    ``damage_labels``, the colours of ``PaperAppearance.vertex_colors``: (V, 3) uint8, or
    float in [0, 1]), sphere probes (P, 3) / (P,) / (P,) and the table plane z =
    ``table_height`` (None: no table) as ``config`` sees them."""
    positions = np.ascontiguousarray(sheet_positions, dtype=np.float64)
    vertex_count = positions.shape[0]
    _require(positions.ndim == 2 and positions.shape[1] == 3,
             f'sheet_positions must be (V, 3), got {positions.shape}')
    triangles = np.ascontiguousarray(triangles, dtype=np.int64)
    _require(triangles.ndim == 2 and triangles.shape[1] == 3,
             f'triangles must be (T, 3), got {triangles.shape}')
    if triangles.size:
        _require(triangles.min() >= 0 and triangles.max() < vertex_count,
                 'triangles index vertices out of range')
    material = np.ascontiguousarray(vertex_material_uv, dtype=np.float64)
    _require(material.shape == (vertex_count, 2),
             f'vertex_material_uv must be ({vertex_count}, 2), got {material.shape}')
    labels = np.ascontiguousarray(vertex_labels, dtype=np.uint16)
    _require(labels.shape == (vertex_count,),
             f'vertex_labels must be ({vertex_count},), got {labels.shape}')
    colors = np.asarray(vertex_colors)
    _require(colors.shape == (vertex_count, 3),
             f'vertex_colors must be ({vertex_count}, 3), got {colors.shape}')
    scale = 255.0 if np.issubdtype(colors.dtype, np.floating) else 1.0
    colors = np.ascontiguousarray(colors, dtype=np.float64) * scale
    radii = np.ascontiguousarray(probe_radii, dtype=np.float64).reshape(-1)
    centers = np.asarray(probe_centers, dtype=np.float64).reshape(-1, 3)
    active = np.ascontiguousarray(probe_active, dtype=np.bool_).reshape(-1)
    _require(centers.shape[0] == radii.shape[0] == active.shape[0],
             'probe_centers, probe_radii and probe_active must have as many probes')
    _require(table_height is None or math.isfinite(table_height),
             f'table_height must be finite or None, got {table_height!r}')
    rotation = camera_rotation(config)
    translation = np.array(config.position)
    centers_camera = np.ascontiguousarray((centers - translation) @ rotation)
    fx, fy = config.focal_x, config.focal_y
    cx, cy = config.principal_x, config.principal_y
    shape = (config.height, config.width)

    # paper: z-buffer of the triangles
    depth_buffer = np.full(shape, np.inf)
    triangle_buffer = np.zeros(shape, dtype=np.int64)
    weight_buffer = np.empty(shape + (3,))
    _raster_kernel(positions, triangles, rotation, translation, fx, fy, cx, cy,
                   float(config.near), depth_buffer, triangle_buffer, weight_buffer)

    # probes and table, then the nearest of all at every pixel
    frame = CameraFrame(depth=np.empty(shape, dtype=np.float32),
                        rgb=np.empty(shape + (3,), dtype=np.uint8),
                        u=np.empty(shape, dtype=np.float32),
                        v=np.empty(shape, dtype=np.float32),
                        label=np.empty(shape, dtype=np.uint16),
                        hit=np.empty(shape, dtype=np.uint8))
    table_offset = 0.0 if table_height is None else table_height - translation[2]
    _shade_kernel(depth_buffer, triangle_buffer, weight_buffer, triangles, material, labels,
                  colors, centers_camera, radii, active, table_height is not None,
                  table_offset, np.ascontiguousarray(rotation[2]), fx, fy, cx, cy,
                  float(config.near), PAPER_OVER_TABLE, np.array(PROBE_COLOR, np.uint8),
                  np.array(TABLE_COLOR, np.uint8), frame.depth, frame.rgb, frame.u,
                  frame.v, frame.label, frame.hit)
    return frame


DEFAULT_POSITION = (0.3, -0.35, 0.5)
"""Where the default camera is [m]: above the table, oblique to an A4 sheet at the origin."""
DEFAULT_TARGET = (0.0, 0.0, 0.0)
"""What the default camera looks at [m]."""


def camera_looking_at(name: str = 'camera', position=DEFAULT_POSITION,
                      target=DEFAULT_TARGET, width: int = 640, height: int = 480,
                      horizontal_fov: float = 1.0, *, fx: float | None = None,
                      fy: float | None = None, cx: float | None = None,
                      cy: float | None = None) -> CameraConfig:
    """A camera at ``position`` whose optical axis goes through ``target`` (world, [m]),
    image up towards +z, or +y when it looks straight down or up; ``fx``, ``fy``, ``cx``,
    ``cy`` as in ``CameraConfig`` (None: derived). ValueError names what is wrong (a name
    that is not a letter then letters, digits or _ — it names topics and frames —,
    non-finite or coinciding points, a bad size, field of view or intrinsic)."""
    _require(isinstance(name, str) and name[:1].isalpha() and name.replace('_', '').isalnum(),
             f'camera name must be a letter then letters, digits or _, got {name!r}')
    eye = _finite_vector('position', position, 3)
    aim = _finite_vector('target', target, 3)
    _require(math.dist(eye, aim) > 1e-6, 'camera target must differ from its position')
    vertical = math.hypot(aim[0] - eye[0], aim[1] - eye[1]) < 1e-9 * math.dist(eye, aim)
    return CameraConfig(name=name, width=width, height=height, horizontal_fov=horizontal_fov,
                        position=eye, orientation=look_at(
                            eye, aim, (0.0, 1.0, 0.0) if vertical else (0.0, 0.0, 1.0)),
                        fx=fx, fy=fy, cx=cx, cy=cy)


def render_simulator(config: CameraConfig, simulator, vertex_colors: np.ndarray) -> CameraFrame:
    """What ``config`` sees of a ``core.simulator.Simulator`` now: its sheet (coloured
    ``vertex_colors``, labelled by ``damage_labels``), its active probes and its table."""
    sheet = simulator.sheet
    contact = simulator.config.contact
    probes = simulator.probes
    return render(config, sheet.positions, sheet.triangles, sheet.material,
                  simulator.damage_labels(), vertex_colors, probes.end, probes.radius,
                  probes.active, contact.ground_height if contact.ground_enabled else None)


def with_depth_noise(frame: CameraFrame, stddev: float,
                     rng: np.random.Generator) -> CameraFrame:
    """``frame`` with Gaussian noise of ``stddev`` [m] on its depth where something is hit
    (a depth sensor's; NaN stays NaN), reproducible for a given ``rng`` state."""
    if not (math.isfinite(stddev) and stddev >= 0):
        raise ValueError(f'depth noise must be finite and >= 0 m, got {stddev}')
    if stddev == 0:
        return frame
    noise = rng.normal(0.0, stddev, frame.depth.shape).astype(np.float32)
    return dataclasses.replace(frame, depth=frame.depth + noise)
