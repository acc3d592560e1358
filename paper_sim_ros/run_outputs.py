"""What a headless run writes besides its metrics: a Rerun recording and a rosbag2 bag, each
camera rendered once per frame it is due for both (``paper_sim_headless --rrd/--bag``, and
every run of a dataset batch). The bag's module is imported only for a bag, so a run
without one needs no ROS message packages."""
from __future__ import annotations

from dataclasses import replace
import math

from .core import Scenario, Simulator
from .core.camera_rig import CameraRig
from .rerun_logger import RerunRecorder


def scenario_cameras(scenario: Scenario, camera_rate: float | None) -> tuple:
    """The scenario's cameras, each at ``camera_rate`` [Hz] when given (0: none)."""
    if camera_rate is None:
        return scenario.cameras
    if not (math.isfinite(camera_rate) and camera_rate >= 0):
        raise ValueError(f'--camera-rate must be finite and >= 0 Hz, got {camera_rate}')
    return tuple(replace(camera, rate=camera_rate) for camera in scenario.cameras)


class RunOutputs:
    """The outputs of one run: ``on_frame`` after every frame, ``close`` at the end (always:
    each file is then complete). A bag has the scenario's cameras at their rates (or
    ``camera_rate``); a recording has them only when ``camera_rate`` is given, as images
    would dwarf the rest of it."""

    def __init__(self, scenario: Scenario, simulator: Simulator, *, rrd: str | None = None,
                 bag: str | None = None, camera_rate: float | None = None,
                 application_id: str = 'paper_sim_headless') -> None:
        """ValueError or OSError (nothing left open) for a bad rate or an unwritable path."""
        if camera_rate is not None and not (bag or rrd):
            raise ValueError('--camera-rate is the rate of the cameras in --bag or --rrd; '
                             'give one')
        self._dt = scenario.config.solver.dt
        self._recorder = self._bag = None
        wanted = scenario_cameras(scenario, camera_rate) if bag or camera_rate is not None \
            else ()
        self._rig = CameraRig(wanted, scenario.appearance, simulator, scenario.config.seed)
        self._recorded_cameras = camera_rate is not None
        try:
            if rrd:
                self._recorder = RerunRecorder(
                    application_id, path=rrd, recording_info={'scenario': scenario.mapping},
                    appearance=scenario.appearance,
                    cameras=tuple(camera.config.name for camera in self._rig.cameras)
                    if self._recorded_cameras else ())
            if bag:
                from .headless_bag import HeadlessBag
                self._bag = HeadlessBag(bag, self._rig.cameras)
        except BaseException:
            self.close()
            raise

    def on_frame(self, simulator: Simulator, step_seconds: float) -> None:
        """Log and write frame ``simulator.frame``, which took ``step_seconds`` to step."""
        if self._recorder is None and self._bag is None:
            return
        camera_frames = self._rig.due_frames(simulator)
        if self._recorder is not None:
            self._recorder.log_frame(simulator.time, simulator, scalars={
                'step_time': step_seconds,
                'real_time_factor': self._dt / step_seconds if step_seconds > 0 else 0.0,
                'energy': simulator.energy(),
                'max_strain': simulator.max_strain(),
            })
            for camera, frame in camera_frames if self._recorded_cameras else ():
                self._recorder.log_camera(simulator.time, simulator, camera.config, frame)
        if self._bag is not None:
            self._bag.on_frame(simulator, camera_frames)

    def close(self) -> None:
        """Finish every file (idempotent)."""
        for output in (self._recorder, self._bag):
            if output is not None:
                output.close()
