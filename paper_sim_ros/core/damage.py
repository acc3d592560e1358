"""The damage policy (SPEC §4, paper §3.2–3.3, Eq. 7–8, Fig. 4–8): which HINGE springs
break, which hinges fold, and random crumpling.

``DamageModel`` decides, at a fixed rate in simulated time (``DamageConfig.check_rate``,
independent of the sub-steps), which HINGE springs break (Eq. 7: P = (1 − r)^φ at each
check, most compressed first) and which interior edges fold (their BEND
spring came short of ``fold_threshold``), and has ``MeshEditor`` (core/mesh_editing.py)
apply them. Which compression 1 − r Eq. 7 sees depends on the solver:
core/probe_compression.py. A break remembers the crease as if the spring had been pushed
to l_t = max(r, ``min_crease_ratio``)·l0.

Eq. 7 is drawn as a hazard (a decision the paper leaves open): each spring gets one
threshold E ~ Exp(1), seeded and in the order the springs are made, and breaks at the
first check where its accumulated −Σ ln(1 − P) reaches E. Surviving n checks then has
probability Π (1 − P), exactly as with a fresh uniform draw per candidate and check, but
which springs break depends only on how each one is pushed, not on how many draws the
other candidates took before it: a sub-step count or grip that adds or drops one
candidate somewhere no longer redraws every later break (docs/solver.md, "Damage").
"""
from __future__ import annotations

import logging
import math

import numpy as np

from .config import DamageConfig
from .kernels import springs_shorter_than
from .mesh_editing import MeshEditor, breakable_springs, spring_lengths
from .probe_compression import ProbeCompression
from .probes import Probes
from .sheet import BEND, HINGE, Sheet

log = logging.getLogger(__name__)

FOLD_MIN_AREA = 0.7
"""An edge folds only while its two triangles keep this share of their flat area: a BEND
spring also comes short when the solver momentarily crushes a region under a probe, and
that is not a fold to remember."""


class DamageModel:
    """Breaks and folds of one simulated sheet, at ``check_rate`` in simulated time.

    ``advance`` is called once per frame, after the sub-steps, with the probes' motion in
    that frame; ``crumple`` applies random damage. ``breaks``, ``folds`` and ``creases``
    count since construction (the simulator builds a new model on reset).
    """

    def __init__(self, config: DamageConfig, seed: int, aux_stiffness: float,
                 held_inextensible: bool = False) -> None:
        """``held_inextensible``: the solver holds HINGE springs at their rest length (the
        'constrained' one), so Eq. 7 sees only the compression the probes impose."""
        self.config = config
        self.aux_stiffness = aux_stiffness
        self.held_inextensible = held_inextensible
        self.rng = np.random.default_rng([seed, 0x0DA3A6E])
        """The random side a break on a flat sheet folds to."""
        self._thresholds = np.random.default_rng([seed, 0xB4EA7])
        """Eq. 7's thresholds: the k-th spring made takes the k-th draw."""
        self._rethresholds = np.random.default_rng([seed, 0xB4EA8])
        """A broken spring's half keeps its index and takes its next threshold from here."""
        self.break_threshold = np.zeros(0)
        """(S,) each spring's E ~ Exp(1): it breaks once ``break_hazard`` reaches it."""
        self.break_hazard = np.zeros(0)
        """(S,) −Σ ln(1 − P) over the checks that found the spring compressed."""
        self.breaks = 0
        self.folds = 0
        self.creases: list[tuple[int, int, int]] = []
        """(i, m, j) of every break: m is the vertex inserted between i and j."""
        self.capped = False
        self.stressed = False
        """Whether the last check found springs compressed enough to gather hazard (a sheet
        so stressed may still break at rest: it does not fall asleep)."""
        self._clock = 0.0
        self.probe_compression = ProbeCompression()
        """What the probes pushed since the last check (used when ``held_inextensible``)."""

    def compression(self, sheet: Sheet) -> np.ndarray:
        """1 − r of every spring as Eq. 7 sees it: l/l0 of a spring that is a force, the
        compression the probes imposed on a held one (core/probe_compression.py)."""
        if not self.held_inextensible:
            lengths = spring_lengths(sheet.positions, sheet.spring_vertices)
            return 1.0 - lengths / sheet.spring_rest_length
        return self.probe_compression.compression(sheet)

    # ------------------------------------------------------------------------ stepping
    def advance(self, sheet: Sheet, dt: float, probes: Probes, grip_probe: np.ndarray,
                frame_motion: np.ndarray) -> bool:
        """A frame of ``dt`` has passed (``probes``: where they went in it; ``grip_probe``:
        per vertex, the probe pinching it, or -1; ``frame_motion``: each vertex's
        displacement in it [m]); run the checks that fall due. Returns True if the mesh
        changed (the caller must then rebuild what derives from it)."""
        if not self.config.enabled:
            return False
        if self.held_inextensible and probes.count:
            self.probe_compression.observe(sheet, probes, grip_probe, frame_motion)
        self._clock += dt * self.config.check_rate
        periods = int(math.floor(self._clock + 1e-9))
        if periods == 0:
            return False
        self._clock -= periods
        changed = self.check(sheet, periods)
        self.probe_compression.clear()
        return changed

    def check(self, sheet: Sheet, periods: int = 1) -> bool:
        """One damage check (``periods`` checks' worth of probability): Eq. 7 breaks, then
        hinge folds. Returns True if the mesh changed."""
        config = self.config
        self.stressed = False
        if self._at_cap(sheet.vertex_count):
            return False
        compression = self.compression(sheet)
        compressed = np.flatnonzero(compression > config.compression_floor)
        candidates = compressed[breakable_springs(
            sheet.spring_kind[compressed], sheet.spring_vertices[compressed],
            sheet.spring_rest_length[compressed], sheet.pinned, config.min_breakable_length)]
        self.stressed = candidates.size > 0
        broken = np.zeros(0, dtype=np.int64)
        if candidates.size:
            self._draw_thresholds(sheet.spring_count)
            probability = np.minimum(compression[candidates], 1.0) ** config.fragility
            with np.errstate(divide='ignore'):  # P = 1: an infinite hazard, it breaks
                self.break_hazard[candidates] -= periods * np.log1p(-probability)
            broken = candidates[self.break_hazard[candidates]
                                >= self.break_threshold[candidates]]
            # most compressed first; a stable order keeps the run reproducible
            broken = broken[np.argsort(-compression[broken], kind='stable')]
        folding = springs_shorter_than(sheet.positions, sheet.spring_vertices,
                                       sheet.spring_rest_length, sheet.spring_kind, BEND,
                                       config.fold_threshold)
        if broken.size == 0 and folding.size == 0:
            return False
        editor = MeshEditor(sheet, self.aux_stiffness)
        for spring in broken.tolist():
            if self._at_cap(editor.vertex_count):
                break
            # the length the spring was pushed to: 1 − c of its rest (the compression
            # Eq. 7 saw, which in a projected sheet is more than its length now shows)
            if not editor.can_break(spring, config.min_breakable_length):
                continue
            ratio = max(1.0 - float(compression[spring]), config.min_crease_ratio)
            crease = ratio * float(sheet.spring_rest_length[spring])
            editor.break_spring(spring, crease, self.rng, config.area_conservation)
            self.breaks += 1
            # its index now holds one of its halves: a new spring, with a new threshold
            self.break_hazard[spring] = 0.0
            self.break_threshold[spring] = self._rethresholds.exponential()
        for spring in folding.tolist():
            if self.capped:
                break
            # a break may have moved this BEND spring's end: test it again
            threshold = config.fold_threshold * editor.rest_length.data[spring]
            if editor.kind.data[spring] == BEND and editor.length(spring) < threshold \
                    and editor.folds_by_bending(spring, FOLD_MIN_AREA):
                editor.fold(spring)
                self.folds += 1
        if editor.changed:
            editor.commit()
            self.creases += editor.creases
        return editor.changed

    def _draw_thresholds(self, spring_count: int) -> None:
        """Thresholds (and no hazard yet) for the springs made since the last call:
        springs are only ever appended, so the k-th spring made always gets the k-th
        draw of its generator."""
        new = spring_count - self.break_threshold.size
        if new > 0:
            self.break_threshold = np.concatenate([self.break_threshold,
                                                   self._thresholds.exponential(size=new)])
            self.break_hazard = np.concatenate([self.break_hazard, np.zeros(new)])

    def _at_cap(self, vertex_count: int) -> bool:
        if vertex_count >= self.config.max_vertices:
            if not self.capped:
                log.warning('damage stopped: the sheet reached the vertex cap of %d '
                            '(DamageConfig.max_vertices)', self.config.max_vertices)
            self.capped = True
        return self.capped

    # ------------------------------------------------------------------- random damage
    def crumple(self, sheet: Sheet, count: int, seed: int, floor: float = -math.inf) -> int:
        """Random damage (SPEC §4.3, paper Fig. 5, 7, 8): ``count`` events on randomly
        chosen springs through the same operations, drawn from their own generator
        seeded with ``seed``. A break compresses its spring to l_t = r·l0 with r drawn in
        [min_crease_ratio, 1); a fold gives the BEND spring of an edge an AUX spring of
        rest r·d0 with r in [min_crease_ratio, fold_threshold) and lifts the edge's ends
        to a random side (a flat sheet would otherwise have no side to fold to).
        Random damage is plastic: what it moved rests in its new shape
        (``moved_by_crumple``). Nothing rests below ``floor`` (the table's height): a fold
        or break that went down into it comes up instead, as paper crumpled on a table
        does. Returns the number of events applied (fewer at the vertex cap)."""
        if count < 0:
            raise ValueError(f'crumple count must be >= 0, got {count}')
        config = self.config
        rng = np.random.default_rng([seed, 0xC3C3])
        editor = MeshEditor(sheet, self.aux_stiffness)
        first_spring = editor.kind.count
        moved: list[int] = []
        applied = 0
        for _ in range(count):
            if self._at_cap(editor.vertex_count):
                break
            want_fold = rng.random() < config.crumple_fold_fraction
            count_now = editor.kind.count
            kinds = editor.kind.data[:count_now]
            bend = np.flatnonzero(kinds == BEND) if want_fold else np.zeros(0)
            if bend.size:
                spring = int(bend[rng.integers(bend.size)])
                upper = max(config.fold_threshold, config.min_crease_ratio)
                ratio = rng.uniform(config.min_crease_ratio, upper)
                rest = ratio * float(editor.rest_length.data[spring])
                moved += self._lift_hinge(editor, spring, ratio, rng)
                editor.fold(spring, rest)
                self.folds += 1
            else:
                breakable = breakable_springs(kinds, editor.spring_vertices.data[:count_now],
                                              editor.rest_length.data[:count_now],
                                              editor.pinned.data, config.min_breakable_length)
                if breakable.size == 0:
                    continue
                spring = int(breakable[rng.integers(breakable.size)])
                if not editor.can_break(spring, config.min_breakable_length):
                    continue
                ratio = rng.uniform(config.min_crease_ratio, 1.0)
                l0 = float(editor.rest_length.data[spring])
                moved.append(editor.break_spring(spring, ratio * l0, rng,
                                                 config.area_conservation))
                self.breaks += 1
            applied += 1
        editor.commit()
        # mirrored in the table's plane: held to a rest shape inside the table, a sheet
        # crumpled on it rested strained 16-23 % (65², 5 x 20 events, the node's defaults)
        below = sheet.positions[:, 2] < floor
        sheet.positions[below, 2] = 2.0 * floor - sheet.positions[below, 2]
        self.moved_by_crumple = np.asarray(moved, dtype=np.int64)
        _take_shape_as_rest(sheet, self.moved_by_crumple, first_spring)
        self.creases += editor.creases
        return applied

    @staticmethod
    def _lift_hinge(editor: MeshEditor, bend_spring: int, ratio: float,
                    rng: np.random.Generator) -> list[int]:
        """Seed a random fold: lift the hinge edge under a BEND spring (r, l) by half the
        height a clean fold to |x_r − x_l| = ratio·d0 would give it, to a random side."""
        r, left = (int(x) for x in editor.spring_vertices.data[bend_spring])
        hinge = editor.hinge_between(r, left)
        if hinge is None:
            return []
        d0 = float(editor.rest_length.data[bend_spring])
        lift = 0.25 * d0 * math.sqrt(max(1.0 - ratio * ratio, 0.0))
        side = 1.0 if rng.random() < 0.5 else -1.0
        lifted = [int(v) for v in hinge if not editor.pinned.data[v]]
        for v in lifted:
            editor.positions.data[v] += side * lift * editor.normals.data[v]
        return lifted


def _take_shape_as_rest(sheet: Sheet, moved: np.ndarray, first_new_spring: int) -> None:
    """Random damage is plastic: the HINGE springs at a vertex it moved, and the ones it
    made, rest at their lengths now (its creases' memories, AUX springs, pull gradually:
    Simulator.crumple). Lifted out of an intact flat sheet, a crease cannot reach its
    memory length without stretching the paper around it (an isolated crease is not
    developable); held to it, the crumpled sheet rested at 79 % strain."""
    touches = np.zeros(sheet.vertex_count, dtype=bool)
    touches[moved] = True
    ends = sheet.spring_vertices
    kind = sheet.spring_kind
    shaped = (kind == HINGE) & (touches[ends[:, 0]] | touches[ends[:, 1]]
                                | (np.arange(kind.size) >= first_new_spring))
    sheet.spring_rest_length[shaped] = spring_lengths(sheet.positions, ends[shaped])
