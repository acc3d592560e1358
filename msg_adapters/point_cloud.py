"""The sheet as ``sensor_msgs/PointCloud2``, built from a numpy structured array.

Modelled on ``sensor_msgs_py.point_cloud2`` (not installable here): pure functions, the
field table as a module constant, and the message data taken as bytes from numpy. There is
no per-point Python loop anywhere in this module.

Cloud layout (little endian, ``point_step`` = 36, one row, ``is_dense`` = True):

    offset  name       type
     0      x          float32   [m]
     4      y          float32
     8      z          float32
    12      normal_x   float32   unit vertex normal
    16      normal_y   float32
    20      normal_z   float32
    24      label      uint16    damage label (``paper_sim_ros.core.damage_labels``)
    26      (2 bytes padding, zero)
    28      u          float32   material x [m]: where the point is on the undeformed sheet
    32      v          float32   material y [m] (ground truth for a tracker)
"""
from __future__ import annotations

import array
import sys

import numpy as np
from sensor_msgs.msg import PointCloud2, PointField
from std_msgs.msg import Header

POINT_DTYPE = np.dtype({
    'names': ['x', 'y', 'z', 'normal_x', 'normal_y', 'normal_z', 'label', 'u', 'v'],
    'formats': ['<f4', '<f4', '<f4', '<f4', '<f4', '<f4', '<u2', '<f4', '<f4'],
    'offsets': [0, 4, 8, 12, 16, 20, 24, 28, 32],
    'itemsize': 36,
})
"""One point of ``paper/points``."""

# PointField datatype code for each numpy type we publish
_DATATYPE_OF = {
    np.dtype('int8'): PointField.INT8, np.dtype('uint8'): PointField.UINT8,
    np.dtype('int16'): PointField.INT16, np.dtype('uint16'): PointField.UINT16,
    np.dtype('int32'): PointField.INT32, np.dtype('uint32'): PointField.UINT32,
    np.dtype('float32'): PointField.FLOAT32, np.dtype('float64'): PointField.FLOAT64,
}
_DTYPE_OF = {code: dtype for dtype, code in _DATATYPE_OF.items()}


def point_fields(dtype: np.dtype) -> list[PointField]:
    """The ``PointField`` list that describes a (little endian) numpy structured dtype."""
    if dtype.names is None:
        raise ValueError('a structured dtype is required')
    fields = []
    for name in dtype.names:
        field_dtype, offset = dtype.fields[name][:2]
        if field_dtype.subdtype is not None:
            raise ValueError(f'field {name!r}: sub-arrays are not supported')
        if field_dtype.byteorder == '>':
            raise ValueError(f'field {name!r}: big-endian fields are not supported')
        code = _DATATYPE_OF.get(field_dtype.newbyteorder('='))
        if code is None:
            raise ValueError(f'field {name!r}: no PointField type for {field_dtype}')
        fields.append(PointField(name=name, offset=offset, datatype=code, count=1))
    return fields


def message_data(shape: tuple, dtype: np.dtype) -> tuple[array.array, np.ndarray]:
    """A message's ``data`` (zeroed ``array('B')``) and a writable numpy view of it as
    ``shape`` of ``dtype``: fill the view, then set ``data``; no copy of the bytes."""
    dtype = np.dtype(dtype)
    data = array.array('B', b'\0') * (int(np.prod(shape)) * dtype.itemsize)
    return data, np.frombuffer(data, dtype=dtype).reshape(shape)


def with_data(message, values: np.ndarray):
    """``message`` with its uint8 sequence ``data`` set to the bytes of ``values``, as the
    ``array('B')`` it holds. Passed to a generated message's constructor, bytes or an array
    are converted element by element (bench/bench_camera.py); set afterwards, an
    ``array('B')`` is taken as it is."""
    data = array.array('B')
    data.frombytes(np.ascontiguousarray(values).reshape(-1).view(np.uint8).data)
    message.data = data
    return message


def create_cloud(header: Header, points: np.ndarray) -> PointCloud2:
    """An unorganised (height 1) cloud of a 1-D structured array; the data are its bytes."""
    points = np.asarray(points)
    if points.ndim != 1 or points.dtype.names is None:
        raise ValueError('points must be a 1-D numpy structured array')
    fields = point_fields(points.dtype)
    finite = all(np.isfinite(points[name]).all() for name in points.dtype.names
                 if points.dtype.fields[name][0].kind == 'f')
    return with_data(PointCloud2(
        header=header, height=1, width=int(points.shape[0]), fields=fields,
        is_bigendian=False, point_step=points.dtype.itemsize,
        row_step=points.dtype.itemsize * int(points.shape[0]), is_dense=bool(finite)), points)


def sheet_points(positions: np.ndarray, normals: np.ndarray, labels: np.ndarray,
                 material: np.ndarray) -> np.ndarray:
    """One POINT_DTYPE row per vertex (``material``: (V, 2) material coordinates [m]).
    Raises ValueError on shape mismatch or on non-finite input, so that a cloud never
    carries NaN."""
    positions = np.asarray(positions)
    normals = np.asarray(normals)
    labels = np.asarray(labels)
    material = np.asarray(material)
    count = positions.shape[0]
    if positions.shape != (count, 3) or normals.shape != (count, 3) \
            or labels.shape != (count,) or material.shape != (count, 2):
        raise ValueError(f'positions {positions.shape}, normals {normals.shape}, labels '
                         f'{labels.shape} and material {material.shape} must be (V, 3), '
                         f'(V, 3), (V,), (V, 2)')
    if not (np.isfinite(positions).all() and np.isfinite(normals).all()
            and np.isfinite(material).all()):
        raise ValueError('positions, normals and material must be finite')
    points = np.zeros(count, dtype=POINT_DTYPE)
    points['x'], points['y'], points['z'] = positions.T
    points['normal_x'], points['normal_y'], points['normal_z'] = normals.T
    points['label'] = labels
    points['u'], points['v'] = material.T
    return points


def dense_surface_points(positions: np.ndarray, normals: np.ndarray, labels: np.ndarray,
                         material: np.ndarray, triangles: np.ndarray, samples_per_triangle: int,
                         noise_stddev: float, rng: np.random.Generator) -> np.ndarray:
    """A denser, sensor-like sampling of the surface: ``samples_per_triangle`` uniform random
    points in every triangle, Gaussian noise of ``noise_stddev`` [m] on the position (the
    normal and the material coordinates stay the exact interpolated ones: ground truth), the
    label of the nearest corner.
    Reproducible for a given ``rng`` state."""
    triangles = np.asarray(triangles)
    if samples_per_triangle < 1:
        raise ValueError(f'samples_per_triangle must be >= 1, got {samples_per_triangle}')
    if not (np.isfinite(noise_stddev) and noise_stddev >= 0):
        raise ValueError(f'noise_stddev must be finite and >= 0, got {noise_stddev}')
    if triangles.ndim != 2 or triangles.shape[1] != 3:
        raise ValueError(f'triangles must be (T, 3), got {triangles.shape}')
    corners = np.repeat(triangles, samples_per_triangle, axis=0)
    count = corners.shape[0]
    # uniform barycentric coordinates by folding the unit square onto the triangle
    u, v = rng.random((2, count))
    outside = u + v > 1.0
    u[outside], v[outside] = 1.0 - u[outside], 1.0 - v[outside]
    weights = np.stack([1.0 - u - v, u, v], axis=1)
    sampled = np.einsum('nk,nkd->nd', weights, positions[corners])
    sampled_normals = np.einsum('nk,nkd->nd', weights, normals[corners])
    length = np.linalg.norm(sampled_normals, axis=1)
    degenerate = length < 1e-12
    sampled_normals[degenerate] = (0.0, 0.0, 1.0)
    length[degenerate] = 1.0
    sampled_normals /= length[:, None]
    if noise_stddev > 0:
        sampled = sampled + rng.normal(0.0, noise_stddev, size=sampled.shape)
    nearest = corners[np.arange(count), np.argmax(weights, axis=1)]
    sampled_material = np.einsum('nk,nkd->nd', weights, np.asarray(material)[corners])
    return sheet_points(sampled, sampled_normals, np.asarray(labels)[nearest], sampled_material)


def read_points(cloud: PointCloud2) -> np.ndarray:
    """The cloud's data as a structured array (a copy), dtype built from its fields."""
    if cloud.height * cloud.width * cloud.point_step != len(cloud.data):
        raise ValueError('cloud data size does not match height * width * point_step')
    if cloud.is_bigendian != (sys.byteorder == 'big'):
        raise ValueError('clouds of the other byte order are not supported')
    dtype = np.dtype({
        'names': [field.name for field in cloud.fields],
        'formats': [_DTYPE_OF[field.datatype] for field in cloud.fields],
        'offsets': [field.offset for field in cloud.fields],
        'itemsize': cloud.point_step,
    })
    return np.frombuffer(bytes(cloud.data), dtype=dtype).copy()
