"""``visualization_msgs/MarkerArray`` serialised straight from numpy (the fast path).

Why: RViz wants one ``geometry_msgs/Point`` per point of a TRIANGLE_LIST or LINE_LIST, and
rclpy serialises a message by reading every one of those Python objects back (about 1 µs a
point, 100+ ms a frame for a 65 x 65 sheet). ``rclpy`` publishers also take the serialised
message as ``bytes`` (``Publisher.publish(bytes)`` → ``rcl_publish_serialized_message``), so we
write the CDR bytes ourselves: the small fields from the message objects, the large arrays
(points, colours) as numpy ``tobytes()``. The result is byte for byte what
``rclpy.serialization.serialize_message`` produces for the equivalent message object
(test_msg_adapters checks it), so subscribers cannot tell the difference.

Encoding: plain CDR, little endian (encapsulation ``00 01 00 00``), as rmw_fastrtps writes
ROS 2 messages. Primitives are aligned to their size, counted from the end of the 4-byte
encapsulation header; strings are a uint32 length including the terminating NUL, then the
bytes and the NUL; sequences a uint32 count, then the elements.
"""
from __future__ import annotations

import struct

import numpy as np
from visualization_msgs.msg import Marker

ENCAPSULATION = b'\x00\x01\x00\x00'
"""CDR, little endian."""
POINT_DTYPE = np.dtype('<f8')
COLOR_DTYPE = np.dtype('<f4')


class CdrWriter:
    """Appends CDR-encoded values to a buffer, keeping the alignment."""

    def __init__(self) -> None:
        self._parts: list[bytes] = [ENCAPSULATION]
        self._size = 0
        """Bytes written after the encapsulation header."""
        self.padding: list[tuple[int, int]] = []
        """[start, end) of every run of padding bytes in ``getvalue()``. (rmw_fastrtps leaves
        padding uninitialised, so only the other bytes can be compared with its output.)"""

    def _write(self, data: bytes) -> None:
        self._parts.append(data)
        self._size += len(data)

    def align(self, alignment: int) -> None:
        padding = -self._size % alignment
        if padding:
            start = len(ENCAPSULATION) + self._size
            self.padding.append((start, start + padding))
            self._write(b'\x00' * padding)

    def uint32(self, value: int) -> None:
        self.align(4)
        self._write(struct.pack('<I', value))

    def int32(self, value: int) -> None:
        self.align(4)
        self._write(struct.pack('<i', value))

    def boolean(self, value: bool) -> None:
        self._write(b'\x01' if value else b'\x00')

    def float64s(self, *values: float) -> None:
        self.align(8)
        self._write(struct.pack(f'<{len(values)}d', *values))

    def float32s(self, *values: float) -> None:
        self.align(4)
        self._write(struct.pack(f'<{len(values)}f', *values))

    def string(self, value: str) -> None:
        encoded = value.encode('utf-8') + b'\x00'
        self.uint32(len(encoded))
        self._write(encoded)

    def octets(self, data: bytes) -> None:
        """A ``uint8[]`` sequence."""
        self.uint32(len(data))
        self._write(bytes(data))

    def array(self, values: np.ndarray, alignment: int) -> None:
        """The elements of a non-empty sequence of fixed-size structs, as raw bytes (the
        count is written by the caller). An empty sequence has no padding."""
        if values.size:
            self.align(alignment)
            self._write(values.tobytes())

    def getvalue(self) -> bytes:
        return b''.join(self._parts)


def _header(writer: CdrWriter, header) -> None:
    writer.int32(header.stamp.sec)
    writer.uint32(header.stamp.nanosec)
    writer.string(header.frame_id)


def write_marker(writer: CdrWriter, marker: Marker, points: np.ndarray | None = None,
                 colors: np.ndarray | None = None) -> None:
    """One Marker. ``points`` (N, 3) and ``colors`` (M, 4) arrays, when given, stand for
    ``marker.points`` and ``marker.colors`` (which are then ignored)."""
    _header(writer, marker.header)
    writer.string(marker.ns)
    writer.int32(marker.id)
    writer.int32(marker.type)
    writer.int32(marker.action)
    position, orientation = marker.pose.position, marker.pose.orientation
    writer.float64s(position.x, position.y, position.z,
                    orientation.x, orientation.y, orientation.z, orientation.w)
    writer.float64s(marker.scale.x, marker.scale.y, marker.scale.z)
    color = marker.color
    writer.float32s(color.r, color.g, color.b, color.a)
    writer.int32(marker.lifetime.sec)
    writer.uint32(marker.lifetime.nanosec)
    writer.boolean(marker.frame_locked)
    if points is None:
        points = np.array([[p.x, p.y, p.z] for p in marker.points], dtype=POINT_DTYPE)
    points = np.ascontiguousarray(points, dtype=POINT_DTYPE).reshape(-1, 3)
    writer.uint32(points.shape[0])
    writer.array(points, 8)
    if colors is None:
        colors = np.array([[c.r, c.g, c.b, c.a] for c in marker.colors], dtype=COLOR_DTYPE)
    colors = np.ascontiguousarray(colors, dtype=COLOR_DTYPE).reshape(-1, 4)
    writer.uint32(colors.shape[0])
    writer.array(colors, 4)
    writer.string(marker.texture_resource)
    _header(writer, marker.texture.header)
    writer.string(marker.texture.format)
    writer.octets(marker.texture.data)
    uv = np.array([[c.u, c.v] for c in marker.uv_coordinates], dtype=COLOR_DTYPE)
    writer.uint32(uv.shape[0])
    writer.array(uv, 4)
    writer.string(marker.text)
    writer.string(marker.mesh_resource)
    writer.string(marker.mesh_file.filename)
    writer.octets(marker.mesh_file.data)
    writer.boolean(marker.mesh_use_embedded_materials)


def serialize_marker_array(parts: list[tuple[Marker, np.ndarray | None, np.ndarray | None]],
                           writer: CdrWriter | None = None) -> bytes:
    """A MarkerArray of ``(marker, points, colors)`` parts (see ``write_marker``) as the
    bytes ``Publisher.publish`` accepts (written into ``writer`` when one is given)."""
    writer = writer if writer is not None else CdrWriter()
    writer.uint32(len(parts))
    for marker, points, colors in parts:
        write_marker(writer, marker, points, colors)
    return writer.getvalue()
