"""Steps a sheet: probes in, one frame of physics, state out (SPEC §2–3).

One frame of ``dt`` is cut into ``substeps`` sub-steps of h = dt / substeps; the probes
sweep along their frame's path, a share per sub-step. docs/solver.md explains every pass.

'constrained' sub-step (the default: paper-stiff and real time, SPEC §2), ``_substep``:
  # inertia      y = x + h v + h² g (air drag), gripped vertices placed with their probe
  # springs      a local/global iteration, then buckling iterations while it is squeezed
  # bending      one prefactored bending solve, the table's reaction in it (Uzawa)
  # springs      the remaining local/global iterations, buckling iterations again
  # contact      the table, then the swept probes, with friction; grips
  # stretch      Gauss–Seidel strain limiting, long-range attachments, contact
  # velocities   v = (x - x_start) / h, so every projection is velocity-consistent

'paper' (Eq. 1–6) and 'explicit' sub-step: ``_force_step`` (every spring a force; Eq. 6
Jacobi from Δv⁽⁰⁾ = W_ii⁻¹ h f̃, or symplectic Euler; x += h v), then the same contact and
velocities (no stretch pass).

After the sub-steps: a non-finite state is rolled back; damage is checked at its own rate
in simulated time (core/damage.py), never per sub-step.
"""
from __future__ import annotations

import itertools
import math

import numpy as np

from . import kernels
from .config import SimulationConfig
from .bending import SheetBending
from .damage import DamageModel
from .probe_compression import PROBE_REACH
from .probes import Probes
from .length_projection import project_lengths
from .membrane import Membrane, membrane_weights
from .mesh_editing import spring_lengths
from .projective import (ConstrainedSolve, GlobalStep, UpdatedStep, global_step,
                         inertial_step, local_targets, spring_entries, term_entries)
from .sheet import AUX, HINGE, Sheet, build_flat_sheet, damage_labels
from .topology import two_edge_path_lengths, vertex_normals

NEAR_PIN_LEVELS = 10
"""Springs within this many hops of a pinned vertex get extra strain-limiting sweeps."""
NEAR_PIN_SWEEPS = 8
TABLE_ITERATIONS = 10
"""Bending solves per sub-step at most while the table's reaction settles; fewer leave a
sheet at rest on the table quivering (docs/solver.md)."""
_REST_IDS = itertools.count(1)
"""Ids of the rests a sheet falls asleep into, unique in the process (Simulator.rest_id)."""
SLEEP_MARGIN = 0.005
"""How far [m] beyond PROBE_REACH of its radius a probe that moves wakes the sheet, measured
between the sheet's bounding box and the probe's sweep over the frame (_probes_disturb): a
probe that touches the sheet in a frame is always that near."""
TABLE_TOLERANCE = 1e-6
"""Contact violation [m] at which the table's reaction counts as settled."""
TABLE_ROWS_MOST = 256
"""Vertices on the table held exactly in the bending solve, at most (Simulator._table_rows:
each costs a third of a solve once, and the rows' dense system grows with their square)."""
NO_ROWS = (np.zeros(0, dtype=np.int64), np.zeros((0, 3)), np.zeros(0))
"""The constraint rows (vertex, direction, value) of a sub-step without probes."""
TABLE_NORMAL = np.array([0.0, 0.0, 1.0])
"""The table's rows hold z: their direction, up out of the table."""
BUCKLING_PROGRESS = 0.05
"""The share of the springs' compression beyond ``buckling_compression`` an extra
local/global iteration must take out for the next one to run (docs/solver.md)."""
RESTORE_MOST = 1.1
"""``solver.energy_restoring`` scales the velocities by at most this a frame (21 % more
kinetic energy): what an energy estimate gets wrong cannot launch the sheet."""
RESTORE_FLOOR = 1e-12
"""Kinetic energy [J] below which there is no motion to scale (a sheet at rest)."""
FAST_PROBE_TRAVEL = 0.25
"""A probe moving more than this many radii in a sub-step carries what it touches."""
GIVE_REACH = 1.5
"""A fingertip's grip gives for the paper within this many of its radii (plus an edge) of
its centre (``ContactConfig.grip_give``)."""
GIVE_PERSISTENCE = 8
"""... for that many sub-steps in a row: paper held elsewhere pulls on while the fingertip
moves (the random scenes' gives: 22-203 sub-steps), where a fingertip pushing a pinned
sheet towards its pin drags the paper behind it out only while it sets off (3-7 sub-steps
over 10 %, up to 23 %; `bench/push_to_pin.py`: with 1 or 4 in a row its grip gave at 37²
and 49² and the sheet never arched)."""
GIVE_STILL = 1e-6
"""A fingertip moving less than this [m] in a sub-step stands still: its grip does not give
(a node's probe placed between equal poses may differ from one sub-step to the next by a
rounding)."""
GIVE_ALIGNMENT = 0.5
"""... for springs behind it that run along its motion at least this much (the cosine of
their angle with it): paper pulled back. The paper beside a squeeze's fingertips, pushed
out sideways between their pads and the table, is stretched as much (10-14 % at 49²-65²);
its grips must hold, or the arch loses its push."""
SMALL_PROBE_EDGES = 0.6
"""A probe whose radius is below this many of the mesh's longest edges can pass between a
triangle's corners (a right triangle's circumradius is half its longest edge): the
triangles, not only the vertices, are kept out of it (kernels.project_probes_on_triangles)."""
GRIP_ROWS_MOST = 192
"""Rows (three a vertex) that hold gripped vertices in the solves, at most: beyond, the
gripped vertices are pins of the factored systems (Simulator._factor_grips). The rows' dense
system costs the cube of their count whenever they change: a wide pad pressed flat onto a
1 400-vertex sheet gripped all of it and took 30 s a frame."""
GRIP_STANDING_SUBSTEPS = 6
"""Sub-steps a set of gripped vertices must stand unchanged before it may become pins of
the factored systems (GRIP_PIN_WORK): a new factor pays for itself only over many solves."""
GRIP_PIN_WORK = 40_000
"""Gripped vertices × the sheet's vertices from which standing grips are pins of the
factored systems rather than rows of every solve (each row vertex costs a pass over the
sheet a solve; a factorisation grows a little faster than the sheet): 10 gripped vertices
at 65², 37 at 33², 3 at 129². The squeeze at 65² (about 21 gripped vertices for 2 s, 27
solves a frame) took 27.8-30.4 ms a frame against 32.4-36.8, its figures within its seeds'
spread (docs/contact.md)."""
SPIN_NONE, SPIN_VERTICAL, SPIN_ALL = 0, 1, 2
"""Which angular momentum a sub-step keeps (Simulator._spin_kept): none, the vertical
component, all of it."""
CONTACT_ROW_PASSES = 3
"""Solves per local/global iteration, at most, while its contact rows settle (rows that
pull let go, vertices carried into a probe given one: Simulator._settle_contact_rows)."""
MEMORY_PULL_RATE = 0.5
"""A random crease's memory pulls its ends together by at most this share of their
distance a second (Simulator._yield_memory): set at once, the memories of a crumple
strained the sheet 38–72 % in its first frames (65²); pulled at 0.5 /s, 1.1–2.6 %."""
MEMORY_PROGRESS = 0.25
"""... while they come closer by this share of the pull a frame, and no HINGE spring at
either end is strained by more than MEMORY_STRAIN_BANDS strain bands; else the memory
keeps what it reached."""
MEMORY_STRAIN_BANDS = 2.0
"""Where a HINGE spring at a memory's ends is strained beyond this many strain bands
(0.6 % by default) the paper no longer follows the memory: a pulling memory stops
(with 1 %, one pull more took a crumpled sheet to 2.33 %, 65², seed 2), and any memory
gives all of its pull (within the band it still pulled as hard as the band let it, and
held a short edge 1.08 % short at rest, 65², seed 1)."""
YIELD_BATCH_FRAMES = 6
"""Patches that yield are dropped together once this many frames have passed since the
first of them (SheetBending.yield_to): each drop changes the bending system (dropped at
once, each change factorised anew: `crumple` at 65² ran at 1.15× real time;
docs/solver.md)."""

SQUEEZE_MULTIPLE_MOST = 8
"""The squeeze's sub-steps (``squeeze_step_ratio``) are at most this multiple of
``substeps``: cardboard at 129² would ask for 10, and run at a fiftieth of real time."""

CONTACT_TOLERANCE = 1e-5
"""Depth inside a probe [m] at which a vertex without a contact row gets one."""
DEEP_IN_RISING_PROBE = 0.1
"""A rising probe holds no rows, but a vertex a solve carries deeper than this share of its
radius into it gets one (Simulator._settle_contact_rows): pushed out after the solve from
near the centre, neighbours left on opposite sides of the probe (a squeeze's lift-off), and
from under it the paper springing up wrapped round its cap (half the radius: a fingertip
lifting off a pushed-up sheet, 24-31 % with four sub-steps; docs/contact.md)."""


class Simulator:
    """The paper sheet and its time stepping. Knows nothing of ROS or Rerun."""

    def __init__(self, config: SimulationConfig, initial_sheet: Sheet | None = None) -> None:
        self.config = config
        self.initial_sheet = initial_sheet if initial_sheet is not None \
            else build_flat_sheet(config.sheet)
        self.reset()

    # ----------------------------------------------------------------- state management
    def reset(self) -> None:
        """Back to the initial sheet, time zero, no probes."""
        self.sheet = self.initial_sheet.copy()
        self.time = 0.0
        self.frame = 0
        self.nan_seen = False
        self.probes = Probes()
        self._release_grips()
        self._release_frames = 0
        """Frames left of the sub-steps that follow a let-go (``release_substeps``)."""
        self._release_multiple = 1
        """The multiple of ``substeps`` those frames run (``release_substeps`` after a
        let-go, ``give_substeps`` after a grip gave, the squeeze's (_keep_squeeze_steps)
        while a fingertip pushes the sheet together: the largest, where several came)."""
        self._refine = 1
        """The multiple of ``substeps`` asked for in this frame from a sub-step on (a grip
        gave, a fingertip pushes the sheet together; 1: none)."""
        self._stepping_substeps: int | None = None
        """While a frame is stepped, its sub-steps (finer from a give or a squeeze on); None
        between."""
        self._sliding = np.zeros(0, dtype=bool)
        """Per probe: it slid over the paper (_slip_grips) and grips nothing new until it
        lifts off the table."""
        self._stretched_behind = np.zeros(0, dtype=np.int64)
        """Per probe: sub-steps in a row its grip has had paper stretched behind it
        (_give_grips)."""
        self._grip_pinned = np.zeros(self.sheet.vertex_count, dtype=bool)
        """The vertices the factored systems hold as pins because a probe grips them
        (_factor_grips): kept when the grips are let go, until the systems are factored
        without them."""
        self._grips_seen = np.zeros(self.sheet.vertex_count, dtype=bool)
        """The gripped vertices at the last _factor_grips, and for how many sub-steps they
        have stood unchanged."""
        self._grips_standing = 0
        self._table_reaction = np.zeros(self.sheet.vertex_count)
        """The table's push on each vertex in the last bending step [N] (a warm start)."""
        self._reaction_from_rows = False
        """Whether that push is the table's rows' (exact holds), not Uzawa's (_bending_solve)."""
        self._table_lift = np.zeros(self.sheet.vertex_count)
        """How far the table lifted each vertex's inertial prediction before the last
        sub-step's solves [m] (_set_contact_rows): the table's push there, as a
        displacement, which its friction's normal force takes as well as the solve's."""
        self._rest_shape = self.sheet.positions.copy()
        """Where each vertex lay when its rest was last set (the sheet as built, a crumple's
        plastic shape, a new vertex where damage made it): how far from a pin the sheet
        reaches at rest (_build_attachments)."""
        self._bending = None  # rest angles from the initial sheet
        self._memory_target = np.zeros(0)
        """Per spring, the length a random crease's memory pulls towards (NaN: none)."""
        self._memory_length = np.zeros(0)
        self._global_step = self._bending_step = None  # factored anew
        self._factored_settings = None
        """What the factored systems were built with (_system_settings)."""
        self._probe_from = self._probe_to = np.zeros((0, 3))
        """Where the probes are at the start and the end of the current sub-step."""
        self._free_probes = np.zeros(0, dtype=bool)
        """The probes whose contacts are rows of the current sub-step's solves."""
        self._rising_probes = np.zeros(0, dtype=bool)
        """The probes that rise off the sheet in the current sub-step (no rows but for what
        a solve carries deep into them: DEEP_IN_RISING_PROBE)."""
        self._rising_indices = np.zeros(0, dtype=np.int64)
        """``_rising_probes`` as indices."""
        self._gripped = np.zeros(0, dtype=bool)
        """The vertices gripped in the current sub-step's solves. Both are fixed for its
        solves: ``_settle_contact_rows`` reads them after every solve."""
        self._lifting_off = np.zeros(0, dtype=bool)
        """The probes that pinch the sheet on the table, or have pinched it and rise since
        without a pause (a fingertip lifting off: _membrane_runs)."""
        self._start_positions = np.zeros((0, 3))
        """Where the sheet was at the start of the current sub-step."""
        self.asleep = False
        """Whether the sheet sleeps (``solver.sleep_speed``): its frames cost nothing and it
        holds still until something near it changes (_wake)."""
        self._quiet_frames = 0
        """Frames in a row in which the sheet stayed still and nothing near it changed."""
        self._slow = False
        """Whether every vertex moved slower than ``sleep_speed`` in the last still frame."""
        self._settling = False
        """Whether the sheet came to rest and settles on (_membrane_runs)."""
        self._recent_ways = np.zeros((0, 0))
        self._ways = np.zeros(0)
        """Each vertex's way [m] in each of the last ``sleep_time`` of those frames, and
        over all of them (_count_still_frame)."""
        self.rest_id: int | None = None
        """While the sheet sleeps, an id of this rest, unique in the process (its state
        stands until it wakes): what derives from the sheet alone may be kept under it, as
        its colours or its camera images; None while it is awake."""
        self._rest_energy: float | None = None
        self.frames_asleep = 0
        """Frames stepped asleep since the last reset (at no cost)."""
        self._probes_seen = Probes()
        """The probes as they were at the end of the last frame (_probes_disturb)."""
        self.spring_iterations = 0
        """Local/global iterations of the held springs ('constrained') since construction:
        a frame's share is most of its cost where probes push the sheet (bench/bench_demo.py
        prints it a frame)."""
        # damage (SPEC §4): breaks and folds at a fixed rate in simulated time
        self.damage = DamageModel(
            self.config.damage, self.config.seed, self.config.sheet.aux_stiffness,
            held_inextensible=self.config.solver.method == 'constrained')
        self.topology_changed()

    def take_rest_shape(self, other: 'Simulator') -> None:
        """Bend towards ``other``'s rest shape (its sheet's, creases and plastic set
        included) instead of this sheet's current shape, for a copy of ``other``'s sheet."""
        if self.config.solver.method != 'constrained' or other._bending is None:
            return
        self._wake()
        sheet = self.sheet
        self._bending = SheetBending(sheet.positions, sheet.triangles, sheet.material,
                                     self.config.sheet.bending_rigidity,
                                     sheet.spring_vertices[sheet.spring_kind == AUX],
                                     other._bending, keep_stiffness=True)
        self._factor_global_steps()

    def reconfigure(self, config: SimulationConfig) -> None:
        """Run on with new settings, the state untouched: contact and solver settings take
        effect at the next frame (what the solver derives from them is rebuilt); sheet
        and damage settings apply from the next reset."""
        solver_changed = config.solver != self.config.solver
        method_changed = config.solver.method != self.config.solver.method
        self.config = config
        self._wake()  # the table, friction or gravity may have changed under a still sheet
        if method_changed:
            # what Eq. 7 reads as compression belongs to the solver: a held sheet's lengths
            # are the strain band's, its compression the probes' (a sheet crumpled by the
            # force solver, read by its lengths under the constrained one, broke 800
            # springs a frame for as long as it ran)
            self.damage.held_inextensible = config.solver.method == 'constrained'
            self.damage.probe_compression.clear()
        if solver_changed:
            self.topology_changed()

    def set_pinned(self, pinned: np.ndarray) -> None:
        """Pin (fix in place) the vertices where ``pinned`` is true."""
        pinned = np.asarray(pinned, dtype=bool)
        if pinned.shape != (self.sheet.vertex_count,):
            raise ValueError(f'pinned must have shape ({self.sheet.vertex_count},)')
        self.sheet.pinned = pinned.copy()
        self.sheet.velocities[pinned] = 0.0
        if self.frame == 0:
            self.initial_sheet.pinned = pinned.copy()
        self.topology_changed()

    def set_probes(self, centers: np.ndarray, radii: np.ndarray, active: np.ndarray) -> None:
        """Where the probes are to be at the end of the next frame. A probe that was
        inactive starts there; an active one sweeps there from where it was."""
        centers = np.asarray(centers, dtype=np.float64).reshape(-1, 3)
        radii = np.asarray(radii, dtype=np.float64).reshape(-1)
        active = np.asarray(active, dtype=bool).reshape(-1)
        if not (len(centers) == len(radii) == len(active)):
            raise ValueError('centers, radii and active must have the same length')
        limit = self.config.contact.max_probe_distance
        finite = np.all(np.isfinite(centers), axis=1)
        distance = np.full(len(centers), np.inf)
        distance[finite] = np.linalg.norm(centers[finite], axis=1)
        usable = active & (distance <= limit)
        if np.any(active & ~usable):
            raise ValueError(f'probe centre not finite or farther than {limit} m from origin')
        if np.any(~np.isfinite(radii)) or np.any(radii <= 0):
            raise ValueError('probe radii must be finite and > 0')
        start = centers.copy()
        if self.probes.count == len(centers):
            keep = self.probes.active & active
            start[keep] = self.probes.end[keep]
        else:
            self._release_grips()
            self._sliding = np.zeros(len(centers), dtype=bool)
            self._stretched_behind = np.zeros(len(centers), dtype=np.int64)
        self.probes = Probes(radius=radii.copy(), start=start, end=centers.copy(),
                             active=active.copy())

    def topology_changed(self) -> None:
        """Rebuild what is derived from the mesh or the pins: inverse masses, the
        constraint sweep order, the long-range attachments and the global step's factor."""
        self._wake()
        sheet = self.sheet
        self._inverse_mass = np.where(sheet.pinned, 0.0, 1.0 / sheet.vertex_mass)
        hinge = sheet.spring_kind == HINGE
        self._longest_edge = float(sheet.spring_rest_length[hinge].max()) if np.any(hinge) \
            else 0.0
        """The longest triangle edge at rest [m]: how small a probe may pass between
        vertices (SMALL_PROBE_EDGES)."""
        self._squeeze_multiple = squeeze_multiple(self.config)
        """The multiple of ``substeps`` a squeeze runs (_keep_squeeze_steps)."""
        # a fold changes a few terms of each system, known without assembling them (not
        # when vertices were added, or the systems' settings changed)
        known_change = sheet.vertex_count == self._grip_probe.shape[0] \
            and self._factored_settings == self._system_settings()
        # damage only appends vertices: the grips of the old ones stand
        added = sheet.vertex_count - self._grip_probe.shape[0]
        self._grip_probe = np.concatenate([self._grip_probe, np.full(added, -1)])
        self._grip_offset = np.concatenate([self._grip_offset, np.zeros((added, 3))])
        self._grip_pinned = np.concatenate([self._grip_pinned, np.zeros(added, dtype=bool)])
        self._slipping = np.concatenate([self._slipping, np.zeros(added, dtype=bool)])
        self._table_reaction = np.concatenate([self._table_reaction, np.zeros(added)])
        self._table_lift = np.concatenate([self._table_lift, np.zeros(added)])
        self._rest_shape = np.concatenate([self._rest_shape,
                                           sheet.positions[sheet.vertex_count - added:]])
        if self.config.solver.method != 'constrained':
            self._global_step = self._bending_step = None
            self._factored_settings = None
            self._constraint_springs = np.zeros(0, dtype=np.int64)
            self._near_pin_count = 0
            self._build_attachments()
            return
        kind = sheet.spring_kind
        held = (kind == HINGE) | (kind == AUX)
        spring_change = self._held_change(held) if known_change else None
        constraint_springs = np.flatnonzero(held)
        # sweep from the pins outwards, so that one forward sweep carries their hold far
        ends = sheet.spring_vertices[constraint_springs]
        level = pin_distance_levels(ends, sheet.pinned)[ends]
        order = np.lexsort((level.max(axis=1), level.min(axis=1)))
        self._constraint_springs = constraint_springs[order]
        self._constraint_ends = sheet.spring_vertices[self._constraint_springs]
        self._constraint_rest = sheet.spring_rest_length[self._constraint_springs]
        self._near_pin_count = int(np.sum(level.min(axis=1) < NEAR_PIN_LEVELS))
        self._spring_blocks = kernels.spring_blocks(self._constraint_ends, sheet.vertex_count)
        self._dirty_blocks = np.ones(-(-self._constraint_ends.shape[0] // kernels.SPRING_BLOCK),
                                     dtype=np.bool_)
        self._build_attachments()
        # held springs enter the global step with a solver weight; bending has its own step
        # (BEND springs, second order in the fold angle, only mark the hinges here)
        held_springs = np.flatnonzero(held)
        self._held_springs = held_springs
        self._held_ends = sheet.spring_vertices[held_springs]
        # a crease's memory never outgrows the paper around it (Simulator._yield_memory)
        self._memory_springs = np.flatnonzero(kind == AUX)
        # springs are only ever appended: the targets of the old ones stand
        added = kind.size - self._memory_target.size
        self._memory_target = np.concatenate([self._memory_target, np.full(added, np.nan)])
        self._memory_length = np.concatenate([self._memory_length, np.full(added, np.inf)])
        hinge = kind == HINGE
        self._memory_longest = two_edge_path_lengths(
            sheet.spring_vertices[self._memory_springs], sheet.spring_vertices[hinge],
            sheet.spring_rest_length[hinge], sheet.vertex_count)
        self._rest_lengths_changed()  # the held springs' rest lengths and membrane weights
        self._global_weight = np.full(held_springs.size, self.config.solver.global_stiffness)
        previous_bending = self._bending
        self._bending = SheetBending(sheet.positions, sheet.triangles, sheet.material,
                                     self.config.sheet.bending_rigidity,
                                     sheet.spring_vertices[kind == AUX], previous_bending)
        # the bending factored is the previous one's unless patches yielded since
        bending_change = self._bending.matrix_change(previous_bending) \
            if known_change and not previous_bending.matrix_changed else None
        self._factor_global_steps(changes=(spring_change, bending_change))

    def _system_settings(self) -> tuple:
        """What the two systems depend on besides the mesh, masses and pins."""
        return (self.config.solver.dt / self.frame_substeps,
                self.config.solver.global_stiffness, self.config.sheet.bending_rigidity)

    def _held_change(self, held: np.ndarray) -> tuple | None:
        """The springs' K less the factored one as rank-one terms (projective.term_entries:
        k (e_i − e_j)(e_i − e_j)ᵀ per spring), where the held springs of the last rebuild
        kept their vertices (a fold, which holds one spring more) and ``held`` marks the
        held springs now; else None."""
        sheet = self.sheet
        if not np.array_equal(sheet.spring_vertices[self._held_springs], self._held_ends):
            return None
        was_held = np.zeros(held.size, dtype=bool)
        was_held[self._held_springs] = True
        gained, lost = held & ~was_held, was_held & ~held
        ends = np.concatenate([sheet.spring_vertices[gained], sheet.spring_vertices[lost]])
        weight = np.full(ends.shape[0], self.config.solver.global_stiffness)
        weight[np.count_nonzero(gained):] *= -1.0
        return ends.astype(np.int64), np.tile([1.0, -1.0], (ends.shape[0], 1)), weight

    def _factor_global_steps(self, springs: bool = True, changes: tuple = (None, None)
                             ) -> None:
        """Factor the bending's system and (``springs``) the springs', the pinned vertices
        held, and the gripped ones _factor_grips pins (what the probes hold changes every
        sub-step: ConstrainedSolve holds it).
        ``changes``: each system's change since its factor where it is known (a fold's:
        _held_change, SheetBending.matrix_change), which spares assembling it anew."""
        sheet = self.sheet
        h = self.config.solver.dt / self.frame_substeps
        pinned = sheet.pinned | self._grip_pinned
        self._table_reaction[pinned] = 0.0  # held vertices are not the solve's to support
        self._bending.matrix_changed = False
        if not np.any(~pinned):
            self._global_step = self._bending_step = None
            return
        # a small change (a break, a fold) reuses the last factors (projective.UpdatedStep)
        spring_change, bending_change = changes
        self._factored_settings = self._system_settings()
        previous_bending = self._bending_step.step if self._bending_step else None
        self._bending_factored_at = self.frame
        self._bending_step = ConstrainedSolve(
            _changed_step(previous_bending, bending_change, pinned)
            or global_step(sheet.vertex_mass, pinned, self._bending.matrix_entries(), h,
                           previous_bending),
            sheet.vertex_count)
        if springs or self._global_step is None:
            previous_springs = self._global_step.step if self._global_step else None
            self._global_step = ConstrainedSolve(
                _changed_step(previous_springs, spring_change, pinned)
                or global_step(sheet.vertex_mass, pinned,
                               spring_entries(self._held_ends, self._global_weight), h,
                               previous_springs),
                sheet.vertex_count)

    def _build_attachments(self) -> None:
        sheet = self.sheet
        anchors = np.flatnonzero(sheet.pinned)
        free = np.flatnonzero(~sheet.pinned)
        if self.config.solver.method != 'constrained' or anchors.size == 0:
            self._attached = np.zeros(0, dtype=np.int64)
            self._anchor = np.zeros(0, dtype=np.int64)
            self._attachment_length = np.zeros(0)
            return
        nearest = np.empty(free.size, dtype=np.int64)
        anchor_material = sheet.material[anchors]
        for start in range(0, free.size, 4096):
            chunk = free[start:start + 4096]
            gap = np.linalg.norm(sheet.material[chunk, None, :] - anchor_material[None], axis=2)
            nearest[start:start + 4096] = anchors[np.argmin(gap, axis=1)]
        self._attached = free
        self._anchor = nearest
        self._attachment_length = self._rest_reach(free, nearest) \
            * (1.0 + self.config.solver.max_stretch)

    def _rest_reach(self, first: np.ndarray, second: np.ndarray) -> np.ndarray:
        """How far apart vertices ``first`` and ``second`` (index arrays, broadcast) may be
        at rest [m]: their material distance, or the rest shape's where that is longer (a
        crumple's plastic set lengthens the paper's path: held to the flat sheet's
        distance from a pin, a spring by it rested 27 % compressed, a 41 x 31 sheet
        crumpled 292 times)."""
        sheet = self.sheet
        return np.maximum(
            np.linalg.norm(sheet.material[first] - sheet.material[second], axis=-1),
            np.linalg.norm(self._rest_shape[first] - self._rest_shape[second], axis=-1))

    # ----------------------------------------------------------------------- stepping
    def step_frame(self) -> None:
        """Advance one frame of ``dt``. If the state ever turned non-finite the frame is
        rolled back, velocities zeroed and ``nan_seen`` set: nothing non-finite escapes."""
        solver = self.config.solver
        # an awake sheet that moves has nothing a disturbance could reset
        if (self.asleep or self._slow) and self._probes_disturb():
            self._wake()
        if self.asleep:
            self.frames_asleep += 1
            self._end_frame()
            return
        substeps = self.frame_substeps
        releasing = solver.release_substeps > 1 and solver.method == 'constrained'
        gripping = self._gripping_probes() if releasing else None
        self._refine = 1
        saved_positions = self.sheet.positions.copy()
        self._air_taken = 0.0
        """The kinetic energy the air's drag across the sheet took this frame [J]."""
        restoring = (solver.energy_restoring and solver.method == 'constrained'
                     and self._bending is not None and not np.any(self.probes.active))
        if restoring:
            energy_before = self.energy()
            kinetic_before = self._kinetic_energy()
            changes_before = (self.breaks, self.folds, len(self.damage.creases))
        # sub-steps, the probes sweeping a share of their frame's path in each
        probe_path = self.probes.end - self.probes.start
        sub = 0
        self._stepping_substeps = substeps
        try:
            while sub < substeps:
                probe_from = self.probes.start + probe_path * (sub / substeps)
                probe_to = self.probes.start + probe_path * ((sub + 1) / substeps)
                self._substep(solver.dt / substeps, probe_from, probe_to)
                sub += 1
                finer = math.ceil(self._refine * solver.substeps / substeps)
                if finer > 1 and sub < substeps:
                    # a grip gave under load, or fingertips push the sheet together: the
                    # rest of the frame in finer sub-steps too
                    sub, substeps = sub * finer, substeps * finer
                    self._stepping_substeps = substeps
                    self._start_release(self._refine)
                    self._factor_global_steps()
        finally:
            self._stepping_substeps = None
        # nothing non-finite escapes: such a frame is rolled back
        rolled_back = not (kernels.all_finite(self.sheet.positions)
                           and kernels.all_finite(self.sheet.velocities))
        if rolled_back:
            self.nan_seen = True
            self.sheet.positions[:] = saved_positions
            self.sheet.velocities[:] = 0.0
        # damage: checked at its own rate in simulated time, never per sub-step
        damage = self.config.damage
        yielded = 0
        if (damage.enabled and damage.yield_curvature > 0 and solver.method == 'constrained'
                and self._bending is not None):
            yielded = self._bending.yield_to(self.sheet.positions, damage.yield_curvature,
                                             YIELD_BATCH_FRAMES)
        if solver.method == 'constrained':
            self._yield_memory()
        creases_before = len(self.damage.creases)
        mesh_changed = self.damage.advance(self.sheet, solver.dt, self.probes,
                                           self._grip_probe,
                                           self.sheet.positions - saved_positions)
        if mesh_changed:
            self._keep_creases_out(self.damage.creases[creases_before:])
            self.topology_changed()
        elif self._global_step is not None and self._global_step.step.stale:
            self._factor_global_steps()  # the updates since the last factor cost more
        elif self._bending_step is not None and (self._bending_step.step.stale
                                                 or self._bending.matrix_changed):
            # patches gave way to hinges: the springs are as they were, and the bending's
            # change is known as terms unless its factor is due anew anyway
            change = None if self._bending_step.step.stale else self._bending.yield_change
            self._factor_global_steps(springs=False, changes=(None, change))
        if restoring and not (yielded or self._bending.matrix_changed or self.nan_seen
                              or (self.breaks, self.folds, len(self.damage.creases))
                              != changes_before):
            self._restore_energy(energy_before - 2.0 * solver.air_damping * solver.dt
                                 * kinetic_before - self._air_taken)
        if releasing or self._release_frames or self._refine > 1:
            self._time_release(gripping)
        self._count_still_frame(not (rolled_back or yielded or mesh_changed
                                     or self._bending_step is not None
                                     and self._bending.matrix_changed
                                     or self.damage.stressed))
        self._end_frame()

    def _end_frame(self) -> None:
        self.probes.start = self.probes.end.copy()
        self._probes_seen = Probes(radius=self.probes.radius.copy(),
                                   start=self.probes.start, end=self.probes.start,
                                   active=self.probes.active.copy())
        self.time += self.config.solver.dt
        self.frame += 1

    @property
    def frame_substeps(self) -> int:
        """Sub-steps of a frame now: ``substeps``, times ``release_substeps`` for
        ``release_time`` after a fingertip let go of the sheet."""
        if self._stepping_substeps is not None:
            return self._stepping_substeps  # a frame being stepped: its sub-steps now
        return self.config.solver.substeps * (self._release_multiple if self._release_frames
                                              else 1)

    def _gripping_probes(self) -> np.ndarray:
        """The probes that grip the sheet now (indices)."""
        gripped = self._grip_probe[self._grip_probe >= 0]
        return np.unique(gripped) if gripped.size else gripped

    def _time_release(self, gripping: np.ndarray | None) -> None:
        """Count down the sub-steps that follow a let-go, start them where a probe that
        gripped the sheet as the frame began (``gripping``, None: not watched) grips none
        of it now and a held spring is squeezed beyond ``buckling_compression``
        (``release_substeps``), or a sub-step asked for finer ones (``_refine``:
        a grip gave, fingertips push the sheet together), and factor the systems for the
        sub-step length that comes of it. A squeezed arch set free, or paper a grip held
        under load, springs back in about a frame, faster than one sub-step can follow."""
        solver = self.config.solver
        if self._release_frames and self._refine == 1:  # else asked again in this frame
            self._release_frames -= 1
        if not self._release_frames:
            self._release_multiple = 1
        # only where the paper let go is loaded: a fingertip lifting off paper it did not
        # push together (`drag`, `slide`, `press`) leaves nothing to spring back, and the
        # sub-steps cost those scenes a seventh to a third of their speed
        if gripping is not None and gripping.size \
                and np.setdiff1d(gripping, self._gripping_probes()).size \
                and kernels.any_squeezed(self.sheet.positions, self._held_ends,
                                         self._held_rest, solver.buckling_compression):
            self._start_release(solver.release_substeps)
        self._start_release(self._refine)
        if self._global_step is not None and self._factored_settings != self._system_settings():
            self._factor_global_steps()

    def _start_release(self, multiple: int) -> None:
        """``release_time`` of frames at ``multiple`` × ``substeps`` from the next frame."""
        if multiple > 1:
            solver = self.config.solver
            self._release_frames = math.ceil(solver.release_time / solver.dt - 1e-9)
            self._release_multiple = max(self._release_multiple, multiple)

    # ----------------------------------------------------------------------- sleeping
    def _count_still_frame(self, calm: bool) -> None:
        """Count the frame towards sleep if the sheet was still in it (``calm``: nothing
        yielded, broke, folded or gathered Eq. 7's hazard), and fall asleep after
        ``sleep_time`` of still frames in a row with no vertex now faster than
        ``sleep_speed``. Still: every vertex's way over the last ``sleep_time`` within what
        ``sleep_speed`` covers in it, that is its mean speed over that window below
        ``sleep_speed`` (as PhysX filters a body's energy over time before it sleeps), not
        its speed in every frame: a crumpled sheet at rest whose creases' memories give one
        vertex a 0.2 mm/s jolt every eleventh frame never slept (docs/solver.md,
        "Sleeping")."""
        solver = self.config.solver
        window = max(1, math.ceil(solver.sleep_time / solver.dt - 1e-9))
        self._slow = False
        if not (calm and solver.sleep_speed > 0 and self._would_stop()):
            self._quiet_frames = 0
            self._settling = False
            return
        if self._quiet_frames == 0:
            self._recent_ways = np.zeros((window, self.sheet.vertex_count))
            self._ways = np.zeros(self.sheet.vertex_count)
        longest, fastest = kernels.slide_paths(self.sheet.velocities, solver.dt,
                                               self._recent_ways, self._quiet_frames % window,
                                               self._ways)
        self._quiet_frames += 1
        self._slow = fastest < solver.sleep_speed
        if self._slow and self._quiet_frames >= window \
                and longest < solver.sleep_speed * window * solver.dt:
            if self._settles_further():
                self._settling = True
                self._quiet_frames = 0
                return
            self.asleep = True
            self.rest_id = next(_REST_IDS)
            self.sheet.velocities[:] = 0.0

    def _settles_further(self) -> bool:
        """Whether a sheet that would fall asleep now goes on settling with the membrane
        in its bending solve (``membrane_scope`` 'squeezed_or_settling'): a pinned sheet
        hanging clear of the table with no probe active. The split step's rest is not the
        sheet's: a drooping strip rests 8-14 % short of the elastica's tip angle beyond
        45° whatever the grid (docs/solver.md, "The cantilever"), and with the membrane at
        the elastica (within 0.6 %), at 2-4 times a step's cost, which it then pays only
        while it settles the rest of the way (0.5-2 s), not while it swings. A sheet on the
        table is left out: the table carries it, and the membrane there only put its sleep
        off by a window at several times a step's cost (docs/solver.md)."""
        return not (self._settling
                    or self.config.solver.membrane_scope != 'squeezed_or_settling'
                    or not self._has_membrane() or not np.any(self.sheet.pinned)
                    or np.any(self.probes.active) or self._on_table())

    def _wake(self) -> None:
        self.asleep = self._slow = self._settling = False
        self._quiet_frames = 0
        self.rest_id = self._rest_energy = None

    def _would_stop(self) -> bool:
        """Whether something would stop the sheet's slow drift: the air's linear drag, a
        pin, the table under it or a probe's grip. A free sheet in a vacuum never sleeps:
        it keeps its momentum however slowly it moves."""
        return (self.config.solver.air_damping > 0 or bool(np.any(self.sheet.pinned))
                or bool(np.any(self._grip_probe >= 0)) or self._on_table())

    def _on_table(self) -> bool:
        """Whether any vertex lies on the table (within TABLE_TOLERANCE of it)."""
        contact = self.config.contact
        return contact.ground_enabled and bool(
            self.sheet.positions[:, 2].min() <= contact.ground_height + TABLE_TOLERANCE)

    def _probes_disturb(self) -> bool:
        """Whether a probe near the sheet moved, appeared, left or changed its radius since
        the last frame (what keeps it awake, or wakes it). Near: within PROBE_REACH of its
        radius plus SLEEP_MARGIN of the sheet's bounding box, where it was or on its way."""
        probes, seen = self.probes, self._probes_seen
        if probes.count != seen.count:
            return bool(np.any(probes.active) or np.any(seen.active))
        changed = (probes.active != seen.active) | (probes.radius != seen.radius) \
            | np.any(probes.end != probes.start, axis=1) | np.any(probes.start != seen.end,
                                                                  axis=1)
        changed &= probes.active | seen.active
        if not np.any(changed):
            return False
        positions = self.sheet.positions
        low, high = positions.min(axis=0), positions.max(axis=0)
        for index in np.flatnonzero(changed):
            for active, start, end, radius in (
                    (probes.active[index], probes.start[index], probes.end[index],
                     probes.radius[index]),
                    (seen.active[index], seen.end[index], seen.end[index],
                     seen.radius[index])):
                reach = PROBE_REACH * radius + SLEEP_MARGIN
                if active and np.all(np.minimum(start, end) - reach <= high) \
                        and np.all(np.maximum(start, end) + reach >= low):
                    return True
        return False

    def _kinetic_energy(self) -> float:
        sheet = self.sheet
        return float(0.5 * np.sum(sheet.vertex_mass * np.sum(sheet.velocities ** 2, axis=1)))

    def _restore_energy(self, target: float) -> None:
        """``solver.energy_restoring``: the velocities scaled so that the energy is
        ``target`` [J] again (what the frame had less air drag's first-order loss), at most
        by RESTORE_MOST a frame, and only where the frame lost energy and nothing touched
        the table. A pinned sheet's velocities are scaled whole; a free one keeps its
        momenta (only its velocities less the rigid motion are scaled, whose kinetic energy
        adds to the rigid motion's). A simplified energy projection (FEPR, Dinev et al.
        2018): the implicit step projects a turning sheet back to its edge lengths and
        loses speed it should not (docs/solver.md, convergence of motion)."""
        sheet = self.sheet
        contact = self.config.contact
        if contact.ground_enabled and \
                sheet.positions[:, 2].min() <= contact.ground_height + TABLE_TOLERANCE:
            return
        lost = target - self.energy()
        if not lost > 0.0:
            return
        mass, velocities = sheet.vertex_mass, sheet.velocities
        scaled = velocities
        if not np.any(sheet.pinned):
            # less the drift, then less the spin: all the angular momentum taken out by the
            # rigid turn the momentum keeping uses (h = 0: the positions stay)
            scaled = velocities - (mass[:, None] * velocities).sum(0) / mass.sum()
            kernels.remove_angular_momentum(
                sheet.positions, scaled, mass,
                kernels.angular_momentum(sheet.positions, velocities, mass), 0.0, False)
        kinetic = float(0.5 * np.sum(mass * np.sum(scaled ** 2, axis=1)))
        if kinetic <= RESTORE_FLOOR:
            return
        scale = min(math.sqrt((kinetic + lost) / kinetic), RESTORE_MOST)
        if scaled is velocities:
            velocities *= scale
        else:
            velocities += (scale - 1.0) * scaled

    def _keep_creases_out(self, creases: list[tuple[int, int, int]]) -> None:
        """A break puts its new vertex m off the sheet, to the side the sheet bulges; where
        that is inside a probe (flattened on the table, as the contact has it) or under the
        table (the squeeze's only penetrations, up to 0.6 mm at 65², 2.6 mm at 33²), m
        bulges to the other side, or, if that is inside too, goes to the nearest point
        outside: the probe's surface, or the table under a fingertip pressed into it."""
        if not creases:
            return
        positions = self.sheet.positions
        probes, contact = self.probes, self.config.contact
        ground = contact.ground_enabled
        floor = contact.ground_height if ground else -np.inf
        flag = np.zeros(1, dtype=bool)

        def inside(point: np.ndarray) -> bool:
            kernels.inside_probes(point[None], probes.end, probes.radius, probes.active,
                                  contact.ground_height, ground, 0.0, flag)
            return point[2] < floor or bool(flag[0])
        for i, m, j in creases:
            if not inside(positions[m]):
                continue
            mirrored = positions[i] + positions[j] - positions[m]
            if not inside(mirrored):
                positions[m] = mirrored
                continue
            point = positions[m].copy()
            for centre, radius in zip(probes.end[probes.active], probes.radius[probes.active]):
                offset = point - centre
                distance = float(np.linalg.norm(offset))
                if distance >= radius:
                    continue
                if point[2] - floor < radius - distance:
                    point[2] = floor
                else:
                    point = centre + offset * (radius / max(distance, 1e-12))
            point[2] = max(point[2], floor)
            positions[m] = point

    def _yield_memory(self) -> None:
        """A crease's memory (AUX spring) that the sheet holds beyond the strain band takes
        its length as its rest: where a remembered fold cannot be reached without
        stretching the paper around it, the fold gives, not the paper (a crumpled sheet
        rested at 79 % strain, 65²). Never longer than the shortest path over two HINGE
        springs between its ends: a memory that grew in a moment the paper was stretched
        would hold it stretched. A random crease's memory pulls towards its target at
        MEMORY_PULL_RATE while its ends still come closer unstretched, and keeps what it
        reached when they stop. Where the paper at its ends is held beyond
        MEMORY_STRAIN_BANDS strain bands, a memory gives all of its pull."""
        springs = self._memory_springs
        if springs.size == 0:
            return
        sheet, solver = self.sheet, self.config.solver
        ends = sheet.spring_vertices[springs]
        length = spring_lengths(sheet.positions, ends)
        rest = sheet.spring_rest_length[springs]
        # the paper at its ends: the largest |HINGE strain| there
        vertex_strain = kernels.vertex_max_abs_strain(sheet.positions, sheet.spring_vertices,
                                                      sheet.spring_rest_length,
                                                      sheet.spring_kind, HINGE)
        end_strain = np.maximum(vertex_strain[ends[:, 0]], vertex_strain[ends[:, 1]])
        followed = MEMORY_STRAIN_BANDS * max(solver.max_stretch, solver.max_compression)
        # within the band of its length; all of its pull given where the paper at its ends
        # is held beyond that
        new_rest = np.where(end_strain > followed, length,
                            np.clip(rest, length / (1.0 + solver.max_stretch),
                                    length / (1.0 - solver.max_compression)))
        new_rest = np.minimum(new_rest, np.maximum(self._memory_longest, rest))
        target = self._memory_target[springs]
        pending = np.isfinite(target)
        if pending.any():
            pull = MEMORY_PULL_RATE * solver.dt
            closing = length < self._memory_length[springs] * (1.0 - MEMORY_PROGRESS * pull)
            reached = np.maximum(target, length * (1.0 - pull))
            # ... and only while the paper at its ends follows unstretched (closing holds
            # for the first pull: its last length is infinite)
            unstretched = end_strain <= followed
            pulls = pending & unstretched & closing
            new_rest = np.where(pulls, reached, new_rest)
            done = pending & (~pulls | (reached <= target))
            self._memory_target[springs[done]] = np.nan
            self._memory_length[springs] = length
        if np.array_equal(new_rest, rest):
            return
        sheet.spring_rest_length[springs] = new_rest
        self._rest_lengths_changed()

    def _rest_lengths_changed(self) -> None:
        sheet = self.sheet
        self._constraint_rest = sheet.spring_rest_length[self._constraint_springs]
        self._held_rest = sheet.spring_rest_length[self._held_springs]
        self._membrane_weight = membrane_weights(self._held_rest,
                                                 self.config.sheet.bending_rigidity,
                                                 self.config.solver.membrane_weight)

    def _substep(self, h: float, probe_from: np.ndarray, probe_to: np.ndarray) -> None:
        """One sub-step of ``h`` [s], the probes moving from ``probe_from`` to ``probe_to``."""
        sheet = self.sheet
        positions, velocities = sheet.positions, sheet.velocities
        start_positions = positions.copy()
        contact = self.config.contact
        if contact.ground_enabled:
            # the table's push over the last sub-step, as a displacement [m]: inside the
            # solve and, while a probe is active, on the prediction before it
            self._table_support = self._table_reaction * (h * h) / sheet.vertex_mass \
                + self._table_lift
        # inertia, springs and bending: implicit ('constrained') or as forces
        constrained = self.config.solver.method == 'constrained'
        if constrained:
            self._air_drag(h)
            if contact.ground_enabled:
                kernels.table_friction(velocities, self._table_support,
                                       contact.ground_friction, h)
            spin_kept = self._spin_kept()
            if spin_kept:
                momentum = kernels.angular_momentum(positions, velocities, sheet.vertex_mass)
            self._projective_step(h, probe_from, probe_to, start_positions)
        else:
            self._force_step(h)

        # contact (swept probes, then the table), with friction (the table's is in the
        # velocities already for the implicit solver)
        touched = np.zeros(sheet.vertex_count, dtype=bool)
        self._contact(positions, start_positions, probe_from, probe_to, True, touched,
                      table_friction=not constrained)
        self._grip(positions, probe_to, touched)

        # stretch: strain limiting, attachments, and contact kept satisfied alongside.
        # What a probe pinches on the table goes where the probe goes. What it only touches
        # the solve has already placed on its surface, and the sheet may slide over it,
        # unless the probe moves faster than a quarter radius in the sub-step: then the
        # sheet ahead of it is dragged along instead of pulling its patch back through the
        # probe
        if self._constraint_springs.size:
            probing = bool(np.any(self.probes.active))
            inverse_mass = self._inverse_mass
            if probing:
                carried = self._grip_probe >= 0
                travel = np.linalg.norm(probe_to - probe_from, axis=1)
                # a fingertip whose grip slipped slides over the paper it pinches on the
                # table and cannot tunnel through it: carried, what its rim touched was
                # dragged off the paper pinched under its pad (random pinned scene 5005)
                fast = self.probes.active & ~self._sliding \
                    & (travel > FAST_PROBE_TRAVEL * self.probes.radius)
                if np.any(fast):
                    carried |= touched & ~self._chasing_fast_probes(
                        fast, positions, start_positions, probe_from, probe_to)
                inverse_mass = np.where(carried, 0.0, inverse_mass)
            # a sheet pushed together on the table can only buckle up; one lying there
            # crumpled is not being pushed (lifting it would keep it moving for ever)
            if contact.ground_enabled and probing:
                kernels.lift_squeezed(positions, inverse_mass, self._constraint_ends,
                                      self._constraint_rest, contact.ground_height,
                                      self.config.solver.buckling_compression)
            self._limit_strain(positions, start_positions, probe_from, probe_to, inverse_mass)

        # velocities from the positions actually reached
        velocities[:] = (positions - start_positions) / h
        velocities[sheet.pinned] = 0.0
        if constrained and contact.grip_give > 0:
            self._give_grips(positions, probe_from, probe_to)
        if constrained:
            self._keep_squeeze_steps(positions)
        if constrained and spin_kept and spin_kept == self._spin_kept():
            self._keep_angular_momentum(momentum * (1.0 - h * self.config.solver.air_damping),
                                        h, spin_kept == SPIN_VERTICAL)

    def _chasing_fast_probes(self, fast, positions, start_positions, probe_from, probe_to
                             ) -> np.ndarray:
        """(V,) bool: the vertices behind one of the ``fast`` probes (those that moved more
        than FAST_PROBE_TRAVEL radii in the sub-step; on the far side of the plane through
        its centre across its motion) both where it and they started and where they ended.
        Such a probe moves away from them: if they touch it, the sheet is not pushed but
        chases it (springing back after a poke, faster than the probe withdraws). Carried
        along, the vertices it touched were held apart round the probe's back, a spring
        between them at 14-16 % in every other frame. Vertices that started ahead and ended
        behind were pushed through, and are carried."""
        chasing = np.zeros(positions.shape[0], dtype=bool)
        motion = probe_to - probe_from
        for probe in np.flatnonzero(fast):
            chasing |= ((start_positions - probe_from[probe]) @ motion[probe] < 0.0) \
                & ((positions - probe_to[probe]) @ motion[probe] < 0.0)
        return chasing

    def _air_drag(self, h: float) -> None:
        """The air's pressure drag across the sheet (``drag_coefficient``), on the velocities
        the sub-step starts from: normal to the sheet, where paper meets the air it must
        push aside (``kernels.normal_air_drag``). Before the momentum a free sheet keeps is
        read, so that its torque is kept too. The implicit solver's only: the paper's own
        solvers keep the paper's model (linear air drag alone), which its figures are
        checked on."""
        solver = self.config.solver
        rate = 0.5 * solver.air_density * solver.drag_coefficient / self.config.sheet.grammage
        if rate > 0.0:
            sheet = self.sheet
            self._air_taken += kernels.normal_air_drag(
                sheet.velocities, vertex_normals(sheet.positions, sheet.triangles),
                sheet.vertex_mass, rate, h)

    def _spin_kept(self) -> int:
        """Which angular momentum about its centre of mass the sheet keeps through a
        sub-step, but for air drag: all of it in free flight (nothing but gravity and air
        acts on it: no pin, no active probe, off the table); about the vertical on the
        table with nothing else touching it (the table's friction, applied to the
        velocities before, is in the momentum kept; its push is vertical); else none."""
        if np.any(self.sheet.pinned) or np.any(self.probes.active):
            return SPIN_NONE
        contact = self.config.contact
        if contact.ground_enabled \
                and self.sheet.positions[:, 2].min() <= contact.ground_height + TABLE_TOLERANCE:
            return SPIN_VERTICAL
        return SPIN_ALL

    def _keep_angular_momentum(self, momentum, h, vertical_only: bool) -> None:
        """The sheet's own forces have no net torque. Those of a sub-step do: each spring's
        target lies along its edge before the solve, not after it, and each hinge's along
        its rest shape turned into its frame, not along its curvature; and a crumpled
        sheet's held springs cannot all be met, so the passes pull against each other
        every sub-step. Left in, a crumpled sheet spins up until air drag holds it (0.8
        rad/s at 33², seed 0, whatever the drag), or spins on the table (3 rad/s), and
        never comes to rest. What the sub-step made of the angular momentum ``momentum``
        should be is taken out by turning the sheet rigidly (about the vertical through
        its centre of mass only, on the table: ``kernels.remove_angular_momentum``)."""
        sheet = self.sheet
        excess = kernels.angular_momentum(sheet.positions, sheet.velocities,
                                          sheet.vertex_mass) - momentum
        if not np.all(np.isfinite(excess)):
            return
        # a sheet landing in this sub-step: a turn that takes it into the table is the
        # table's torque, not the sheet's own (aged with the membrane, 33², seed 0: a turn
        # about a horizontal axis put a corner 0.49 mm below it); a turn about the vertical
        # keeps the heights
        contact = self.config.contact
        landing = contact.ground_enabled and not vertical_only
        if landing:
            before = sheet.positions.copy(), sheet.velocities.copy()
        kernels.remove_angular_momentum(sheet.positions, sheet.velocities, sheet.vertex_mass,
                                        excess, h, vertical_only)
        if landing and sheet.positions[:, 2].min() < contact.ground_height - TABLE_TOLERANCE:
            sheet.positions[:], sheet.velocities[:] = before

    def _force_step(self, h: float) -> None:
        """Every spring a force: the paper's Eq. 6 Jacobi iteration, or symplectic Euler."""
        sheet = self.sheet
        solver = self.config.solver
        positions, velocities, mass = sheet.positions, sheet.velocities, sheet.vertex_mass
        gravity = np.asarray(solver.gravity)
        vertex_count = sheet.vertex_count
        force = mass[:, None] * (gravity[None, :] - solver.air_damping * velocities)
        diagonal = np.zeros((vertex_count, 3, 3))
        coupling = np.zeros((sheet.spring_count, 6))
        rhs_jv = np.zeros((vertex_count, 3))
        kernels.spring_system(positions, velocities, sheet.spring_vertices,
                              sheet.spring_rest_length, sheet.spring_stiffness,
                              sheet.spring_damping, h, force, diagonal, coupling, rhs_jv)
        if solver.method == 'explicit':
            delta_v = h * force / mass[:, None]
        else:
            # W_ii = m_i (1 + h·air) I + Σ B: air drag taken implicitly too
            for axis in range(3):
                diagonal[:, axis, axis] += mass * (1.0 + h * solver.air_damping)
            diagonal_inverse = np.empty_like(diagonal)
            kernels.invert_blocks(diagonal, diagonal_inverse)
            rhs = h * force + rhs_jv  # Eq. 3's right-hand side, h f + h² J v
            delta_v = np.einsum('vab,vb->va', diagonal_inverse, rhs)  # Eq. 6, k = 0
            delta_v[sheet.pinned] = 0.0
            kernels.jacobi_iterate(diagonal_inverse, coupling, sheet.spring_vertices, rhs,
                                   sheet.pinned, solver.jacobi_iterations, delta_v,
                                   np.empty_like(delta_v))
        delta_v[sheet.pinned] = 0.0
        velocities += delta_v
        positions += h * velocities

    def _projective_step(self, h: float, probe_from: np.ndarray, probe_to: np.ndarray,
                         start_positions: np.ndarray) -> None:
        """Implicit Euler split in two: one solve of the bending system (core/bending.py)
        from the inertial prediction, then the springs by local/global iterations
        (core/projective.py) from where bending left the sheet. Keeping the two apart
        matters: in one system the springs' solver weight, which must be large for paper's
        stiffness, resists every bending motion until the iterations turn the springs'
        targets, and a few iterations never do; bending, being near-linear, needs one
        solve. Bending comes first so that it carries the sub-step's weight before the
        springs see it (docs/solver.md: springs first left a drooping strip 30 % too stiff
        at 2.5 mm cells). Every spring aims at its rest length and every hinge and patch at
        its rest shape, so the sheet keeps its own shape; the strain band is then enforced
        by _limit_strain."""
        sheet = self.sheet
        solver = self.config.solver
        positions = sheet.positions
        weighted_inertia = np.empty_like(positions)
        # inertia: the starting iterate y = x + h v + h² g
        inertial_step(positions, sheet.velocities, sheet.pinned, sheet.vertex_mass, h,
                      solver.air_damping, np.asarray(solver.gravity, dtype=np.float64),
                      weighted_inertia)
        # gripped vertices are where their probe puts them: held in the global steps like
        # pins, so that the whole sheet, not only its gripped patch, follows the probe
        gripped = self._grip_probe >= 0
        if np.any(gripped):
            positions[gripped] = probe_to[self._grip_probe[gripped]] + self._grip_offset[gripped]
            positions[gripped, 2] = self.config.contact.ground_height  # pinched on the table
            self._slip_grips(positions)  # before the solves hold the sheet where it cannot go
        if self._global_step is None:
            return
        self._set_contact_rows(positions, probe_from, probe_to, start_positions)
        inertia_weight = (sheet.vertex_mass / (h * h))[:, None]
        rhs = np.empty_like(positions)
        iterations = solver.projective_iterations
        extra = solver.projective_max_iterations - iterations
        # a squeezed sheet: local/global iterations while it buckles, before bending
        if iterations and self._squeezed_before_bending(positions, start_positions, probe_from,
                                                        probe_to):
            self._buckling_iterations(positions, weighted_inertia, rhs, extra)
        # bending, from the prediction (or where buckling put the sheet), with the table's
        # reaction
        np.multiply(positions, inertia_weight, out=weighted_inertia)
        self._bending.add_targets(positions, weighted_inertia)
        self._bending_solve(weighted_inertia, positions, inertia_weight[:, 0])
        if self._membrane_runs(positions):
            self._membrane_solve(weighted_inertia, positions, start_positions)
        if solver.length_projection and self._constraint_springs.size:
            # the edges turn towards their lengths before the iterations rebuild the sheet
            # from their directions (docs/solver.md, "The cantilever")
            project_lengths(positions, np.where(self._grip_probe >= 0, 0.0, self._inverse_mass),
                            self._constraint_ends, self._constraint_rest,
                            1.0 - solver.max_compression, 1.0 + solver.max_stretch)
        np.multiply(positions, inertia_weight, out=weighted_inertia)
        # springs: the iterations, from where bending left the sheet
        for _ in range(iterations):
            self._spring_iteration(positions, weighted_inertia, rhs)
        if iterations:
            self._buckling_iterations(positions, weighted_inertia, rhs, extra)

    def _squeezed_before_bending(self, prediction, start_positions, probe_from,
                                 probe_to) -> bool:
        """Whether the buckling iterations before the bending solve have a squeezed sheet to
        work on: a held spring squeezed beyond ``buckling_compression`` in the inertial
        prediction, but on the table only within PROBE_REACH and a spring's length of an
        active probe's sweep in this sub-step, or in the sheet as the sub-step starts (its
        gripped vertices where their probes carry them). On the table the prediction is
        squeezed by what is not the sheet's: it takes a sheet lying there h²g into it, the
        table's push shortens the springs that slope onto it, and friction holds a vertex
        on it while its neighbour lifting off moves on. In the demo's scene with no probe,
        129-387 springs of the prediction were beyond 1 % (the worst 89 %) where the sheet
        itself had none beyond 0.4 %, and these iterations ran 2-6 times a frame for
        nothing. Near a probe they are the probe's push carried on into the sheet (a fast
        probe leaves the paper it swept squeezed along its path; a small one squeezes
        springs whose midpoints lie beyond its reach). With no probe active there is no push
        to carry on: a sheet resting on the table with a spring squeezed by its own crease
        ran them in every sub-step from a prediction h²g into the table, and they launched
        it (`squeeze` at 65², seed 2, after the fingertips left: 1 200 vertices off the
        table at 0.125 m/s every fifth frame, for ever). Figures: docs/solver.md, "Buckling
        iterations"."""
        probes = self.probes
        if not np.any(probes.active):
            return False  # nothing pushes the sheet together (_buckling_iterations)
        contact = self.config.contact
        table_top = contact.ground_height + TABLE_TOLERANCE if contact.ground_enabled \
            else -np.inf
        return kernels.squeezed_before_bending(
            start_positions, prediction, self._grip_probe, bool(np.any(self._grip_probe >= 0)),
            self._held_ends, self._held_rest, self.config.solver.buckling_compression,
            table_top, probe_from, probe_to, probes.radius, probes.active, PROBE_REACH)

    def _buckling_iterations(self, positions, weighted_inertia, rhs, most: int) -> None:
        """Up to ``most`` more local/global iterations while the sheet is squeezed (more
        than ``buckling_compression``): a compressed flat sheet leaves its plane only as
        the iterations turn the springs' targets, so this is what lets it buckle. They stop
        once an iteration no longer takes BUCKLING_PROGRESS of the compression out (a
        crumpled sheet stays compressed where it cannot buckle any further). While no probe
        is active nothing pushes the sheet together: what squeezes it is its own damage (a
        crease's memory pulling, a plastic bend) or its landing, and they stop once the
        compression left is within one spring's strain band (``max_compression``), which
        the band's sweeps take. A crumpled sheet settling ran 15-27 of them every frame for
        two seconds, each taking out a tenth of what the last left. Why they run on both
        sides of the bending solve, with figures: docs/solver.md."""
        solver = self.config.solver
        buckling_compression = solver.buckling_compression
        if most <= 0 or not kernels.any_squeezed(positions, self._held_ends, self._held_rest,
                                                 buckling_compression):
            return  # not squeezed (most sub-steps): no local step's right-hand side needed
        settled = 0.0 if np.any(self.probes.active) else solver.max_compression
        excess = np.inf
        for _ in range(most):
            # the local step measures the compression it starts from (one pass, not two)
            now = local_targets(positions, weighted_inertia, self._held_ends,
                                self._held_rest, self._global_weight, rhs,
                                buckling_compression)
            if now <= settled or now > (1.0 - BUCKLING_PROGRESS) * excess:
                return
            excess = now
            self._global_iteration(positions, rhs)

    def _bending_solve(self, rhs, positions, mass_over_h2) -> None:
        """The bending step with the table's reaction in it. Projecting the solution onto
        the table afterwards would move only the vertices below it: a bent sheet resting
        on its low points would be flattened into the table one sub-step after another,
        since nothing carries the table's push to the rest of it. Here the reaction λ ≥ 0
        is part of the solve, so the push reaches the whole sheet through its bending
        stiffness: exactly, by holding the vertices on the table (``_table_rows``), where
        they are few; by Uzawa iterations (``_table_uzawa``) where the sheet lies flat on
        the table."""
        self._solved_rows = self._rows
        if not self.config.contact.ground_enabled:
            self._bending_step.solve(rhs, positions, *self._rows)
        elif self._table_rows(rhs, positions):
            self._reaction_from_rows = True
        else:
            if self._reaction_from_rows:
                # no warm start: a row's reaction holds its vertex with the bending's
                # stiffness, and Uzawa's steps of M/h² take hundreds to undo one where the
                # contacts change. An aged sheet landing (97², seed 1) went from five rows
                # to Uzawa's iterations warm-started with their reactions, which then
                # lifted its edge 15 mm in one sub-step and threw it 48 mm up
                self._table_reaction[:] = 0.0
            self._reaction_from_rows = False
            self._table_uzawa(rhs, positions, mass_over_h2)

    def _membrane_runs(self, positions) -> bool:
        """Whether this sub-step's bending solve takes the held springs' membrane
        (``membrane_scope``). 'squeezed': while probes push the sheet together, that is a
        fingertip pinches it on the table or a probe lifts off it, and the bending solve
        left a held spring squeezed beyond ``buckling_compression``. (A probe that rises
        through a sheet it never pinched lets go of it as before: the membrane there kept
        the sheet's lengths by pulling it back through the probe.) Alone, that solve
        crushes the arch a squeezed sheet buckles into and the compression goes sideways
        into the sheet (docs/contact.md); a sheet nothing squeezes (hanging, swinging,
        crumpled at rest, poked) steps as it would without the membrane, at its cost.
        'squeezed_or_settling': also while a hanging sheet settles (_settles_further)."""
        solver = self.config.solver
        if not self._has_membrane():
            return False
        if solver.membrane_scope == 'always' or self._settling:
            return True
        return bool(np.any(self._lifting_off)) and kernels.any_squeezed(
            positions, self._held_ends, self._held_rest, solver.buckling_compression)

    def _has_membrane(self) -> bool:
        """Whether the bending solve can take the held springs as a membrane at all."""
        return self.config.solver.membrane_weight > 0.0 and self._held_ends.size > 0

    def _membrane_solve(self, rhs, positions, start_positions) -> None:
        """The bending solve again with the held springs as a membrane (core/membrane.py),
        by conjugate gradients from the bending solve's answer, under the rows it ended
        with (probes, grips, the table's active set; the Uzawa reaction stays in ``rhs``)."""
        solver = self.config.solver
        vertex, direction, value = self._solved_rows
        free_rows = np.zeros_like(value)
        bending_step = self._bending_step

        def precondition(residual, out):
            bending_step.solve(residual, out, vertex, direction, free_rows)
        membrane = Membrane(self._held_ends, self._held_rest, self._membrane_weight,
                            start_positions)
        membrane.solve(bending_step.step.system, precondition, rhs, positions,
                       bending_step.step.pinned_mask, solver.membrane_iterations)

    def _table_rows(self, rhs, positions) -> bool:
        """The table's contacts as constraint rows of the bending solve (z = table height),
        found by an active set: the vertices the table pushed in the last sub-step, less
        those it would now pull down, plus those the solve puts below it, until the set
        holds (a primal-dual active set method; it ends in one or two solves where the
        contacts change little). What it finds is the reaction for the friction of the next
        sub-step. Uzawa's projected gradient steps, by contrast, crawl here: a point
        contact on a sheet that bending stiffens takes hundreds of its steps (the demo's
        sheet, its far edge on the table, ran out of TABLE_ITERATIONS in every sub-step:
        docs/solver.md). Returns False, the reaction as it was (the Uzawa iterations' warm
        start), when more than TABLE_ROWS_MOST vertices are on the table."""
        ground = self.config.contact.ground_height
        vertex, direction, value = self._rows
        eligible = ~(self.sheet.pinned | self._grip_pinned)
        eligible[vertex] = False  # a probe's row decides its vertex
        held = np.flatnonzero(eligible & (self._table_reaction > 0.0))
        # the rows' columns are bought once per factor: worth it where the factor stands
        # long enough to spread their cost below the Uzawa iterations' (a factor that has
        # stood some frames is taken to stand about as long again; in a squeeze's yielding
        # it is renewed every other frame, in the demo's drape it stands for seconds)
        standing = max(self.frame - self._bending_factored_at, 1)
        if held.size > TABLE_ROWS_MOST \
                or self._bending_step.missing_columns(held) \
                > 3 * (TABLE_ITERATIONS - 1) * standing:
            return False
        for iteration in range(TABLE_ITERATIONS):
            self._solved_rows = (np.concatenate([vertex, held]),
                                 np.concatenate([direction, np.tile(TABLE_NORMAL, (held.size, 1))]),
                                 np.concatenate([value, np.full(held.size, ground)]))
            multipliers = self._bending_step.solve(rhs, positions, *self._solved_rows,
                                                   same_rhs=iteration > 0)
            push = -multipliers[vertex.size:]  # a row pushes along its direction where λ < 0
            solved = held
            below = eligible & (positions[:, 2] < ground - TABLE_TOLERANCE)
            below[held] = False
            pulling = push < 0.0
            if not (np.any(pulling) or np.any(below)):
                break
            held = np.concatenate([held[~pulling], np.flatnonzero(below)])
            if held.size > TABLE_ROWS_MOST:
                return False  # the reaction as it was: the Uzawa iterations' warm start
        self._table_reaction[:] = 0.0
        self._table_reaction[solved] = np.maximum(push, 0.0)
        return True

    def _table_uzawa(self, rhs, positions, mass_over_h2) -> None:
        """The table's reaction by projected Uzawa iterations with Nesterov's extrapolation,
        warm-started from the last sub-step: where the sheet lies flat on the table they
        settle at once."""
        contact = self.config.contact
        free = self._bending_step.step.free
        inertia_z = rhs[:, 2].copy()
        reaction = self._table_reaction
        trial = reaction.copy()
        momentum = 1.0
        for _ in range(TABLE_ITERATIONS):
            rhs[:, 2] = inertia_z + trial
            self._bending_step.solve(rhs, positions, *self._rows)
            if kernels.update_table_reaction(positions, free, mass_over_h2,
                                             contact.ground_height, trial) < TABLE_TOLERANCE:
                reaction[:] = trial
                break
            # Nesterov's extrapolation (FISTA): the plain projected gradient crawls where
            # the sheet is stiff between its contacts
            next_momentum = 0.5 * (1.0 + math.sqrt(1.0 + 4.0 * momentum * momentum))
            step = trial - reaction
            reaction[:] = trial
            np.maximum(trial + (momentum - 1.0) / next_momentum * step, 0.0, out=trial)
            momentum = next_momentum

    def _spring_iteration(self, positions, weighted_inertia, rhs) -> None:
        """One local/global iteration of the held springs (core/projective.py)."""
        local_targets(positions, weighted_inertia, self._held_ends, self._held_rest,
                      self._global_weight, rhs)
        self._global_iteration(positions, rhs)

    def _global_iteration(self, positions, rhs) -> None:
        """The springs' global step from the local step's ``rhs``, the contact rows settled
        on its solution (``_settle_contact_rows``)."""
        self.spring_iterations += 1
        multipliers = self._global_step.solve(rhs, positions, *self._rows)
        for _ in range(CONTACT_ROW_PASSES):
            if not self._settle_contact_rows(positions, multipliers):
                return
            multipliers = self._global_step.solve(rhs, positions, *self._rows, same_rhs=True)

    def _settle_contact_rows(self, positions, multipliers) -> bool:
        """Contact only pushes: a contact row that pulls its vertex towards the probe is let
        go (the grips' rows, three to a vertex, hold). And a vertex the solve carried into a
        probe without a row gets one: left to the stretch pass, it would be pushed out
        alone, denting the sheet around the probe and stretching it. So does a free vertex
        a solve carries nearer than DEEP_IN_RISING_PROBE of its radius to the centre of a
        rising probe: at a squeeze's lift-off the released paper springs out under the
        rising fingertips, a solve that does not see them carried it 12-16 mm into one in a
        sub-step, to within a few millimetres of its centre, and pushed out from there after
        the solve it was torn across the fingertip (65², seed 0: 343 %). Both in one pass
        (``kernels.settled_contact_rows``). Returns whether the rows changed (the solve must
        run again)."""
        if not self.probes.count:
            return False
        vertex, direction, value = self._rows
        contact = self.config.contact
        if kernels.contact_rows_hold(
                positions, self._probe_to, self.probes.radius, self._free_probes,
                contact.ground_height, contact.ground_enabled, CONTACT_TOLERANCE,
                self.sheet.pinned, vertex, self._contact_row, multipliers,
                self._rising_indices, DEEP_IN_RISING_PROBE, self._gripped):
            return False
        row_vertex, row_direction, row_value, self._contact_row = kernels.settled_contact_rows(
            positions, self._start_positions, self._probe_from, self._probe_to,
            self.probes.radius, self.probes.active, self._free_probes, self._rising_indices,
            contact.ground_height, contact.ground_enabled, CONTACT_TOLERANCE,
            DEEP_IN_RISING_PROBE, self.sheet.pinned, self._gripped, vertex, direction, value,
            self._contact_row, multipliers, self._table_reaction)
        self._rows = (row_vertex, row_direction, row_value)
        return True

    def _set_contact_rows(self, positions, probe_from, probe_to, start_positions) -> None:
        """What the probes hold in this sub-step's solves, as ConstrainedSolve rows
        (``_rows``: vertex, direction, value; ``_contact_row``: a contact's row, not a
        grip's): each gripped vertex where its probe carries it (three rows), and each
        vertex a probe reaches from where inertia takes it on that probe's surface along its
        normal (one row, so the sheet slides over the probe instead of being dragged through
        itself)."""
        sheet = self.sheet
        self._probe_from, self._probe_to = probe_from, probe_to
        self._factor_grips()
        self._table_lift[:] = 0.0
        if not self.probes.count:  # nothing to hold (nor gripped: grips need a probe)
            self._rows, self._contact_row = NO_ROWS, np.zeros(0, dtype=bool)
            self._lifting_off = np.zeros(0, dtype=bool)
            return
        # the probes that hold what they reach in this sub-step's solves (_settle_contact_rows):
        # a probe pressed into the table pinches what it reaches there (_grip), and the
        # stretch pass lets the sheet ahead of it buckle (docs/contact.md); a probe rising
        # lets go of what rode up its front: neither holds more rows
        table = self.config.contact
        lifted = self.probes.active & ~(
            table.ground_enabled & (probe_to[:, 2] - self.probes.radius < table.ground_height))
        rising = probe_to[:, 2] > probe_from[:, 2]
        self._free_probes = lifted & ~rising
        self._rising_probes = lifted & rising
        self._rising_indices = np.flatnonzero(self._rising_probes)
        self._gripped = self._grip_probe >= 0
        pinching = np.zeros(self.probes.count, dtype=bool)
        pinching[self._grip_probe[self._gripped]] = True
        if self._lifting_off.shape != pinching.shape:
            self._lifting_off = np.zeros_like(pinching)
        self._lifting_off = (self._lifting_off & self._rising_probes) | pinching
        self._start_positions = start_positions
        gripped = np.flatnonzero(self._gripped & ~self._grip_pinned)
        touched = np.zeros(sheet.vertex_count, dtype=bool)
        # the prediction on the probes; with none active nothing to place, and nothing onto
        # the table: lifted onto it here, a sheet lying there left the bending solve a
        # reaction of 1.5 % of its weight, which is all its friction, and slid on as if on
        # ice (`squeeze` at 33², after the fingertips left: 0.25 m/s for over a second).
        # With a probe active it still is, and the lift counts as the table's push
        if np.any(self.probes.active):
            below = self.config.contact.ground_height - positions[:, 2]
            self._contact(positions, start_positions, probe_from, probe_to, True, touched,
                          table_friction=False)
            # the lift is the table's push on the prediction: its friction's normal force
            # where the sheet lies on it (h² g for paper at rest there: its weight)
            if self.config.contact.ground_enabled:
                np.maximum(below, 0.0, out=self._table_lift)
                self._table_lift[touched] = 0.0
        touched[self._grip_probe >= 0] = False
        touched[sheet.pinned] = False
        contact = np.flatnonzero(touched)
        normal, _ = self._contact_planes(positions, contact, probe_to)
        vertex = np.concatenate([np.repeat(gripped, 3), contact])
        direction = np.concatenate([np.tile(np.eye(3), (gripped.size, 1)), normal])
        value = np.concatenate([positions[gripped].reshape(-1),
                                np.einsum('va,va->v', normal, positions[contact])])
        self._contact_row = np.concatenate([np.zeros(3 * gripped.size, dtype=bool),
                                            np.ones(contact.size, dtype=bool)])
        # what the probes hold is not the table's to support (nor, once let go, to launch)
        self._table_reaction[vertex] = 0.0
        self._rows = (vertex, direction, value)

    def _contact_planes(self, positions, vertices, probe_to):
        """Where ``vertices`` touch the nearest active probe: the unit normals out of it and
        the surface points nearest them; under a probe pressed into the table, its
        flattened pad's face (the table plane, facing down; ``kernels.contact_planes``)."""
        normal = np.empty((vertices.size, 3))
        surface = np.empty((vertices.size, 3))
        table = self.config.contact
        kernels.contact_planes(positions, vertices, probe_to, self.probes.radius,
                               self.probes.active, table.ground_height, table.ground_enabled,
                               normal, surface)
        return normal, surface

    def _limit_strain(self, positions, start_positions, probe_from, probe_to,
                      inverse_mass) -> None:
        solver = self.config.solver
        ends, rest = self._constraint_ends, self._constraint_rest
        # paper a fingertip pushes together on the table buckles; the sweeps would only
        # carry its compression to the grip's rim (docs/contact.md)
        gripping = bool(np.any(self._grip_probe >= 0))
        shortest = 1.0 - (solver.gripped_max_compression if gripping else solver.max_compression)
        longest = 1.0 + solver.max_stretch
        # where the sheet folds away from its pins the strain concentrates (a released
        # sheet folds at its clamped edge); a few more sweeps there cost a few rows only.
        # They come first: the full sweeps after them smooth the seam at their border
        # A pass that moved nothing ends its loop: the next would start where it did and
        # move nothing either (a sheet within its band, as most are most of the time)
        # A sweep passes only over the blocks of springs whose vertices moved since it last
        # passed there (kernels.project_springs): the same sweeps, at the cost of the few
        # springs out of the band where the rest of the sheet is within it
        near = self._near_pin_count
        dirty = self._dirty_blocks
        blocks = self._spring_blocks
        dirty[:] = True
        for _ in range(NEAR_PIN_SWEEPS if near else 0):
            moved = 0
            for reverse in (False, True):
                moved += kernels.project_springs(positions, inverse_mass, ends[:near],
                                                 rest[:near], shortest, longest, reverse,
                                                 dirty, *blocks)
            if not moved:
                break
        dirty[:] = True
        for _ in range(solver.constraint_iterations):
            moved = 0
            for reverse in (False, True):
                moved += kernels.project_springs(positions, inverse_mass, ends, rest,
                                                 shortest, longest, reverse, dirty, *blocks)
            others = kernels.project_attachments(positions, self._attached, self._anchor,
                                                 self._attachment_length) \
                + self._contact(positions, start_positions, probe_from, probe_to, False)
            if others:
                dirty[:] = True  # they do not say which vertices they moved
            if not moved + others:
                break

    def _contact(self, positions, start_positions, probe_from, probe_to, with_friction,
                 touched=None, table_friction=True) -> int:
        """Push the sheet out of the probes and the table; how many pushes that took."""
        contact = self.config.contact
        moved = 0
        # the probes first, the table last: the table is rigid, and a probe pressed into
        # it is flattened there like a fingertip, pinching the sheet on the table
        if self.probes.count:
            touched = touched if touched is not None else np.zeros(positions.shape[0],
                                                                   dtype=bool)
            pad_height = contact.ground_height if contact.ground_enabled else -np.inf
            moved += kernels.project_probes(
                positions, start_positions, self._inverse_mass, probe_from, probe_to,
                self.probes.radius, self.probes.active,
                contact.probe_friction if with_friction else 0.0, True, pad_height, touched)
            small = self.probes.active \
                & (self.probes.radius < SMALL_PROBE_EDGES * self._longest_edge)
            if np.any(small):
                moved += kernels.project_probes_on_triangles(
                    positions, self._inverse_mass, self.sheet.triangles, probe_from, probe_to,
                    self.probes.radius, small, pad_height, touched)
        if contact.ground_enabled:
            moved += kernels.project_ground(positions, start_positions, self._inverse_mass,
                                            contact.ground_height, contact.ground_friction,
                                            with_friction and table_friction,
                                            self._table_support)
        return moved

    def _grip(self, positions, probe_to, touched) -> None:
        """A probe pressing the sheet into the table pinches it, and where the probe's
        friction exceeds the table's the pinched patch goes where the probe goes, as paper
        under a fingertip does. Friction alone cannot say so here: the spring solve pulls a
        pinched vertex back by more than one step's penetration allows friction to hold,
        and the probe then slides through the sheet instead of pushing it."""
        contact = self.config.contact
        if not (self.probes.count and contact.ground_enabled
                and contact.probe_friction > contact.ground_friction):
            self._grip_probe[:] = -1
            self._slipping[:] = False
            return
        pressing = self.probes.active & (probe_to[:, 2] - self.probes.radius
                                         < contact.ground_height)
        self._sliding &= pressing  # lifted off, a fingertip grips afresh when it presses
        kernels.hold_gripped(positions, probe_to, pressing, self._grip_probe,
                             self._grip_offset, contact.ground_height)
        self._slip_grips(positions)
        if np.any(self._slipping):  # out from under a pressing probe, it can be gripped again
            slipping = np.flatnonzero(self._slipping)
            gap = np.linalg.norm(positions[slipping, None, :] - probe_to[None], axis=2)
            under = (gap <= 1.02 * self.probes.radius[None]) & pressing[None]
            self._slipping[slipping[~np.any(under, axis=1)]] = False
        kernels.grip_pinched(positions, np.where(self._slipping, 0.0, self._inverse_mass),
                             probe_to, self.probes.radius, pressing & ~self._sliding,
                             contact.ground_height, self._grip_probe, self._grip_offset)
        touched |= self._grip_probe >= 0

    def _release_grips(self) -> None:
        self._grip_probe = np.full(self.sheet.vertex_count, -1)
        self._grip_offset = np.zeros((self.sheet.vertex_count, 3))
        self._slipping = np.zeros(self.sheet.vertex_count, dtype=bool)
        """Vertices that slipped out of a grip (_slip_grips): not gripped again while a
        pressing probe still holds them against the table."""

    def _slip_grips(self, positions) -> None:
        """A fingertip holds paper by friction, and paper gives long before it stretches: where
        the grips have carried two gripped vertices farther apart than the paper between them
        reaches at rest, one grip slips. Against the pins, the fingertip's: a gripped vertex
        farther from any pinned vertex than the paper reaches lets go (from its nearest pin
        alone, a fingertip dragged along a pinned edge kept its grip, as the distance to that
        pin grows only to second order, and sheared the sheet 11-73 %). Between two
        fingertips, the one gripping fewer vertices, the weaker. A fingertip that slips
        slides (``_sliding``): all it grips slides under it, and it grips nothing new until it
        lifts off. The test is on where the probes put their gripped vertices (before the
        solves, and after the sub-step), not on what the solve left of the springs around
        them, so solver error never lets go: a squeeze's fingertips (coming together) and one
        fingertip dragging a free sheet keep their grip. Held rigidly, two fingertips moving
        apart or one dragging a sheet pinned elsewhere stretched it by up to 19 times its
        length (`bench/random_scenes.py`)."""
        gripped = np.flatnonzero(self._grip_probe >= 0)
        if gripped.size == 0:
            return
        stretch = 1.0 + self.config.solver.max_stretch
        letting_go = kernels.beyond_rest_reach(positions, self.sheet.material, self._rest_shape,
                                               gripped, np.flatnonzero(self.sheet.pinned),
                                               stretch)
        probe = self._grip_probe[gripped]
        holding = np.unique(probe)
        for first in range(holding.size):
            for second in range(first + 1, holding.size):
                ours = gripped[probe == holding[first]]
                theirs = gripped[probe == holding[second]]
                if ours.size >= theirs.size:  # the weaker grip slips (ties: the later probe)
                    ours, theirs = theirs, ours
                beyond = kernels.beyond_rest_reach(positions, self.sheet.material,
                                                   self._rest_shape, ours, theirs, stretch)
                letting_go[np.isin(gripped, ours[beyond])] = True
        # friction holds the fingertip's whole patch or none of it: once part of it slips,
        # all of it slides, and it grips nothing new (gripping what came under its leading
        # edge, each vertex dragged until it too was beyond reach, it sheared a pinned
        # sheet by 31 %: random pinned scene 9)
        self._slide(np.unique(probe[letting_go]))

    def _slide(self, probes: np.ndarray) -> None:
        """These probes' grips let go of all they hold: they slide (``_sliding``)."""
        if probes.size == 0:
            return
        self._sliding[probes] = True
        slipped = np.flatnonzero(np.isin(self._grip_probe, probes))
        self._grip_probe[slipped] = -1
        self._slipping[slipped] = True

    def _give_grips(self, positions, probe_from, probe_to) -> None:
        """A moving fingertip's grip gives where the paper behind it, along its motion,
        has been stretched beyond ``grip_give`` for GIVE_PERSISTENCE sub-steps in a row
        (ContactConfig: paper held elsewhere slips from under a fingertip long before it
        stretches); the let-go is under load, so the frames after it run
        ``give_substeps``."""
        gripped = self._grip_probe[self._grip_probe >= 0]
        if gripped.size == 0:  # most sub-steps: nothing to give, no count runs on
            self._stretched_behind[:] = 0
            return
        stretched = np.zeros(self.probes.count, dtype=bool)
        give = self.config.contact.grip_give
        for probe in np.unique(gripped):
            motion = probe_to[probe] - probe_from[probe]
            travel = math.hypot(motion[0], motion[1])
            if travel <= GIVE_STILL:
                continue  # a fingertip standing still has no behind
            direction = np.array([motion[0] / travel, motion[1] / travel, 0.0])
            reach = GIVE_REACH * self.probes.radius[probe] + self._longest_edge
            stretched[probe] = kernels.stretched_behind(
                positions, self._held_ends, self._held_rest, probe_to[probe], reach,
                direction, give, GIVE_ALIGNMENT)
        self._stretched_behind = np.where(stretched, self._stretched_behind + 1, 0)
        giving = np.flatnonzero(self._stretched_behind >= GIVE_PERSISTENCE)
        if giving.size:
            self._stretched_behind[giving] = 0
            self._slide(giving)
            self._refine = max(self._refine, self.config.solver.give_substeps)

    def _keep_squeeze_steps(self, positions) -> None:
        """Sub-steps of at most ``squeeze_step_ratio`` cell bending periods (SolverConfig)
        while fingertips push the sheet together: asked for from the sub-step after which
        a fingertip grips the sheet and a held spring is squeezed beyond
        ``buckling_compression``, then for as long as a fingertip grips it (switching
        between sub-step lengths each time the squeeze eased for a sub-step, the sheet was
        jolted into a tangle: `squeeze` at 65², two sub-steps, 76 % and 188 folds)."""
        multiple = self._squeeze_multiple
        if multiple == 1 or not np.any(self._grip_probe >= 0):
            return
        running = self._stepping_substeps is not None \
            and self._stepping_substeps >= multiple * self.config.solver.substeps
        if running or kernels.any_squeezed(positions, self._held_ends, self._held_rest,
                                           self.config.solver.buckling_compression):
            self._refine = max(self._refine, multiple)

    def _factor_grips(self) -> None:
        """Where a probe grips more vertices than GRIP_ROWS_MOST rows can hold, factor the
        systems anew with the gripped vertices pinned (they are placed where their probe
        carries them before the solves, as pins are where they were), and again when one of
        them is let go: a wide pad holds its footprint for one factorisation per change of
        its grip, not the cube of its rows per solve. So too grips that have stood
        GRIP_STANDING_SUBSTEPS sub-steps, where their rows would cost more than a factor
        (GRIP_PIN_WORK): a squeeze's fingertips hold the same vertices for seconds."""
        gripped = self._grip_probe >= 0
        pinned = self._grip_pinned
        if np.array_equal(self._grips_seen, gripped):
            self._grips_standing += 1
        else:
            self._grips_seen, self._grips_standing = gripped.copy(), 0
        held = np.count_nonzero(gripped)
        standing = self._grips_standing >= GRIP_STANDING_SUBSTEPS \
            and held * gripped.size >= GRIP_PIN_WORK
        rows = np.count_nonzero(gripped & ~pinned)
        if not (np.any(pinned & ~gripped) or 3 * rows > GRIP_ROWS_MOST or (standing and rows)):
            return
        self._grip_pinned = gripped if standing or 3 * held > GRIP_ROWS_MOST \
            else np.zeros_like(gripped)
        self._factor_global_steps()

    # ------------------------------------------------------------------------- damage
    def crumple(self, count: int, seed: int) -> None:
        """Random damage (SPEC §4.3): ``count`` random breaks and folds, seeded."""
        contact = self.config.contact
        self.damage.crumple(self.sheet, count, seed,
                            contact.ground_height if contact.ground_enabled else -math.inf)
        # the crumpled shape is the sheet's rest (damage._take_shape_as_rest): the old
        # vertices' here, the ones it added appended by topology_changed
        self._rest_shape = self.sheet.positions[:self._rest_shape.shape[0]].copy()
        self.topology_changed()
        if self.config.solver.method != 'constrained':
            return  # springs that are forces: the memories pull as Eq. 6 has them
        self._bending.take_shape(self.sheet.positions, self.damage.moved_by_crumple)
        # a crumple's creases pull the sheet towards their memory frame by frame, not at
        # once (Simulator._yield_memory): their rests start at the lengths they have
        sheet = self.sheet
        springs = self._memory_springs
        length = spring_lengths(sheet.positions, sheet.spring_vertices[springs])
        pulling = sheet.spring_rest_length[springs] < length
        self._memory_target[springs[pulling]] = sheet.spring_rest_length[springs[pulling]]
        sheet.spring_rest_length[springs[pulling]] = length[pulling]
        self._memory_length[:] = np.inf
        self._rest_lengths_changed()

    @property
    def breaks(self) -> int:
        """HINGE springs broken since the last reset."""
        return self.damage.breaks

    @property
    def folds(self) -> int:
        """Edges folded since the last reset."""
        return self.damage.folds

    # -------------------------------------------------------------------------- reads
    def vertex_normals(self) -> np.ndarray:
        """(V, 3) float64 area-weighted unit vertex normals of the sheet now."""
        return vertex_normals(self.sheet.positions, self.sheet.triangles)

    def damage_labels(self) -> np.ndarray:
        """(V,) uint16 per vertex: 0 intact, 1 on a crease or fold, 2 inserted by a break
        (``core.sheet.damage_labels``)."""
        sheet = self.sheet
        return damage_labels(sheet.vertex_count, sheet.spring_vertices, sheet.spring_kind,
                             self.initial_sheet.vertex_count)

    # ------------------------------------------------------------------------ metrics
    def max_strain(self) -> float:
        """Largest |l/l0 - 1| over HINGE springs now."""
        sheet = self.sheet
        return float(kernels.max_abs_strain(sheet.positions, sheet.spring_vertices,
                                            sheet.spring_rest_length, sheet.spring_kind, HINGE))

    def energy(self) -> float:
        """Kinetic + gravitational + elastic energy [J]. The elastic part counts what
        acts as a force: every spring for 'paper' and 'explicit'; for 'constrained' the
        dihedral bending, its held springs being inextensible (their slack within the
        strain band stores nothing). Computed once for a sleeping sheet."""
        if self._rest_energy is not None:
            return self._rest_energy
        sheet = self.sheet
        gravity = np.asarray(self.config.solver.gravity)
        kinetic = self._kinetic_energy()
        potential = -np.sum(sheet.vertex_mass * (sheet.positions @ gravity))
        if self.config.solver.method == 'constrained':
            energy = float(kinetic + potential + self._bending.energy(sheet.positions))
            if self.asleep:
                self._rest_energy = energy
            return energy
        elastic_springs = np.ones(sheet.spring_count, dtype=bool)
        ends = sheet.spring_vertices[elastic_springs]
        length = np.linalg.norm(sheet.positions[ends[:, 1]] - sheet.positions[ends[:, 0]], axis=1)
        stretch = length - sheet.spring_rest_length[elastic_springs]
        elastic = 0.5 * np.sum(sheet.spring_stiffness[elastic_springs] * stretch ** 2)
        return float(kinetic + potential + elastic)

    def max_probe_penetration(self) -> float:
        """Deepest any vertex sits inside an active probe now [m] (0 when none); a probe
        pressed into the table is flattened there (kernels.probe_penetration)."""
        contact = self.config.contact
        probes = self.probes
        return float(kernels.probe_penetration(self.sheet.positions, probes.end, probes.radius,
                                               probes.active, contact.ground_height,
                                               contact.ground_enabled))

    def max_table_penetration(self) -> float:
        """Deepest any vertex sits below the table now [m] (0 without a table)."""
        contact = self.config.contact
        if not contact.ground_enabled:
            return 0.0
        return float(kernels.table_penetration(self.sheet.positions, contact.ground_height))


def squeeze_multiple(config: SimulationConfig) -> int:
    """The multiple of ``substeps`` a squeeze's frames run (SolverConfig): at least
    ``squeeze_substeps``, and as many as make a sub-step at most ``squeeze_step_ratio``
    bending periods l² √(ρ_A / B) of the sheet's grid cell (none where the ratio is 0), at
    most SQUEEZE_MULTIPLE_MOST."""
    solver, sheet = config.solver, config.sheet
    if solver.squeeze_step_ratio == 0.0:
        return solver.squeeze_substeps
    cell = min(sheet.width / (sheet.nx - 1), sheet.height / (sheet.ny - 1))
    period = cell * cell * math.sqrt(sheet.grammage / sheet.bending_rigidity)
    periods = solver.dt / solver.substeps / period
    return max(solver.squeeze_substeps,
               min(math.ceil(periods / solver.squeeze_step_ratio - 1e-9), SQUEEZE_MULTIPLE_MOST))


def pin_distance_levels(spring_vertices: np.ndarray, pinned: np.ndarray) -> np.ndarray:
    """Breadth-first hop count of every vertex from the nearest pinned vertex along the
    springs (0 at pins; vertex count + 1 where unreachable, or everywhere without pins)."""
    vertex_count = pinned.shape[0]
    unreached = vertex_count + 1
    level = np.where(pinned, 0, unreached).astype(np.int64)
    if spring_vertices.size == 0:
        return level
    first, second = spring_vertices[:, 0], spring_vertices[:, 1]
    current = 0
    while True:
        reached_first = (level[first] == current) & (level[second] == unreached)
        reached_second = (level[second] == current) & (level[first] == unreached)
        frontier = np.concatenate([second[reached_first], first[reached_second]])
        if frontier.size == 0:
            return level
        current += 1
        level[frontier] = current


def _changed_step(previous, change, pinned: np.ndarray):
    """``previous`` for its system plus a known ``change`` (rank-one terms): its factor
    updated (GlobalStep.updated), else answered by it (UpdatedStep.changed_by); None if
    neither can."""
    if previous is None or change is None:
        return None
    if isinstance(previous, GlobalStep):
        step = previous.updated(change, pinned)
        if step is not None:
            return step
    return UpdatedStep.changed_by(previous, term_entries(change), pinned)
