"""The headless runner's rosbag2 output (``--bag DIR``): what the node would have published
for the run, from the simulated clock: ``/paper/points`` every frame and each of the
scenario's cameras' four topics at its rate, their poses on ``/tf_static`` (issue 16).

Kept apart from ``headless`` so that a run without ``--bag`` needs no ROS message packages.
"""
from __future__ import annotations

from dataclasses import replace
import math

import numpy as np

from builtin_interfaces.msg import Time
from std_msgs.msg import Header

from .bag_recorder import BagRecorder, message_type_name
from .core.appearance import PaperAppearance
from .core.camera import render_simulator, with_depth_noise
from .core.scenarios import Scenario
from .core.simulator import Simulator
from .core.topology import vertex_normals
from .msg_adapters.camera import camera_messages
from .msg_adapters.point_cloud import create_cloud, sheet_points

FRAME_ID = 'world'


class HeadlessBag:
    """Writes one run into a bag; ``on_frame`` after every frame, ``close`` at the end."""

    def __init__(self, path: str, scenario: Scenario, simulator: Simulator,
                 camera_rate: float | None) -> None:
        """``camera_rate``: every camera's rate [Hz] (0: no camera), instead of the
        scenario's own (None)."""
        if camera_rate is not None and not (math.isfinite(camera_rate) and camera_rate >= 0):
            raise ValueError(f'--camera-rate must be finite and >= 0 Hz, got {camera_rate}')
        self._cameras = [camera if camera_rate is None else replace(camera, rate=camera_rate)
                         for camera in scenario.cameras]
        self._cameras = [camera for camera in self._cameras if camera.rate > 0]
        self._slots = [-1] * len(self._cameras)
        self._seed = scenario.config.seed
        self._bag = BagRecorder(path)
        self._appearance = PaperAppearance(scenario.appearance, simulator.sheet)
        for camera in self._cameras:
            self._bag.write_camera_transform(FRAME_ID, camera.config, 0)

    def on_frame(self, simulator: Simulator) -> None:
        sheet = simulator.sheet
        nanoseconds = int(round(simulator.time * 1e9))
        stamp = Time(sec=nanoseconds // 1_000_000_000, nanosec=nanoseconds % 1_000_000_000)
        header = Header(frame_id=FRAME_ID, stamp=stamp)
        cloud = create_cloud(header, sheet_points(
            sheet.positions, vertex_normals(sheet.positions, sheet.triangles),
            simulator.damage_labels(), sheet.material))
        self._write('/paper/points', cloud, nanoseconds)
        colors = None
        for index, camera in enumerate(self._cameras):
            slot = math.floor(simulator.time * camera.rate + 1e-9)
            if slot <= self._slots[index]:
                continue
            self._slots[index] = slot
            if colors is None:
                colors = self._appearance.vertex_colors(sheet)
            rng = np.random.default_rng([self._seed, simulator.frame, index])
            frame = with_depth_noise(render_simulator(camera.config, simulator, colors),
                                     camera.depth_noise_stddev, rng)
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
