"""The sphere probes of one frame: where each starts and ends it (SPEC §3)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Probes:
    """Sphere probes. Centres in m; ``start`` is where each was at the frame's start."""

    radius: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """(P,) float64 [m]."""
    start: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    """(P, 3) float64 [m]: centres at the start of the frame."""
    end: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    """(P, 3) float64 [m]: centres at the end of the frame."""
    active: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    """(P,) bool: an inactive probe touches nothing."""

    @property
    def count(self) -> int:
        return int(self.radius.shape[0])
