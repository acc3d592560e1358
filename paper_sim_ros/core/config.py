"""Plain, validated configuration of the simulation core.

Units are SI throughout the core: metres, kilograms, seconds, newtons.
Every dataclass validates itself on construction and raises ``ValueError`` with
the offending field named, so a bad value never reaches a kernel.
"""
from __future__ import annotations

from dataclasses import dataclass, field, fields
import math

SOLVERS = ('constrained', 'paper', 'explicit')
MEMBRANE_SCOPES = ('squeezed_or_settling', 'squeezed', 'always')


def _require(condition: bool, message: str) -> None:
    if not condition:
        raise ValueError(message)


def _finite_positive(name: str, value: float) -> None:
    _require(isinstance(value, (int, float)) and math.isfinite(value) and value > 0,
             f'{name} must be a finite number > 0, got {value!r}')


def _finite_non_negative(name: str, value: float) -> None:
    _require(isinstance(value, (int, float)) and math.isfinite(value) and value >= 0,
             f'{name} must be a finite number >= 0, got {value!r}')


@dataclass(frozen=True)
class SheetConfig:
    """The sheet of SPEC §1: a rectangle on a regular, alternately triangulated grid."""

    width: float = 0.210
    """Extent along x [m] (A4 short side)."""
    height: float = 0.297
    """Extent along y [m] (A4 long side)."""
    nx: int = 65
    """Vertices along x."""
    ny: int = 65
    """Vertices along y."""
    grammage: float = 0.080
    """Areal density [kg/m²] (80 g/m² office paper)."""
    stretch_stiffness: float = 3.0e5
    """In-plane stiffness E·t [N/m]; each HINGE spring gets k = E·t (EA/L with A = t·L)."""
    stretch_damping: float = 0.0
    """Axial damping of HINGE springs [N·s/m] (used by the spring-force solvers)."""
    bend_stiffness: float = 2.0
    """Stiffness of BEND springs [N/m] at the reference cell size of 4.64 mm (65 vertices on
    0.297 m); scaled with the cell size so that a sheet bends alike on any grid. The
    'paper' and 'explicit' solvers' bending; 'constrained' bends by ``bending_rigidity``."""
    bending_rigidity: float = 4.0e-4
    """Bending rigidity B [N·m] of the 'constrained' solver's plate and hinges
    (core/patches.py, core/bending.py): E·t³/12 of office paper, E ≈ 5 GPa along the
    fibres, t ≈ 0.1 mm."""
    bend_damping: float = 2.0e-4
    """Axial damping of BEND springs [N·s/m]."""
    aux_stiffness: float = 3.0e4
    """Stiffness of AUX (damage memory) springs [N/m]."""
    elevation: float = 0.0
    """Height of the flat sheet above the origin [m]."""

    def __post_init__(self) -> None:
        for name in ('width', 'height', 'grammage', 'stretch_stiffness', 'bend_stiffness',
                     'aux_stiffness', 'bending_rigidity'):
            _finite_positive(name, getattr(self, name))
        for name in ('stretch_damping', 'bend_damping'):
            _finite_non_negative(name, getattr(self, name))
        _require(math.isfinite(self.elevation), f'elevation must be finite, got {self.elevation}')
        for name in ('nx', 'ny'):
            value = getattr(self, name)
            _require(isinstance(value, int) and 3 <= value <= 1025,
                     f'{name} must be an integer in [3, 1025], got {value!r}')
        _require(self.width <= 10 and self.height <= 10, 'a sheet larger than 10 m is absurd')


@dataclass(frozen=True)
class SolverConfig:
    """Time stepping (SPEC §2)."""

    method: str = 'constrained'
    """'constrained' (default): HINGE and AUX springs held within a strain band (projective
    local/global iterations, then Gauss–Seidel strain limiting), dihedral bending implicit;
    'paper': the paper's Eq. 6 Jacobi iteration, every spring a force;
    'explicit': symplectic Euler, kept to show why the paper needs an implicit method."""
    dt: float = 1.0 / 60.0
    """Frame step [s]."""
    substeps: int = 1
    """Integration sub-steps per frame."""
    jacobi_iterations: int = 10
    """Jacobi iterations of Eq. 6 per sub-step ('paper')."""
    projective_iterations: int = 3
    """Local/global iterations per sub-step ('constrained'), at least."""
    projective_max_iterations: int = 30
    """Bounds the extra local/global iterations of a squeezed sheet: beyond
    ``projective_iterations``, up to this minus ``projective_iterations`` run before the
    bending solve and as many after it, while held springs are compressed by more than
    ``buckling_compression`` and each iteration still takes ``BUCKLING_PROGRESS``
    (core/simulator.py) of that compression out (the sheet is buckling)."""
    buckling_compression: float = 0.01
    """Compression (1 - l/l0) of a held spring that keeps the local/global iterations going
    (a squeezed sheet buckles as they turn the springs' targets; docs/solver.md)."""
    global_stiffness: float = 600.0
    """Weight [N/m] of the held springs in the global step ('constrained'). It is a solver
    weight, not the material's E·t: the strain band, not this, holds paper inextensible;
    far larger weights lock the sheet's rotation in few iterations."""
    constraint_iterations: int = 4
    """Symmetric Gauss–Seidel strain-limiting sweeps per sub-step ('constrained')."""
    max_stretch: float = 0.003
    """Stretch the projection aims for at most (l/l0 - 1)."""
    max_compression: float = 0.003
    """Compression the projection aims for at most (1 - l/l0)."""
    gripped_max_compression: float = 0.05
    """Compression the projection aims for at most while a probe grips the sheet on the
    table. Paper pushed together there must buckle, which the projection's in-plane sweeps
    cannot do: held to ``max_compression`` they only carry the compression to the grip,
    which they cannot move (docs/contact.md, "The strain band while a fingertip grips")."""
    air_damping: float = 0.2
    """Linear air drag rate [1/s], mass proportional."""
    air_density: float = 1.2
    """Density of the air [kg/m³] (0: vacuum), for the drag across the sheet."""
    drag_coefficient: float = 1.2
    """Pressure drag coefficient of the sheet moving along its normal (a flat plate's,
    ~1.2): each vertex's normal speed v_n loses ½ ρ C_d v_n² of pressure over its area,
    so a flat 80 g/m² sheet falls at about 1 m/s and a swinging one is slowed by the air
    it pushes, as paper is; edgewise it meets only ``air_damping``. ('constrained'; the
    paper's own solvers keep its model, ``air_damping`` alone.)"""
    gravity: tuple = (0.0, 0.0, -9.81)
    """Gravity [m/s²]."""
    length_projection: bool = False
    """('constrained') Between the bending solve and the springs' iterations, project the
    held springs onto the strain band by Newton steps on their lengths
    (core/length_projection.py, Goldenthal et al. 2007): a drooping strip then settles at
    the elastica's tip angle at large deflections too (within 2 % up to 72°, where it is
    8–14 % short without), at a cost (docs/solver.md). Off by default: it makes a hanging
    sheet several times slower, and its swing strains more (1.1 % against 0.35 %, 65²)."""
    membrane_weight: float = 30.0
    """('constrained') The held springs' membrane in the bending solve, its weight per
    spring this × B / l0² (core/membrane.py; 0: none): the bending solve then keeps the
    edges' lengths while it turns them, which the springs' iterations alone cannot.
    Where it runs: ``membrane_scope``."""
    membrane_scope: str = 'squeezed_or_settling'
    """('constrained') Which sub-steps take the membrane: 'squeezed', only those in which
    probes push the sheet together (a fingertip pinches it on the table or a probe lifts
    off it, and a held spring is squeezed beyond ``buckling_compression``: the arch it
    buckles into is crushed without the membrane, docs/contact.md), so a sheet nothing
    squeezes steps as fast as without it; 'squeezed_or_settling' (the default), those and,
    once a pinned sheet hanging clear of the table would fall asleep, every sub-step until
    it does so again: a drooping strip then rests at the elastica (without, 8-14 % short of
    it beyond 45°), and only its last settling costs more; 'always', every sub-step (also
    a swinging sheet, at 2-4 times the cost: docs/solver.md)."""
    membrane_iterations: int = 10
    """Conjugate-gradient iterations of the membrane's solve per sub-step, at most (each
    a bending solve)."""
    release_substeps: int = 4
    """('constrained') Sub-steps a frame, as a multiple of ``substeps``, for
    ``release_time`` after a fingertip lets go of the sheet while it is pushed together (a
    held spring squeezed beyond ``buckling_compression``; 1: never more). A squeezed
    arch set free springs back in its bending mode in about a frame (a 0.2 m arch: a
    quarter period of 22 ms), which one sub-step cannot follow: its crest folds on the way
    down and strains the sheet (`squeeze` at 65², seeds 0, 1, 3: 27 folds and 23.2 % with
    1, none and 12.6 %, its largest strain then the push's, with 4; docs/contact.md). A
    fingertip lifting off paper it did not push together starts none."""
    release_time: float = 0.25
    """How long [s] the sub-steps of ``release_substeps`` (or ``give_substeps``) last after
    a let-go."""
    give_substeps: int = 4
    """('constrained') Sub-steps a frame, as a multiple of ``substeps``, for ``release_time``
    after a fingertip's grip gives (``ContactConfig.grip_give``; 1: never more). That
    let-go is under load: the paper it held springs back at once, so they start in the
    very sub-step after the give (random pinned scene 8405: 29.9 % over the run with one
    sub-step, 12.1 % with four; docs/contact.md, "A grip gives where the paper behind it
    stretches")."""
    squeeze_step_ratio: float = 125.0
    """('constrained') While a fingertip that pinches the sheet on the table pushes it
    together (a held spring squeezed beyond ``buckling_compression`` after a sub-step), a
    sub-step lasts at most this many times the bending period of a grid cell, l² √(ρ_A / B)
    (l the shorter cell side, ρ_A the grammage, B the bending rigidity): from that sub-step
    on, frames run as many times ``substeps`` as that takes, for as long as a fingertip
    grips the sheet and ``release_time`` after (0: no bound from the cells; then only
    ``squeeze_substeps``). A longer step than that tangles the squeezed sheet: the split
    step carries the sheet's mesh-scale bending modes the less faithfully the more of
    their periods a step spans. A4 printer paper needs none
    of it up to 65 × 65 vertices at 60 Hz (the default scene, 110 periods a step); at 97²,
    2 sub-steps, at 129², 4; cardboard at 65², 3 (docs/contact.md, "Sub-steps a squeeze
    needs")."""
    squeeze_substeps: int = 1
    """('constrained') While fingertips push the sheet together (``squeeze_step_ratio``),
    frames run at least this many times ``substeps``. 4: `squeeze` at 65² strains 6.2-8.1 %
    instead of 12.6-19.2 % (seeds 0-4) and the worst of 45 random fingertip scenes on a
    table 38.5 % instead of 72.9 %, at half the squeeze's speed; the arch then springs back when
    let go (relaxed 0.5-1.0 mm instead of 9-11 mm: with one sub-step that set is the
    crinkling the strain leaves). 1 by default (docs/contact.md, "Sub-steps a squeeze
    needs")."""
    energy_restoring: bool = False
    """('constrained') After a frame in which nothing but gravity, air and the pins acted
    and nothing yielded or broke, give back the energy the step lost beyond air drag by
    scaling the velocities (without changing a free sheet's momenta): one implicit step
    projected back to the edge lengths loses about (vh/L)²/3 of a swinging sheet's speed a
    frame. On, one sub-step swings as 128 do; off by default because a sheet that keeps its
    swing is strained more by what then touches it (docs/solver.md)."""
    sleep_speed: float = 1e-4
    """A sheet whose every vertex moved slower than this [m/s] on average over the last
    ``sleep_time``, and moves slower now, with nothing near it changing, falls asleep: it
    holds still at no cost until a probe near it moves, appears or leaves, or the sheet or
    the settings change (a physics engine's sleeping body; docs/solver.md, "Sleeping").
    0: never."""
    sleep_time: float = 0.5
    """How long [s] a sheet stays that still before it falls asleep."""

    def __post_init__(self) -> None:
        _require(self.method in SOLVERS, f'method must be one of {SOLVERS}, got {self.method!r}')
        _finite_positive('dt', self.dt)
        _require(self.dt <= 0.1, f'dt must be <= 0.1 s, got {self.dt}')
        for name, upper in (('substeps', 10000), ('jacobi_iterations', 100000),
                            ('projective_iterations', 1000), ('projective_max_iterations', 1000),
                            ('constraint_iterations', 10000),
                            ('membrane_iterations', 1000), ('release_substeps', 64),
                            ('give_substeps', 64), ('squeeze_substeps', 64)):
            value = getattr(self, name)
            _require(isinstance(value, int) and 0 <= value <= upper,
                     f'{name} must be an integer in [0, {upper}], got {value!r}')
        _require(self.substeps >= 1, 'substeps must be >= 1')
        _require(self.release_substeps >= 1, 'release_substeps must be >= 1')
        _require(self.give_substeps >= 1, 'give_substeps must be >= 1')
        _require(self.squeeze_substeps >= 1, 'squeeze_substeps must be >= 1')
        _require(math.isfinite(self.squeeze_step_ratio) and self.squeeze_step_ratio >= 0,
                 f'squeeze_step_ratio must be finite and >= 0, got {self.squeeze_step_ratio!r}')
        _require(math.isfinite(self.release_time) and 0 <= self.release_time <= 60,
                 f'release_time must be in [0, 60] s, got {self.release_time!r}')
        for name in ('max_stretch', 'max_compression', 'gripped_max_compression'):
            value = getattr(self, name)
            _require(math.isfinite(value) and 0 < value < 0.5,
                     f'{name} must be in (0, 0.5), got {value!r}')
        _finite_non_negative('air_damping', self.air_damping)
        _finite_non_negative('air_density', self.air_density)
        _finite_non_negative('drag_coefficient', self.drag_coefficient)
        _finite_non_negative('sleep_speed', self.sleep_speed)
        _finite_non_negative('sleep_time', self.sleep_time)
        _require(math.isfinite(self.buckling_compression) and 0 < self.buckling_compression < 1,
                 f'buckling_compression must be in (0, 1), got {self.buckling_compression!r}')
        _finite_positive('global_stiffness', self.global_stiffness)
        _finite_non_negative('membrane_weight', self.membrane_weight)
        _require(self.membrane_scope in MEMBRANE_SCOPES,
                 f'membrane_scope must be one of {MEMBRANE_SCOPES}, '
                 f'got {self.membrane_scope!r}')
        _require(len(self.gravity) == 3 and all(math.isfinite(g) for g in self.gravity),
                 f'gravity must be three finite numbers, got {self.gravity!r}')
        _require(isinstance(self.energy_restoring, bool),
                 f'energy_restoring must be a bool, got {self.energy_restoring!r}')
        _require(isinstance(self.length_projection, bool),
                 f'length_projection must be a bool, got {self.length_projection!r}')


@dataclass(frozen=True)
class ContactConfig:
    """Probes and the ground plane (SPEC §3)."""

    ground_enabled: bool = False
    ground_height: float = 0.0
    """Height of the table [m]."""
    ground_friction: float = 0.4
    probe_friction: float = 0.6
    max_probe_distance: float = 100.0
    """Probe centres farther than this from the origin [m] are refused as absurd."""
    grip_give: float = 0.1
    """A fingertip's grip lets go where the paper behind it (along its motion, within
    GIVE_REACH radii of it) has been stretched beyond this for GIVE_PERSISTENCE sub-steps
    (0: never): paper held elsewhere (a
    pin, another fingertip, the table) slips from under a fingertip long before it
    stretches. The grips' reach checks (Simulator._slip_grips) catch a fingertip moving
    away from what holds the paper, not one that shears it: random pinned scene 8405
    stretched to 265 %. A limit of the solver's error, not of paper's band: a moving grip's
    rim strains 5-12 % (docs/contact.md)."""

    def __post_init__(self) -> None:
        _require(math.isfinite(self.ground_height), 'ground_height must be finite')
        for name in ('ground_friction', 'probe_friction'):
            value = getattr(self, name)
            _require(math.isfinite(value) and 0 <= value <= 10,
                     f'{name} must be in [0, 10], got {value!r}')
        _finite_positive('max_probe_distance', self.max_probe_distance)
        _require(math.isfinite(self.grip_give) and 0 <= self.grip_give <= 10,
                 f'grip_give must be in [0, 10], got {self.grip_give!r}')


@dataclass(frozen=True)
class DamageConfig:
    """Breakable hinge springs, hinge folds and random damage (SPEC §4, paper Eq. 7–8).
    Defaults look like 80 g/m² office paper; see ``materials.MATERIAL_PRESETS``."""

    enabled: bool = True
    fragility: float = 1.0
    """φ of Eq. 7, P = (1 - l/l0)^φ: large → rubbery, small → fragile."""
    area_conservation: float = 1.0
    """ψ of Eq. 8, h = ψ/2·sqrt(l0² - l²); with ψ = 1 the two halves come out at rest length."""
    fold_threshold: float = 0.6
    """An interior edge folds when |x_r - x_l| / d0 of its BEND spring falls below this."""
    check_rate: float = 60.0
    """Damage checks per simulated second (independent of the sub-step count) [Hz]."""
    compression_floor: float = 0.01
    """Compression 1 - l/l0 below which a hinge never breaks (solver tolerance, noise)."""
    min_breakable_length: float = 1.5e-3
    """HINGE springs with a shorter rest length do not break [m]."""
    max_vertices: int = 30000
    """Vertex cap: at it damage stops (one warning is logged)."""
    min_crease_ratio: float = 0.6
    """A crease remembers a broken spring at no less than this × l0; random damage
    (crumple) draws its l/l0 in [this, 1)."""
    crumple_fold_fraction: float = 0.5
    """Share of random-damage events that are folds rather than breaks."""
    yield_curvature: float = 100.0
    """Curvature beyond which bending sets (paper's plasticity: its fibres yield at about
    0.5 % strain, 2 ε / t = 100 /m for a 0.1 mm sheet: rolled tighter than a 1 cm radius it
    keeps a curl) [1/m]; a hinge bent further than this from its rest shape keeps the
    excess. 0: elastic ('constrained' solver only)."""

    def __post_init__(self) -> None:
        _require(isinstance(self.enabled, bool), f'enabled must be a bool, got {self.enabled!r}')
        _finite_positive('fragility', self.fragility)
        _require(self.fragility <= 100, f'fragility must be <= 100, got {self.fragility}')
        _require(isinstance(self.area_conservation, (int, float))
                 and 0 <= self.area_conservation <= 2,
                 f'area_conservation must be in [0, 2], got {self.area_conservation!r}')
        _require(isinstance(self.fold_threshold, (int, float))
                 and 0 <= self.fold_threshold < 1,
                 f'fold_threshold must be in [0, 1), got {self.fold_threshold!r}')
        _finite_positive('check_rate', self.check_rate)
        _finite_non_negative('yield_curvature', self.yield_curvature)
        _require(self.check_rate <= 10000,
                 f'check_rate must be <= 10000 Hz, got {self.check_rate}')
        _require(isinstance(self.compression_floor, (int, float))
                 and 0 <= self.compression_floor < 1,
                 f'compression_floor must be in [0, 1), got {self.compression_floor!r}')
        _finite_non_negative('min_breakable_length', self.min_breakable_length)
        _require(isinstance(self.max_vertices, int) and 9 <= self.max_vertices <= 10_000_000,
                 f'max_vertices must be an integer in [9, 10000000], got {self.max_vertices!r}')
        _require(isinstance(self.min_crease_ratio, (int, float))
                 and 0 < self.min_crease_ratio < 1,
                 f'min_crease_ratio must be in (0, 1), got {self.min_crease_ratio!r}')
        _require(isinstance(self.crumple_fold_fraction, (int, float))
                 and 0 <= self.crumple_fold_fraction <= 1,
                 f'crumple_fold_fraction must be in [0, 1], got {self.crumple_fold_fraction!r}')


@dataclass(frozen=True)
class SimulationConfig:
    """Everything the core needs to build and step a sheet."""

    sheet: SheetConfig = field(default_factory=SheetConfig)
    solver: SolverConfig = field(default_factory=SolverConfig)
    contact: ContactConfig = field(default_factory=ContactConfig)
    seed: int = 0
    damage: DamageConfig = field(default_factory=DamageConfig)

    def __post_init__(self) -> None:
        _require(isinstance(self.seed, int) and 0 <= self.seed < 2**63,
                 f'seed must be a non-negative integer, got {self.seed!r}')


def from_mapping(cls, values: dict):
    """Build a config dataclass from a plain mapping, refusing unknown keys by name."""
    known = {f.name for f in fields(cls)}
    unknown = sorted(set(values) - known)
    if unknown:
        raise ValueError(f'unknown {cls.__name__} keys: {", ".join(unknown)}')
    converted = {}
    for key, value in values.items():
        if key == 'gravity':
            value = tuple(float(g) for g in value)
        converted[key] = value
    return cls(**converted)
