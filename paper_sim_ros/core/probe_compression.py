"""Which compression Eq. 7 sees with the 'constrained' solver: the compression the probes
impose (a decision the paper, written for a soft spring mesh, leaves open).

With the 'paper' and 'explicit' solvers springs are forces and Eq. 7 sees the literal
r = l/l0 at each check. With the 'constrained' solver HINGE springs are held within
``max_compression`` of their rest length, so l/l0 says nothing about how hard the sheet is
pushed together, and what the projection removes in a sub-step depends on the sub-step
(docs/solver.md has the measurement). So there Eq. 7 sees the compression the probes
impose: over each frame each probe pushes some vertices by a displacement u, of which only
the part tangent to the sheet counts (the push straight into the sheet does not compress
it; its bending is what folds it, §4.2), and a HINGE spring (i, j) is shortened by
(u_i − u_j)·(x_j − x_i)/l; summed over the frames since the last check and divided by l0,
that is 1 − r. Which vertices a probe pushes:

- a probe that pinches the sheet against the table (a fingertip pressing it down, which
  grips it: ``Simulator._grip``) pushes the patch it pinches by its own travel, so the
  springs from that patch into the free sheet ahead of it take the compression. The patch
  is set by where the probe meets the table, not by how the free sheet lies against the
  probe's front, which depends on the sub-step (docs/solver.md);
- any other probe pushes the vertices within ``PROBE_REACH`` of it by u = max(0, Δc·n) n
  (Δc: its travel, n: the contact normal).

It is what the spring would have been compressed by had the sheet not moved out of the
way: kinematic, so it does not depend on the solver's convergence, and zero without a
moving probe, so a sheet at rest never breaks from numerical noise. The table is not a
source of damage. The kernel is ``kernels.accumulate_probe_compression``.
"""
from __future__ import annotations

import numpy as np

from .kernels import accumulate_probe_compression
from .probes import Probes
from .sheet import HINGE, Sheet
from .topology import vertex_normals

PROBE_REACH = 1.1
"""A vertex within this × radius of a probe counts as touched by it (contact leaves touched
vertices on the sphere, give or take the stretch projection's last corrections)."""


class ProbeCompression:
    """The compression the probes imposed on each spring since it was last cleared."""

    def __init__(self) -> None:
        self._pushed = np.zeros(0)

    def observe(self, sheet: Sheet, probes: Probes, grip_probe: np.ndarray,
                frame_motion: np.ndarray) -> None:
        """Add up the compression the probes' motion over this frame imposes on the HINGE
        springs they push (``probes``: with ``start`` and ``end``; ``grip_probe``: per
        vertex, the probe that pinches it against the table, or -1; ``frame_motion``: each
        vertex's displacement over the frame [m])."""
        if self._pushed.shape[0] != sheet.spring_count:
            self._pushed = np.zeros(sheet.spring_count)
        if not np.any(probes.active):
            return
        accumulate_probe_compression(
            sheet.positions, vertex_normals(sheet.positions, sheet.triangles), frame_motion,
            sheet.spring_vertices, sheet.spring_rest_length,
            np.flatnonzero(sheet.spring_kind == HINGE), probes.start, probes.end,
            probes.radius, probes.active, grip_probe, PROBE_REACH, self._pushed)

    def compression(self, sheet: Sheet) -> np.ndarray:
        """(S,) 1 − r of every spring of ``sheet`` (zeros when nothing was observed since
        the mesh last changed)."""
        if self._pushed.shape[0] == sheet.spring_count:
            return self._pushed.copy()
        return np.zeros(sheet.spring_count)

    def clear(self) -> None:
        """Start counting afresh (after a damage check)."""
        self._pushed = np.zeros(0)
