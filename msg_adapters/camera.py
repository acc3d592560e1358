"""A virtual camera's frame (``paper_sim_ros.core.camera``) as ROS 2 messages: depth and
colour ``sensor_msgs/Image``, ``sensor_msgs/CameraInfo`` and an organised
``sensor_msgs/PointCloud2`` with ground truth per pixel (issue 16).

All built from numpy arrays as bytes; no per-pixel Python loop. Every message of one frame
takes the same header: the camera's optical frame (REP 103: z forward, x right, y down) and
one stamp. Depth is metres along the optical axis, NaN where nothing is hit (REP 118).

Organised cloud layout (little endian, ``point_step`` = 24, height × width, row-major,
``is_dense`` = False: pixels that hit nothing are NaN in x, y, z, u, v):

    offset  name    type
     0      x       float32   [m], optical frame
     4      y       float32
     8      z       float32   (= depth)
    12      u       float32   [m] material x of the paper point seen (NaN: not paper)
    16      v       float32   [m] material y
    20      label   uint16    damage label of the paper seen (0: not paper)
    22      hit     uint8     what the pixel shows (core.camera HIT_*)
    23      (1 byte padding, zero)
"""
from __future__ import annotations

import sys

import numpy as np
from numba import njit
from sensor_msgs.msg import CameraInfo, Image, PointCloud2
from std_msgs.msg import Header

from paper_sim_ros.core.camera import CameraConfig, CameraFrame, intrinsics, projection_matrix
from .point_cloud import message_data, point_fields, with_data

PIXEL_DTYPE = np.dtype({
    'names': ['x', 'y', 'z', 'u', 'v', 'label', 'hit'],
    'formats': ['<f4', '<f4', '<f4', '<f4', '<f4', '<u2', 'u1'],
    'offsets': [0, 4, 8, 12, 16, 20, 22],
    'itemsize': 24,
})
"""One pixel of ``paper/<camera>/points``."""

_BIG_ENDIAN = sys.byteorder == 'big'


def _image(header: Header, pixels: np.ndarray, encoding: str) -> Image:
    height, width = pixels.shape[:2]
    data = np.ascontiguousarray(pixels)
    return with_data(Image(header=header, height=height, width=width, encoding=encoding,
                           is_bigendian=int(_BIG_ENDIAN and data.dtype.itemsize > 1),
                           step=data.strides[0]), data)


def depth_image(header: Header, frame: CameraFrame) -> Image:
    """``32FC1``: metres along the optical axis, NaN where nothing is hit."""
    return _image(header, frame.depth.astype(np.float32, copy=False), '32FC1')


def color_image(header: Header, frame: CameraFrame) -> Image:
    """``rgb8``, as the appearance model shades the sheet."""
    return _image(header, frame.rgb.astype(np.uint8, copy=False), 'rgb8')


def camera_info(header: Header, config: CameraConfig) -> CameraInfo:
    """Plumb-bob model with zero distortion; K, R (identity: monocular) and P = [K | 0]
    consistent with ``core.camera.project``."""
    return CameraInfo(header=header, height=config.height, width=config.width,
                      distortion_model='plumb_bob', d=[0.0] * 5,
                      k=intrinsics(config).ravel().tolist(),
                      r=np.eye(3).ravel().tolist(),
                      p=projection_matrix(config).ravel().tolist())


@njit(cache=True)
def _write_pixels(depth, u, v, label, hit, column_scale, row_scale, floats, octets):
    """Each pixel's x y z u v (float32 at bytes 0-19), label (uint16, little endian, at 20)
    and hit (uint8 at 22; the padding byte after it stays zero), in one pass."""
    for row in range(depth.shape[0]):
        for column in range(depth.shape[1]):
            z = depth[row, column]
            floats[row, column, 0] = z * column_scale[column]
            floats[row, column, 1] = z * row_scale[row]
            floats[row, column, 2] = z
            floats[row, column, 3] = u[row, column]
            floats[row, column, 4] = v[row, column]
            octets[row, column, 20] = label[row, column] & 0xFF
            octets[row, column, 21] = label[row, column] >> 8
            octets[row, column, 22] = hit[row, column]


def organized_cloud(header: Header, config: CameraConfig, frame: CameraFrame) -> PointCloud2:
    """height × width points back-projected from the depth image with the ground truth of
    each pixel (PIXEL_DTYPE); NaN where the pixel hits nothing."""
    data, points = message_data((config.height, config.width), PIXEL_DTYPE)
    # written in place through views of the message's bytes, in float32 (back-projection
    # as core.camera.back_project), in one pass: numpy's strided writes field by field
    # took 8.6 ms at 640 x 480, this 3.8 ms (bench/bench_camera.py)
    column_scale = ((np.arange(config.width) - config.principal_x)
                    / config.focal_x).astype(np.float32)
    row_scale = ((np.arange(config.height) - config.principal_y)
                 / config.focal_y).astype(np.float32)
    _write_pixels(frame.depth.astype(np.float32, copy=False),
                  frame.u.astype(np.float32, copy=False), frame.v.astype(np.float32, copy=False),
                  frame.label.astype(np.uint16, copy=False), frame.hit.astype(np.uint8, copy=False),
                  column_scale, row_scale,
                  points.view(np.float32).reshape(config.height, config.width, 6),
                  points.view(np.uint8).reshape(config.height, config.width, 24))
    cloud = PointCloud2(
        header=header, height=config.height, width=config.width,
        fields=point_fields(PIXEL_DTYPE), is_bigendian=False,
        point_step=PIXEL_DTYPE.itemsize, row_step=PIXEL_DTYPE.itemsize * config.width,
        is_dense=bool(np.isfinite(frame.depth).all()))
    cloud.data = data  # after construction: a constructor copies element by element
    return cloud


def camera_messages(header: Header, config: CameraConfig, frame: CameraFrame,
                    wanted: tuple[bool, bool, bool, bool] = (True, True, True, True)
                    ) -> tuple[Image | None, Image | None, CameraInfo | None, PointCloud2 | None]:
    """The four messages of one camera frame under one header (in the camera's optical
    frame): depth, colour, camera info, organised cloud; None for those not ``wanted``
    (built only for a topic someone reads)."""
    depth, color, info, cloud = wanted
    return (depth_image(header, frame) if depth else None,
            color_image(header, frame) if color else None,
            camera_info(header, config) if info else None,
            organized_cloud(header, config, frame) if cloud else None)
