"""A run's virtual cameras, each rendered when its rate says so: the frames a headless run's
bag and Rerun recording both take, so a camera renders once per frame it is due."""
from __future__ import annotations

import math

import numpy as np

from .appearance import AppearanceConfig, PaperAppearance
from .camera import CameraFrame, render_simulator, with_depth_noise
from .scenarios import ScenarioCamera
from .simulator import Simulator


class CameraRig:
    """Cameras on the slot grid t = k / rate of simulated time, depth noise seeded by the
    run's seed, the frame number and the camera's index (the same frames for the same run)."""

    def __init__(self, cameras: tuple[ScenarioCamera, ...], appearance: AppearanceConfig,
                 simulator: Simulator, seed: int) -> None:
        self.cameras = tuple(camera for camera in cameras if camera.rate > 0)
        self._last_slot = [-1] * len(self.cameras)
        self._seed = seed
        # the texture is built only for a rig that renders
        self._appearance = (PaperAppearance(appearance, simulator.sheet) if self.cameras
                            else None)

    def due_frames(self, simulator: Simulator) -> list[tuple[ScenarioCamera, CameraFrame]]:
        """The cameras whose next slot has come at ``simulator.time``, with what they see."""
        frames = []
        colors = None
        for index, camera in enumerate(self.cameras):
            slot = math.floor(simulator.time * camera.rate + 1e-9)
            if slot <= self._last_slot[index]:
                continue
            self._last_slot[index] = slot
            if colors is None:
                colors = self._appearance.vertex_colors(simulator.sheet)
            rng = np.random.default_rng([self._seed, simulator.frame, index])
            frames.append((camera, with_depth_noise(
                render_simulator(camera.config, simulator, colors),
                camera.depth_noise_stddev, rng)))
        return frames
