"""Every message the node publishes, written to a rosbag2 directory with MCAP storage
(issue 16), so that a ROS 2 user replays a session with ``ros2 bag play DIR``.

Written with ``rosbags`` (the maintained pure-Python rosbag2 library; there is no rosbag2
wheel): the messages go in as the CDR bytes rclpy serialises, so a bag holds exactly what
went over DDS; message definitions come from rosbags' Jazzy typestore. The camera's pose is
on ``/tf_static`` (``tf2_msgs/TFMessage``, built with the typestore: no tf2 wheel exists).
``close`` writes the bag's metadata; the node calls it on SIGINT/SIGTERM too.
"""
from __future__ import annotations

import os
from pathlib import Path

from rclpy.serialization import serialize_message
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from .core.camera import CameraConfig

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)


def message_type_name(message_class) -> str:
    """'sensor_msgs/msg/PointCloud2' of a generated rclpy message class."""
    package = message_class.__module__.split('.')[0]
    return f'{package}/msg/{message_class.__name__}'


def check_bag_path(path: str) -> None:
    """Refuse, before anything runs, a bag directory that exists or cannot be created
    (``ValueError`` with the reason)."""
    if os.path.exists(path):
        raise ValueError(f'bag_path {path!r} exists; rosbag2 writes a new directory')
    parent = os.path.dirname(os.path.abspath(path))
    if not (os.path.isdir(parent) and os.access(parent, os.W_OK)):
        raise ValueError(f'bag_path {path!r}: cannot create it in {parent!r}')


class BagRecorder:
    """One rosbag2 (MCAP) directory; a connection per topic, added on its first message."""

    def __init__(self, path: str) -> None:
        check_bag_path(path)
        self.path = path
        self._writer = Writer(Path(path), version=9, storage_plugin=StoragePlugin.MCAP)
        self._writer.open()
        self._connections: dict[str, object] = {}
        self.counts: dict[str, int] = {}

    def _connection(self, topic: str, type_name: str):
        if topic not in self._connections:
            self._connections[topic] = self._writer.add_connection(
                topic, type_name, typestore=TYPESTORE)
            self.counts[topic] = 0
        return self._connections[topic]

    def write(self, topic: str, message, stamp_ns: int, type_name: str) -> None:
        """Record ``message`` (an rclpy message, or its CDR bytes) of type ``type_name``
        ('pkg/msg/Name') at ``stamp_ns`` [ns]."""
        data = bytes(message) if isinstance(message, (bytes, bytearray, memoryview)) \
            else serialize_message(message)
        self._writer.write(self._connection(topic, type_name), stamp_ns, data)
        self.counts[topic] += 1

    def write_camera_transform(self, parent_frame: str, camera: CameraConfig,
                               stamp_ns: int) -> None:
        """The camera's optical frame in ``parent_frame``, once, on /tf_static."""
        types = TYPESTORE.types
        seconds, nanoseconds = divmod(stamp_ns, 1_000_000_000)
        header = types['std_msgs/msg/Header'](
            stamp=types['builtin_interfaces/msg/Time'](sec=seconds, nanosec=nanoseconds),
            frame_id=parent_frame)
        x, y, z = camera.position
        qx, qy, qz, qw = camera.orientation
        transform = types['geometry_msgs/msg/TransformStamped'](
            header=header, child_frame_id=camera.optical_frame,
            transform=types['geometry_msgs/msg/Transform'](
                translation=types['geometry_msgs/msg/Vector3'](x=x, y=y, z=z),
                rotation=types['geometry_msgs/msg/Quaternion'](x=qx, y=qy, z=qz, w=qw)))
        message = types['tf2_msgs/msg/TFMessage'](transforms=[transform])
        self.write('/tf_static', TYPESTORE.serialize_cdr(message, 'tf2_msgs/msg/TFMessage'),
                   stamp_ns, 'tf2_msgs/msg/TFMessage')

    def close(self) -> None:
        """Write the metadata; the bag is complete. Idempotent."""
        if self._writer is not None:
            self._writer.close()
            self._writer = None
