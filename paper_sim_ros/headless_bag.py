"""The headless runner's rosbag2 output (``--bag DIR``): what the node would have published
for the run, from the simulated clock: ``/paper/points`` every frame and each of the
scenario's cameras' four topics at its rate, their poses on ``/tf_static`` (issue 16).

Kept apart from ``headless`` so that a run without ``--bag`` needs no ROS message packages.
"""
from __future__ import annotations

from builtin_interfaces.msg import Time
from std_msgs.msg import Header

from .bag_recorder import BagRecorder, message_type_name
from .core.camera import CameraFrame
from .core.scenarios import ScenarioCamera
from .core.simulator import Simulator
from .core.topology import vertex_normals
from .msg_adapters.camera import camera_messages
from .msg_adapters.point_cloud import create_cloud, sheet_points

FRAME_ID = 'world'


class HeadlessBag:
    """Writes one run into a bag; ``on_frame`` after every frame, ``close`` at the end."""

    def __init__(self, path: str, cameras: tuple[ScenarioCamera, ...]) -> None:
        """``cameras``: those whose frames ``on_frame`` will be given (their poses go on
        /tf_static now)."""
        self._bag = BagRecorder(path)
        for camera in cameras:
            self._bag.write_camera_transform(FRAME_ID, camera.config, 0)

    def on_frame(self, simulator: Simulator,
                 camera_frames: list[tuple[ScenarioCamera, CameraFrame]]) -> None:
        """The sheet's cloud, and each camera frame due now (``CameraRig.due_frames``)."""
        sheet = simulator.sheet
        nanoseconds = int(round(simulator.time * 1e9))
        stamp = Time(sec=nanoseconds // 1_000_000_000, nanosec=nanoseconds % 1_000_000_000)
        header = Header(frame_id=FRAME_ID, stamp=stamp)
        cloud = create_cloud(header, sheet_points(
            sheet.positions, vertex_normals(sheet.positions, sheet.triangles),
            simulator.damage_labels(), sheet.material))
        self._write('/paper/points', cloud, nanoseconds)
        for camera, frame in camera_frames:
            camera_header = Header(frame_id=camera.config.optical_frame, stamp=stamp)
            topic = f'/paper/{camera.config.name}'
            for suffix, message in zip(('depth/image_raw', 'color/image_raw', 'camera_info',
                                        'points'),
                                       camera_messages(camera_header, camera.config, frame)):
                self._write(f'{topic}/{suffix}', message, nanoseconds)

    def _write(self, topic: str, message, nanoseconds: int) -> None:
        self._bag.write(topic, message, nanoseconds, message_type_name(type(message)))

    def close(self) -> None:
        self._bag.close()
