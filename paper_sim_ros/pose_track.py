"""Where a probe is at a given time, from its stamped poses (no ROS: the node feeds it).

Poses arrive in bursts: over DDS, and whenever the node's tick and the publisher's timer
interleave unevenly, a frame sees no new pose and the next sees two. Stepped with the
latest pose, a probe moving at an even 0.1 m/s stood still for frames and then jumped
5–9 mm in one, and the sheet it dragged was strained 13 % (the demo, 33²; 3.5 % with the
same path sampled evenly, bench/bench_demo.py). The track places the probe at each
frame's own time instead: between two poses by linear interpolation, past the newest by
the velocity of the last two for at most 0.1 s if they are close in time (a probe that
stops overshoots by a tenth of a second's motion at most), before the oldest at the oldest.

A frame the simulation has stepped cannot be redone, so where the probe is *placed* must be
continuous even when later poses say it was elsewhere at that time. They do whenever frames
outrun the poses: a node behind the clock steps frames past its newest pose (held there once
the poses are too far apart to extrapolate from), and the next poses put the probe further
along. Read from the track alone the probe then jumped 16-32 mm in one frame and strained the
sheet up to 55 % (the demo, 65², one tick in two). ``place`` takes such a difference out over
about CATCH_UP_SECONDS of simulated time instead. Times in ns, positions in m.
"""
from __future__ import annotations

from collections import deque

import numpy as np

POSE_HISTORY = 32
"""Poses a track keeps: half a second of a 60 Hz stream, so that the time of the last frame
placed is still among them after a tick that ran long."""

MAX_EXTRAPOLATION_NS = 100_000_000
"""A track never extrapolates past its newest pose by more than this (0.1 s)."""

MAX_VELOCITY_GAP_NS = 100_000_000
"""Only two poses at most this far apart (0.1 s: a 10 Hz stream) give a velocity to
extrapolate with: poses far apart, as a node far behind the clock reads them, would carry
the probe past a turn of its path and back (the demo at 65², 0.5x real time: 23–27 mm
strides, 42 % strain)."""

CATCH_UP_SECONDS = 0.1
"""A placed probe closes the gap to where its poses put it by the share of this its frame
takes (a sixth a frame at 60 Hz: to 4 % in 0.3 s)."""


class PoseTrack:
    """The recent stamped positions of one probe."""

    def __init__(self) -> None:
        self._stamps: deque[int] = deque(maxlen=POSE_HISTORY)
        self._positions: deque[np.ndarray] = deque(maxlen=POSE_HISTORY)
        self._placed: tuple[int, np.ndarray, np.ndarray] | None = None
        """The last placement: time, position, and its difference from the track then."""

    def __len__(self) -> int:
        return len(self._stamps)

    @property
    def newest_stamp(self) -> int | None:
        return self._stamps[-1] if self._stamps else None

    def clear(self) -> None:
        """Forget the poses (not the last placement: see ``place``)."""
        self._stamps.clear()
        self._positions.clear()

    def forget_placement(self) -> None:
        """The probe left the simulation (it timed out, or the simulation was reset): its
        next placement starts where its poses put it."""
        self._placed = None

    def add(self, stamp_ns: int, position: np.ndarray) -> None:
        """A pose stamped ``stamp_ns``. One stamped no later than the newest starts the
        track afresh (the publisher restarted, or its clock jumped back)."""
        if self._stamps and stamp_ns <= self._stamps[-1]:
            self.clear()
        self._stamps.append(int(stamp_ns))
        self._positions.append(np.array(position, dtype=np.float64))

    def at(self, time_ns: int) -> np.ndarray:
        """The position at ``time_ns``; the track must not be empty."""
        stamps, positions = self._stamps, self._positions
        if len(stamps) == 1 or time_ns <= stamps[0]:
            return positions[0].copy()
        if time_ns >= stamps[-1]:
            interval = stamps[-1] - stamps[-2]
            if interval > MAX_VELOCITY_GAP_NS:
                return positions[-1].copy()
            ahead = min(time_ns - stamps[-1], MAX_EXTRAPOLATION_NS)
            return positions[-1] + (positions[-1] - positions[-2]) * (ahead / interval)
        later = next(k for k in range(1, len(stamps)) if stamps[k] >= time_ns)
        share = (time_ns - stamps[later - 1]) / (stamps[later] - stamps[later - 1])
        return positions[later - 1] + share * (positions[later] - positions[later - 1])

    def place(self, time_ns: int, simulated_seconds: float) -> np.ndarray:
        """Where the simulation puts the probe at ``time_ns``, ``simulated_seconds`` after
        its last placement: ``at(time_ns)``, plus what is left of the difference between
        the last placement and where the track now puts the probe at that time (1 less
        ``simulated_seconds / CATCH_UP_SECONDS`` of it). Where the track no longer reaches
        back to the last placement (a flood of poses outran POSE_HISTORY within a tick),
        the probe goes evenly from there to the oldest pose. The track must not be
        empty."""
        oldest = self._stamps[0]
        offset = np.zeros(3)
        if self._placed is None:
            position = self.at(time_ns)
        elif self._placed[0] < oldest and time_ns < oldest:
            placed_ns, placed_position, _ = self._placed
            share = (time_ns - placed_ns) / (oldest - placed_ns)
            position = placed_position + share * (self._positions[0] - placed_position)
        else:
            placed_ns, placed_position, offset = self._placed
            if placed_ns >= oldest:
                offset = placed_position - self.at(placed_ns)
            offset = max(0.0, 1.0 - simulated_seconds / CATCH_UP_SECONDS) * offset
            position = self.at(time_ns) + offset
        self._placed = (int(time_ns), position, offset)
        return position.copy()
