"""A scripted probe for the demo: presses into the sheet, drags across it, lifts, returns.

    ros2 run paper_sim_ros paper_sim_scripted_probe
    python -m paper_sim_ros.scripted_probe --ros-args -p period:=6.0

Publishes ``geometry_msgs/PoseStamped`` on ``probe/pose`` (parameter ``topic``) in
``frame_id`` at ``rate``; the path is a pure function of the time since the node started on
its clock (wall clock or ``/clock``), so it is the same in every run.
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

PHASES = (('descend', 0.15), ('drag', 0.55), ('lift', 0.15), ('return', 0.15))
"""The share of a period each phase takes, in order."""


@dataclass(frozen=True)
class ProbePath:
    """Press at ``start`` down to ``press_height``, drag to ``end``, lift to ``hover_height``,
    move back above ``start``. Heights are of the probe centre [m]."""

    start: tuple = (-0.06, -0.09)
    end: tuple = (0.06, 0.09)
    press_height: float = 0.019
    hover_height: float = 0.05
    period: float = 6.0

    def __post_init__(self) -> None:
        values = [*self.start, *self.end, self.press_height, self.hover_height, self.period]
        if len(self.start) != 2 or len(self.end) != 2 or not all(map(math.isfinite, values)):
            raise ValueError('start and end must be two finite numbers each; heights finite')
        if self.period <= 0:
            raise ValueError(f'period must be > 0, got {self.period}')

    def position(self, seconds: float) -> np.ndarray:
        """The probe centre at ``seconds`` after the start (periodic)."""
        phase = (seconds % self.period) / self.period
        start = np.array([*self.start, self.hover_height])
        pressed_start = np.array([*self.start, self.press_height])
        pressed_end = np.array([*self.end, self.press_height])
        lifted_end = np.array([*self.end, self.hover_height])
        waypoints = (start, pressed_start, pressed_end, lifted_end, start)
        for index, (_, share) in enumerate(PHASES):
            if phase <= share or index == len(PHASES) - 1:
                fraction = min(phase / share, 1.0)
                # smooth start and stop of each phase
                eased = 0.5 - 0.5 * math.cos(math.pi * fraction)
                return waypoints[index] + eased * (waypoints[index + 1] - waypoints[index])
            phase -= share
        return start


def _float_range(low: float, high: float) -> list[FloatingPointRange]:
    return [FloatingPointRange(from_value=low, to_value=high, step=0.0)]


class ScriptedProbe(Node):
    """Publishes the poses of a ``ProbePath``."""

    def __init__(self, **node_kwargs) -> None:
        super().__init__('scripted_probe', **node_kwargs)
        defaults = ProbePath()
        read_only = {'read_only': True}
        self.declare_parameter('topic', 'probe/pose', ParameterDescriptor(
            description='PoseStamped topic of the probe', **read_only))
        self.declare_parameter('frame_id', 'world', ParameterDescriptor(
            description='Frame of the poses (the sheet frame)', **read_only))
        self.declare_parameter('rate', 60.0, ParameterDescriptor(
            description='Poses per second [Hz]', floating_point_range=_float_range(1.0, 1000.0),
            **read_only))
        self.declare_parameter('start', list(defaults.start), ParameterDescriptor(
            description='Where the press begins, x y [m]', **read_only))
        self.declare_parameter('end', list(defaults.end), ParameterDescriptor(
            description='Where the drag ends, x y [m]', **read_only))
        self.declare_parameter('press_height', defaults.press_height, ParameterDescriptor(
            description='Probe centre height while pressing [m]',
            floating_point_range=_float_range(-10.0, 10.0), **read_only))
        self.declare_parameter('hover_height', defaults.hover_height, ParameterDescriptor(
            description='Probe centre height between presses [m]',
            floating_point_range=_float_range(-10.0, 10.0), **read_only))
        self.declare_parameter('period', defaults.period, ParameterDescriptor(
            description='Seconds of one press-drag-lift-return cycle',
            floating_point_range=_float_range(0.1, 3600.0), **read_only))
        value = self._value
        self.path = ProbePath(start=tuple(value('start')), end=tuple(value('end')),
                              press_height=value('press_height'),
                              hover_height=value('hover_height'), period=value('period'))
        self._frame_id = value('frame_id')
        self._publisher = self.create_publisher(PoseStamped, value('topic'), 10)
        self._started = None
        self.create_timer(1.0 / value('rate'), self._on_timer)

    def _value(self, name: str):
        return self.get_parameter(name).value

    def _on_timer(self) -> None:
        now = self.get_clock().now()
        if self._started is None:
            self._started = now
        seconds = (now - self._started).nanoseconds * 1e-9
        x, y, z = self.path.position(seconds).tolist()
        msg = PoseStamped()
        msg.header.frame_id = self._frame_id
        msg.header.stamp = now.to_msg()
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = x, y, z
        msg.pose.orientation.w = 1.0
        self._publisher.publish(msg)


def main(args=None) -> int:
    return run_node(ScriptedProbe, args, 'scripted_probe')


if __name__ == '__main__':
    sys.exit(main())
