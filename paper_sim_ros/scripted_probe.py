"""A scripted probe for the demo: approaches, presses into the sheet, drags across, retreats.

    ros2 run paper_sim_ros paper_sim_probe
    python -m paper_sim_ros.scripted_probe --ros-args -p period:=6.0

Publishes ``geometry_msgs/PoseStamped`` on ``probe/pose`` (parameter ``topic``) in
``frame_id`` at ``rate``. The path is a pure function of the time since the node started on
its clock (wall clock or ``/clock``), so it is the same in every run: for ``start_delay``
seconds nothing (the probe is away), then in every ``period`` it goes approach →
press_start → press_end → retreat → approach, easing in and out of each leg.

The defaults suit the demo: an A4 sheet clamped at its short edge at y = -0.1485 m hangs
down; the probe pushes 1.5 cm into its hanging part from the +y side and drags along x.
"""
from __future__ import annotations

from dataclasses import dataclass
import math
import sys

import numpy as np
from rclpy.node import Node
from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor
from geometry_msgs.msg import PoseStamped

from .node_runner import run_node

LEGS = (0.15, 0.55, 0.15, 0.15)
"""The share of a period each leg takes: approach→press_start, press_start→press_end,
press_end→retreat, retreat→approach."""


@dataclass(frozen=True)
class ProbePath:
    """Waypoints of the probe centre [m] in the sheet frame, and the timing [s]."""

    approach: tuple = (-0.06, -0.08, -0.10)
    press_start: tuple = (-0.06, -0.145, -0.10)
    press_end: tuple = (0.06, -0.145, -0.10)
    retreat: tuple = (0.06, -0.08, -0.10)
    period: float = 6.0
    start_delay: float = 2.0

    def __post_init__(self) -> None:
        for name in ('approach', 'press_start', 'press_end', 'retreat'):
            point = getattr(self, name)
            if len(point) != 3 or not all(math.isfinite(float(v)) for v in point):
                raise ValueError(f'{name} must be three finite numbers, got {point!r}')
        if not (math.isfinite(self.period) and self.period > 0):
            raise ValueError(f'period must be > 0, got {self.period}')
        if not (math.isfinite(self.start_delay) and self.start_delay >= 0):
            raise ValueError(f'start_delay must be >= 0, got {self.start_delay}')

    def position(self, seconds: float) -> np.ndarray | None:
        """The probe centre ``seconds`` after the start, or None during the start delay."""
        if seconds < self.start_delay:
            return None
        phase = ((seconds - self.start_delay) % self.period) / self.period
        waypoints = [np.asarray(point, dtype=np.float64) for point in
                     (self.approach, self.press_start, self.press_end, self.retreat,
                      self.approach)]
        for leg, share in enumerate(LEGS):
            if phase <= share or leg == len(LEGS) - 1:
                fraction = min(phase / share, 1.0)
                eased = 0.5 - 0.5 * math.cos(math.pi * fraction)  # smooth start and stop
                return waypoints[leg] + eased * (waypoints[leg + 1] - waypoints[leg])
            phase -= share
        return waypoints[0]


def _float_range(low: float, high: float) -> list[FloatingPointRange]:
    return [FloatingPointRange(from_value=low, to_value=high, step=0.0)]


class ScriptedProbe(Node):
    """Publishes the poses of a ``ProbePath``."""

    def __init__(self, **node_kwargs) -> None:
        super().__init__('scripted_probe', **node_kwargs)
        defaults = ProbePath()

        def declare(name, value, description, **descriptor):
            self.declare_parameter(name, value, ParameterDescriptor(
                description=description, read_only=True, **descriptor))
            return self.get_parameter(name).value
        topic = declare('topic', 'probe/pose', 'PoseStamped topic of the probe')
        self._frame_id = declare('frame_id', 'world', 'Frame of the poses (the sheet frame)')
        rate = declare('rate', 60.0, 'Poses per second [Hz]',
                       floating_point_range=_float_range(1.0, 1000.0))
        waypoints = {name: tuple(declare(name, list(getattr(defaults, name)),
                                         f'Waypoint {name}: probe centre x y z [m]'))
                     for name in ('approach', 'press_start', 'press_end', 'retreat')}
        period = declare('period', defaults.period, 'Seconds of one cycle of the path',
                         floating_point_range=_float_range(0.1, 3600.0))
        delay = declare('start_delay', defaults.start_delay,
                        'Seconds before the first pose (the probe is away until then)',
                        floating_point_range=_float_range(0.0, 3600.0))
        self.path = ProbePath(**waypoints, period=period, start_delay=delay)
        self._publisher = self.create_publisher(PoseStamped, topic, 10)
        self._started = None
        self.create_timer(1.0 / rate, self._on_timer)

    def _on_timer(self) -> None:
        now = self.get_clock().now()
        if self._started is None:
            self._started = now
        position = self.path.position((now - self._started).nanoseconds * 1e-9)
        if position is None:
            return
        msg = PoseStamped()
        msg.header.frame_id = self._frame_id
        msg.header.stamp = now.to_msg()
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = position.tolist()
        msg.pose.orientation.w = 1.0
        self._publisher.publish(msg)


def main(args=None) -> int:
    return run_node(ScriptedProbe, args, 'scripted_probe')


if __name__ == '__main__':
    sys.exit(main())
