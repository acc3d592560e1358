"""The headless runner's rosbag2 output (``--bag DIR``): what the node would have published
for the run, from the simulated clock: ``/paper/points`` every frame and the default
camera's four topics at its rate, its pose on ``/tf_static`` (issue 16).

Kept apart from ``headless`` so that a run without ``--bag`` needs no ROS message packages.
"""
from __future__ import annotations

import math

from builtin_interfaces.msg import Time
from std_msgs.msg import Header

from .bag_recorder import BagRecorder, message_type_name
from .core.appearance import PaperAppearance
from .core.camera import default_camera, render_simulator
from .core.scenarios import Scenario
from .core.simulator import Simulator
from .core.topology import vertex_normals
from .msg_adapters.camera import camera_messages
from .msg_adapters.point_cloud import create_cloud, sheet_points

FRAME_ID = 'world'
DEFAULT_CAMERA_RATE = 15.0
"""The default camera's rate in a bag [Hz, simulated time]."""


class HeadlessBag:
    """Writes one run into a bag; ``on_frame`` after every frame, ``close`` at the end."""

    def __init__(self, path: str, scenario: Scenario, simulator: Simulator,
                 camera_rate: float | None) -> None:
        camera_rate = DEFAULT_CAMERA_RATE if camera_rate is None else camera_rate
        if not (math.isfinite(camera_rate) and camera_rate >= 0):
            raise ValueError(f'--camera-rate must be finite and >= 0 Hz, got {camera_rate}')
        self._bag = BagRecorder(path)
        self._appearance = PaperAppearance(scenario.appearance, simulator.sheet)
        self._camera = default_camera()
        self._camera_rate = camera_rate
        self._camera_slot = -1
        self._bag.write_camera_transform(FRAME_ID, self._camera, 0)

    def on_frame(self, simulator: Simulator) -> None:
        sheet = simulator.sheet
        nanoseconds = int(round(simulator.time * 1e9))
        stamp = Time(sec=nanoseconds // 1_000_000_000, nanosec=nanoseconds % 1_000_000_000)
        header = Header(frame_id=FRAME_ID, stamp=stamp)
        cloud = create_cloud(header, sheet_points(
            sheet.positions, vertex_normals(sheet.positions, sheet.triangles),
            simulator.damage_labels(), sheet.material))
        self._write('/paper/points', cloud, nanoseconds)
        slot = math.floor(simulator.time * self._camera_rate + 1e-9)
        if self._camera_rate > 0 and slot > self._camera_slot:
            self._camera_slot = slot
            frame = render_simulator(self._camera, simulator,
                                     self._appearance.vertex_colors(sheet))
            camera_header = Header(frame_id=self._camera.optical_frame, stamp=stamp)
            topic = f'/paper/{self._camera.name}'
            for suffix, message in zip(('depth/image_raw', 'color/image_raw', 'camera_info',
                                        'points'),
                                       camera_messages(camera_header, self._camera, frame)):
                self._write(f'{topic}/{suffix}', message, nanoseconds)

    def _write(self, topic: str, message, nanoseconds: int) -> None:
        self._bag.write(topic, message, nanoseconds, message_type_name(type(message)))

    def close(self) -> None:
        self._bag.close()
