"""The node's parameters: one table, declared once, frozen into the core's config dataclasses.

Every parameter has a description and, where it is a number, a range that rclpy itself
enforces; ``read_only`` ones are fixed at start-up (the sheet, the solver method, the probe
topics...). ``settings_from_values`` turns a complete set of values into ``NodeSettings`` or
raises ``ValueError`` with the reason, which is how run-time changes are validated before
anything running is touched.

Material presets. ``material`` names a preset of ``core.materials``; the node declares it
first, and the preset's values become the *defaults* of the ``sheet.*`` and ``damage.*``
parameters it names (``declared_defaults``). rclpy gives a parameter the value of the
parameter file or the command line when there is one, else its declared default, so a value
given explicitly wins over the preset, and ``ros2 param get`` shows what is in use.
"""
from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Any, Mapping

from .core.appearance import FULL_DETAIL_LEVEL, AppearanceConfig
from .core.camera import DEFAULT_POSITION, DEFAULT_TARGET, CameraConfig, camera_looking_at
from .core.config import (MEMBRANE_SCOPES, SOLVERS, ContactConfig, DamageConfig, SheetConfig,
                          SimulationConfig, SolverConfig, from_mapping)
from .core.materials import MATERIAL_PRESETS, material_preset
from .core.scenarios import PIN_MODES, ScenarioCamera
from .core.simulator import BUCKLING_PROGRESS


@dataclass(frozen=True)
class ParameterSpec:
    name: str
    default: Any
    description: str
    bounds: tuple | None = None
    """(low, high), inclusive; an ``IntegerRange`` or ``FloatingPointRange``."""
    read_only: bool = False


@dataclass(frozen=True)
class NodeSettings:
    """Everything the node runs with, validated."""

    simulation: SimulationConfig
    frame_id: str
    physics_rate: float
    publish_rate: float
    markers_rate: float
    diagnostics_rate: float
    max_catchup_frames: int
    strain_warning: float
    publish_clock: bool
    max_real_time_factor: float
    material: str
    """The material preset the sheet.* and damage.* defaults came from; '' : none."""
    appearance: AppearanceConfig
    pin_mode: str
    probe_topics: tuple
    probe_radii: tuple
    """One radius per probe topic [m]."""
    probe_timeout: float
    crumple_count: int
    crumple_seed: int
    dense_samples: int
    noise_stddev: float
    noise_seed: int
    hinge_springs: bool
    aux_springs: bool
    bend_springs: bool
    rerun_path: str
    rerun_connect: str
    cameras: tuple[ScenarioCamera, ...]
    """The virtual cameras, in the order of the ``cameras`` parameter; rate 0: off."""
    bag_path: str


_SHEET = SheetConfig()
_SOLVER = SolverConfig()
_CONTACT = ContactConfig()
_DAMAGE = DamageConfig()
_APPEARANCE = AppearanceConfig()
_CAMERA = CameraConfig()
DEFAULT_CAMERA_NAME = _CAMERA.name

GLOBAL_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec('frame_id', 'world', 'Frame of the sheet: of every published header, and the '
                  'only frame accepted for probe poses.', read_only=True),
    ParameterSpec('physics_rate', 60.0, 'Simulation frames per second of simulated time; one '
                  'frame steps dt = 1 / physics_rate [Hz].', (1.0, 1000.0), read_only=True),
    ParameterSpec('publish_rate', 30.0, 'Rate of paper/points in simulated time [Hz]; 0: off.',
                  (0.0, 1000.0)),
    ParameterSpec('markers_rate', 10.0, 'Rate of paper/markers in simulated time [Hz]; 0: off. '
                  'The largest output: about 1.6 MB a frame at 65 x 65 with the springs.',
                  (0.0, 1000.0)),
    ParameterSpec('diagnostics_rate', 1.0, 'Rate of /diagnostics in wall-clock time [Hz].',
                  (0.1, 100.0)),
    ParameterSpec('max_catchup_frames', 4, 'Frames stepped in one timer tick to catch up with '
                  'the clock; beyond that the simulation slips (real-time factor < 1, reported '
                  'in diagnostics). Publishing is what is dropped first, never physics frames.',
                  (1, 1000)),
    ParameterSpec('strain_warning', 0.02, '/diagnostics warns while the sheet\'s largest HINGE '
                  'strain |l/l0 - 1| over its window exceeds this: paper stretches well under '
                  '1 %, so beyond it the simulation no longer keeps the sheet paper (fingertips '
                  'pushing it together on the table, docs/contact.md); 0: never.', (0.0, 100.0)),
    ParameterSpec('publish_clock', False, 'The simulation is the clock: it steps as fast as '
                  'it can (up to max_real_time_factor), never slips, and publishes its time on '
                  '/clock after every frame, from 0, for nodes run with use_sim_time:=true '
                  '(probe poses are then stamped in simulated time). Not with use_sim_time.',
                  read_only=True),
    ParameterSpec('max_real_time_factor', 1.0, 'With publish_clock: the most simulated '
                  'seconds a wall-clock second; 0: as fast as it steps (at most 1 000 frames a '
                  'wall-clock second).', (0.0, 1000.0)),
    ParameterSpec('seed', 0, 'Seed of every random draw of the simulation (damage, crumple).',
                  (0, 2**62), read_only=True),
    ParameterSpec('material', '', "Material preset, one of '' (none), "
                  f'{", ".join(MATERIAL_PRESETS)}: its values become the defaults of the '
                  'sheet.* and damage.* parameters it names; a value given in the parameter '
                  'file or on the command line wins.', read_only=True),
    ParameterSpec('sheet.width', _SHEET.width, 'Sheet extent along x [m].', (0.01, 10.0),
                  read_only=True),
    ParameterSpec('sheet.height', _SHEET.height, 'Sheet extent along y [m].', (0.01, 10.0),
                  read_only=True),
    ParameterSpec('sheet.nx', _SHEET.nx, 'Vertices along x (2^N + 1 is natural).', (3, 1025),
                  read_only=True),
    ParameterSpec('sheet.ny', _SHEET.ny, 'Vertices along y (2^N + 1 is natural).', (3, 1025),
                  read_only=True),
    ParameterSpec('sheet.grammage', _SHEET.grammage, 'Areal density [kg/m^2].', (0.001, 10.0),
                  read_only=True),
    ParameterSpec('sheet.stretch_stiffness', _SHEET.stretch_stiffness,
                  'In-plane stiffness E*t of HINGE springs [N/m].', (1.0, 1.0e9),
                  read_only=True),
    ParameterSpec('sheet.bend_stiffness', _SHEET.bend_stiffness,
                  'BEND spring stiffness at the reference cell size [N/m] (paper and '
                  'explicit solvers).', (1.0e-6, 1.0e6), read_only=True),
    ParameterSpec('sheet.bending_rigidity', _SHEET.bending_rigidity,
                  'Bending rigidity B of the constrained solver [N*m].', (1.0e-9, 1.0),
                  read_only=True),
    ParameterSpec('sheet.aux_stiffness', _SHEET.aux_stiffness,
                  'Stiffness of AUX (damage memory) springs [N/m].', (1.0e-3, 1.0e9),
                  read_only=True),
    ParameterSpec('sheet.elevation', 0.0, 'Height of the flat initial sheet [m].',
                  (-100.0, 100.0), read_only=True),
    ParameterSpec('solver.method', _SOLVER.method, f'Integrator, one of {", ".join(SOLVERS)}.',
                  read_only=True),
    ParameterSpec('solver.substeps', _SOLVER.substeps, 'Integration sub-steps per frame.',
                  (1, 10000)),
    ParameterSpec('solver.jacobi_iterations', _SOLVER.jacobi_iterations,
                  'Jacobi iterations of Eq. 6 per sub-step.', (0, 100000)),
    ParameterSpec('solver.constraint_iterations', _SOLVER.constraint_iterations,
                  "Strain-limiting sweeps per sub-step ('constrained' method).", (0, 10000)),
    ParameterSpec('solver.projective_iterations', _SOLVER.projective_iterations,
                  "Local/global iterations per sub-step, at least ('constrained' method).",
                  (0, 1000)),
    ParameterSpec('solver.projective_max_iterations', _SOLVER.projective_max_iterations,
                  'Bounds the extra local/global iterations of a squeezed sheet: beyond the '
                  'least, up to this minus the least run before the bending solve and as '
                  'many after it, while held springs are compressed by more than '
                  f'buckling_compression and each iteration takes '
                  f'{100 * BUCKLING_PROGRESS:g} % of that out.',
                  (0, 1000)),
    ParameterSpec('solver.buckling_compression', _SOLVER.buckling_compression,
                  'Compression (1 - l/l0) of a held spring that keeps the local/global '
                  'iterations going (a squeezed sheet buckles as they go on).', (1.0e-6, 0.99)),
    ParameterSpec('solver.global_stiffness', _SOLVER.global_stiffness,
                  "Weight of the held springs in the global step [N/m] ('constrained'; a "
                  'solver weight, not the material stiffness).', (1.0e-3, 1.0e9)),
    ParameterSpec('solver.air_damping', _SOLVER.air_damping,
                  'Linear air drag rate, mass proportional [1/s].', (0.0, 1000.0)),
    ParameterSpec('solver.air_density', _SOLVER.air_density,
                  'Density of the air [kg/m^3] (0: vacuum), for the drag across the sheet.',
                  (0.0, 100.0)),
    ParameterSpec('solver.drag_coefficient', _SOLVER.drag_coefficient,
                  "Pressure drag coefficient of the sheet moving along its normal (a flat "
                  "plate's, about 1.2: a flat sheet falls at about 1 m/s).", (0.0, 100.0)),
    ParameterSpec('solver.energy_restoring', _SOLVER.energy_restoring,
                  "After a frame of free motion (no probe, off the table, nothing yielded "
                  "or broke), give back the energy the step lost beyond air drag "
                  "('constrained'; one sub-step then swings as many do)."),
    ParameterSpec('solver.length_projection', _SOLVER.length_projection,
                  "Project the held springs onto the strain band between the bending solve "
                  "and the springs' iterations ('constrained'; bending right at large "
                  'deflections, several times slower).'),
    ParameterSpec('solver.membrane_weight', _SOLVER.membrane_weight,
                  "The held springs as a membrane in the bending solve, each of weight this "
                  "x B / rest length^2 ('constrained'; 0: none; 30: a squeezed sheet's arch "
                  'kept from crushing).', (0.0, 1.0e6)),
    ParameterSpec('solver.membrane_scope', _SOLVER.membrane_scope,
                  f'Sub-steps that take the membrane, one of {", ".join(MEMBRANE_SCOPES)}: '
                  'squeezed, only while probes push the sheet together; squeezed_or_settling, '
                  'also while a pinned sheet hanging clear of the table settles to rest (a '
                  'drooping strip rests at the elastica); always, every one (1.5-4 times '
                  'slower).'),
    ParameterSpec('solver.membrane_iterations', _SOLVER.membrane_iterations,
                  "Conjugate-gradient iterations of the membrane's solve per sub-step, at "
                  'most (each a bending solve).', (0, 1000)),
    ParameterSpec('solver.gripped_max_compression', _SOLVER.gripped_max_compression,
                  'Compression (1 - l/l0) the strain band allows while a fingertip grips the '
                  'sheet on the table (paper pushed together there must buckle).',
                  (1e-6, 0.49)),
    ParameterSpec('solver.release_substeps', _SOLVER.release_substeps,
                  'Sub-steps a frame, times substeps, for release_time after a fingertip '
                  'lets go of the sheet while it is pushed together (1: never more): a '
                  'squeezed arch set free springs back in about a frame, faster than one '
                  'sub-step follows (docs/contact.md).',
                  (1, 64)),
    ParameterSpec('solver.release_time', _SOLVER.release_time,
                  'How long [s] the sub-steps of release_substeps (or give_substeps) last '
                  'after a let-go.', (0.0, 60.0)),
    ParameterSpec('solver.give_substeps', _SOLVER.give_substeps,
                  'Sub-steps a frame, times substeps, for release_time after a fingertip\'s '
                  'grip gives (contact.grip_give; 1: never more): the paper it held under load '
                  'springs back at once.', (1, 64)),
    ParameterSpec('solver.squeeze_step_ratio', _SOLVER.squeeze_step_ratio,
                  'While fingertips pinching the sheet on the table push it together, a '
                  'sub-step lasts at most this many bending periods of a grid cell (the '
                  'frames then run as many times substeps as that takes; 0: no bound from '
                  'the cells, only squeeze_substeps): longer, a squeeze on fine cells '
                  'tangles (docs/contact.md).', (0.0, 1e6)),
    ParameterSpec('solver.squeeze_substeps', _SOLVER.squeeze_substeps,
                  'While fingertips push the sheet together, frames run at least this many '
                  'times substeps (4: squeeze at 65² strains half as much, at half its speed, '
                  'and its arch springs back when let go; docs/contact.md).', (1, 64)),
    ParameterSpec('solver.sleep_speed', _SOLVER.sleep_speed,
                  'A sheet whose every vertex moved slower than this [m/s] on average over '
                  'sleep_time, and moves slower now, nothing near it changing, sleeps: it '
                  'holds still at no cost until a probe near it moves or the settings change '
                  '(0: never).', (0.0, 1.0)),
    ParameterSpec('solver.sleep_time', _SOLVER.sleep_time,
                  'How long [s] a sheet stays that still before it sleeps.', (0.0, 3600.0)),
    ParameterSpec('contact.ground_enabled', True, 'A table (ground plane) under the sheet.'),
    ParameterSpec('contact.ground_height', 0.0, 'Height of the table [m].', (-100.0, 100.0)),
    ParameterSpec('contact.ground_friction', _CONTACT.ground_friction,
                  'Friction coefficient of the table.', (0.0, 10.0)),
    ParameterSpec('contact.probe_friction', _CONTACT.probe_friction,
                  "Friction coefficient of the probes (above the table's, a probe pressed "
                  'into the table grips the paper).', (0.0, 10.0)),
    ParameterSpec('contact.grip_give', _CONTACT.grip_give,
                  'A fingertip\'s grip lets go where the paper behind it, along its motion, '
                  'is stretched beyond this (0: never): paper held elsewhere (a pin, another '
                  'fingertip) slips from under a fingertip before it stretches.', (0.0, 10.0)),
    ParameterSpec('contact.max_probe_distance', 10.0, 'Probe poses farther than this from the '
                  "origin of frame_id are refused as absurd [m].", (0.01, 1.0e6)),
    ParameterSpec('pin_mode', 'none', f'Pinned vertices, one of {", ".join(PIN_MODES)} '
                  '(short_edge: the short edge at y = -height/2 is clamped).'),
    ParameterSpec('probe_topics', ['probe/pose'], 'geometry_msgs/PoseStamped topics, one '
                  'sphere probe each.', read_only=True),
    ParameterSpec('probe_radii', [0.02], 'Radius of each probe [m]: one per topic, or one for '
                  'all.'),
    ParameterSpec('probe_timeout', 0.5, 'A probe without a new pose for this long stops acting '
                  'on the sheet [s].', (0.001, 3600.0)),
    ParameterSpec('crumple_count', 20, 'Random damage events of one paper/crumple call.',
                  (0, 1000000)),
    ParameterSpec('crumple_seed', 0, 'Seed of paper/crumple (the n-th call uses seed + n).',
                  (0, 2**62)),
    ParameterSpec('points.dense_samples', 0, 'Random samples per triangle in paper/points; 0: '
                  'the vertices themselves.', (0, 64)),
    ParameterSpec('points.noise_stddev', 0.0, 'Gaussian noise on published point positions, '
                  'like a depth sensor [m].', (0.0, 0.05)),
    ParameterSpec('points.noise_seed', 0, 'Seed of the sampling and noise (with the frame '
                  'number: the same seed gives the same clouds).', (0, 2**62)),
    ParameterSpec('markers.hinge_springs', True, 'Draw HINGE springs (mesh edges).'),
    ParameterSpec('markers.aux_springs', True, 'Draw AUX springs (creases and folds).'),
    ParameterSpec('markers.bend_springs', False, 'Draw BEND springs.'),
    ParameterSpec('rerun_path', '', "Record every published frame to this .rrd file; '' : off.",
                  read_only=True),
    ParameterSpec('rerun_connect', '', "Stream to a Rerun viewer at this URL "
                  "(rerun+http://127.0.0.1:9876/proxy); '': off.", read_only=True),
    ParameterSpec('bag_path', '', "Record every published message to this rosbag2 directory "
                  "(MCAP storage; it must not exist yet), with the camera's pose on "
                  "/tf_static; '' : off.", read_only=True),
    ParameterSpec('cameras', [DEFAULT_CAMERA_NAME], 'Names of the virtual cameras; each name N '
                  'has the parameters N.rate, N.width, ... (as camera.* below) and publishes '
                  'paper/N/depth/image_raw (32FC1 [m], NaN where nothing is hit), '
                  'color/image_raw (rgb8), camera_info and points (an organised cloud with '
                  'material u, v and damage label per pixel), in frame N_optical_frame.',
                  read_only=True),
    ParameterSpec('damage.enabled', _DAMAGE.enabled, 'Breaks and folds happen (SPEC section '
                  '4).', read_only=True),
    ParameterSpec('damage.fragility', _DAMAGE.fragility, 'phi of Eq. 7: large is rubbery, '
                  'small is fragile.', (1e-6, 100.0), read_only=True),
    ParameterSpec('damage.area_conservation', _DAMAGE.area_conservation, 'psi of Eq. 8.',
                  (0.0, 2.0), read_only=True),
    ParameterSpec('damage.fold_threshold', _DAMAGE.fold_threshold, 'An interior edge folds '
                  'when |x_r - x_l| / d0 falls below this.', (0.0, 0.999), read_only=True),
    ParameterSpec('damage.max_vertices', _DAMAGE.max_vertices, 'Vertex cap: damage stops '
                  'there.', (9, 10000000), read_only=True),
    ParameterSpec('damage.yield_curvature', _DAMAGE.yield_curvature, 'Curvature beyond '
                  'which bending sets, as paper yields [1/m]; 0: elastic.', (0.0, 1.0e5),
                  read_only=True),
    ParameterSpec('appearance.texture_path', _APPEARANCE.texture_path, 'Image file mapped '
                  "onto the sheet (any format Pillow reads); '': the procedural paper "
                  'texture.', read_only=True),
    ParameterSpec('appearance.normal_level', _APPEARANCE.normal_level, 'Fractal level whose '
                  'normals light the surface (paper Fig. 10: 2 or 4); above the levels of the '
                  'grid: the full-detail normals.', (1, FULL_DETAIL_LEVEL), read_only=True),
    ParameterSpec('appearance.light_direction', list(_APPEARANCE.light_direction),
                  'Direction towards the light in frame_id: x y z, not all zero (need not be '
                  'unit length).', read_only=True),
    ParameterSpec('appearance.ambient', _APPEARANCE.ambient, 'Share of the brightness that '
                  'does not depend on the light.', (0.0, 1.0), read_only=True),
    ParameterSpec('appearance.texture_blend', _APPEARANCE.texture_blend, '0: plain white '
                  'paper, 1: the full texture, in between: the texture mixed with white.',
                  (0.0, 1.0), read_only=True),
    ParameterSpec('appearance.texture_seed', _APPEARANCE.texture_seed, 'Seed of the '
                  'procedural texture.', (0, 2**62), read_only=True),
    ParameterSpec('appearance.texture_size', _APPEARANCE.texture_size, 'Pixels along the '
                  'longer side of the procedural texture.', (16, 2048), read_only=True),
)


def camera_parameters(name: str) -> tuple[ParameterSpec, ...]:
    """The parameters of the camera ``name`` (one entry of ``cameras``)."""
    return (
        ParameterSpec(f'{name}.rate', 0.0, 'Frames per second in simulated time [Hz]; 0: off.',
                      (0.0, 1000.0)),
        ParameterSpec(f'{name}.depth_noise_stddev', 0.0, 'Gaussian noise on the depth (and '
                      'the cloud), like a depth sensor [m]; seeded by points.noise_seed and '
                      'the frame number.', (0.0, 0.1)),
        ParameterSpec(f'{name}.width', _CAMERA.width, 'Image width [pixels].', (1, 4096),
                      read_only=True),
        ParameterSpec(f'{name}.height', _CAMERA.height, 'Image height [pixels].', (1, 4096),
                      read_only=True),
        ParameterSpec(f'{name}.horizontal_fov', _CAMERA.horizontal_fov, 'Horizontal field '
                      'of view [rad]; gives fx when fx is 0.', (0.01, 3.1), read_only=True),
        ParameterSpec(f'{name}.fx', 0.0, 'Focal length along x [pixels]; 0: from '
                      'horizontal_fov.', (0.0, 1.0e6), read_only=True),
        ParameterSpec(f'{name}.fy', 0.0, 'Focal length along y [pixels]; 0: fx (square '
                      'pixels).', (0.0, 1.0e6), read_only=True),
        ParameterSpec(f'{name}.cx', 0.0, 'Principal point x [pixels]; 0: the image centre, '
                      '(width - 1) / 2.', (0.0, 1.0e5), read_only=True),
        ParameterSpec(f'{name}.cy', 0.0, 'Principal point y [pixels]; 0: the image centre, '
                      '(height - 1) / 2.', (0.0, 1.0e5), read_only=True),
        ParameterSpec(f'{name}.position', list(DEFAULT_POSITION), 'Optical centre in frame_id: '
                      'x y z [m] (default: above the table, oblique).', read_only=True),
        ParameterSpec(f'{name}.target', list(DEFAULT_TARGET), 'Point the optical axis goes '
                      'through, in frame_id: x y z [m]; image up is towards +z (+y looking '
                      'straight down).', read_only=True),
    )


def parameter_table(cameras=(DEFAULT_CAMERA_NAME,)) -> tuple[ParameterSpec, ...]:
    """Every parameter of a node whose ``cameras`` parameter lists ``cameras``. ValueError
    for a camera name that cannot name topics and frames or that would shadow another
    parameter."""
    names = [str(name) for name in cameras]
    if len(set(names)) != len(names):
        raise ValueError(f'cameras: names must be distinct, got {names}')
    taken = {spec.name.split('.')[0] for spec in GLOBAL_PARAMETERS}
    for name in names:
        if not (name[:1].isalpha() and name.replace('_', '').isalnum()):
            raise ValueError(f'cameras: a name must be a letter then letters, digits or _, '
                             f'got {name!r}')
        if name in taken:
            raise ValueError(f'cameras: {name!r} is taken by the parameters {name}.*')
    return GLOBAL_PARAMETERS + sum((camera_parameters(name) for name in names), ())


PARAMETERS = parameter_table()
"""The table of a node with the default camera list."""
PARAMETER_SPECS = {spec.name: spec for spec in PARAMETERS}


def declared_defaults(material: str = '', cameras=(DEFAULT_CAMERA_NAME,)) -> dict[str, Any]:
    """The default every parameter is declared with when the node starts with ``material``
    and ``cameras``: the preset's value for each ``sheet.*`` and ``damage.*`` parameter it
    names (as the type of the parameter), the table's for the others. ``ValueError`` for an
    unknown material or a bad camera name."""
    defaults = {spec.name: spec.default for spec in parameter_table(cameras)}
    defaults['material'] = material
    defaults['cameras'] = list(cameras)
    if material:
        for section, values in material_preset(material).items():
            for field, value in values.items():
                name = f'{section}.{field}'
                defaults[name] = type(PARAMETER_SPECS[name].default)(value)
    return defaults


def _section(values: Mapping[str, Any], prefix: str) -> dict:
    return {name[len(prefix):]: value for name, value in values.items()
            if name.startswith(prefix)}


def _rate(values: Mapping[str, Any], name: str) -> float:
    rate = float(values[name])
    if not (math.isfinite(rate) and rate >= 0):
        raise ValueError(f'{name} must be finite and >= 0, got {rate}')
    return rate


def camera_from_values(values: Mapping[str, Any], name: str) -> ScenarioCamera:
    """The ``name.*`` parameters as a camera; ValueError names what is wrong."""
    def intrinsic(field: str) -> float | None:
        value = float(values[f'{name}.{field}'])
        return value if value != 0.0 else None  # 0: derived (see camera_parameters)

    rate = _rate(values, f'{name}.rate')
    noise = float(values[f'{name}.depth_noise_stddev'])
    if not (math.isfinite(noise) and noise >= 0):
        raise ValueError(f'{name}.depth_noise_stddev: depth noise must be finite and >= 0 m, '
                         f'got {noise}')
    try:
        config = camera_looking_at(name, tuple(values[f'{name}.position']),
                                   tuple(values[f'{name}.target']),
                                   int(values[f'{name}.width']), int(values[f'{name}.height']),
                                   float(values[f'{name}.horizontal_fov']),
                                   fx=intrinsic('fx'), fy=intrinsic('fy'),
                                   cx=intrinsic('cx'), cy=intrinsic('cy'))
    except ValueError as error:
        raise ValueError(f'{name}.*: {error}') from None
    return ScenarioCamera(config, rate, noise)


def settings_from_values(values: Mapping[str, Any]) -> NodeSettings:
    """Validate a complete set of parameter values; ValueError names what is wrong."""
    camera_names = tuple(str(name) for name in values.get('cameras', ()))
    missing = [spec.name for spec in parameter_table(camera_names) if spec.name not in values]
    if missing:
        raise ValueError(f'missing parameters: {", ".join(missing)}')
    frame_id = str(values['frame_id']).strip()
    if not frame_id:
        raise ValueError('frame_id must not be empty')
    physics_rate = float(values['physics_rate'])
    if not (math.isfinite(physics_rate) and physics_rate > 0):
        raise ValueError(f'physics_rate must be > 0, got {physics_rate}')
    solver = _section(values, 'solver.')
    solver['dt'] = 1.0 / physics_rate
    simulation = SimulationConfig(
        sheet=from_mapping(SheetConfig, _section(values, 'sheet.')),
        solver=from_mapping(SolverConfig, solver),
        contact=from_mapping(ContactConfig, _section(values, 'contact.')),
        seed=int(values['seed']),
        damage=from_mapping(DamageConfig, _section(values, 'damage.')),
    )
    material = str(values['material'])
    if material:
        material_preset(material)  # ValueError naming the known ones
    appearance = from_mapping(AppearanceConfig, _section(values, 'appearance.'))
    pin_mode = str(values['pin_mode'])
    if pin_mode not in PIN_MODES:
        raise ValueError(f'pin_mode must be one of {", ".join(PIN_MODES)}, got {pin_mode!r}')
    topics = tuple(str(topic) for topic in values['probe_topics'])
    if any(not topic.strip() for topic in topics) or len(set(topics)) != len(topics):
        raise ValueError(f'probe_topics must be distinct, non-empty names, got {list(topics)}')
    radii = tuple(float(radius) for radius in values['probe_radii'])
    if len(radii) == 1 and len(topics) > 1:
        radii = radii * len(topics)
    if topics and len(radii) != len(topics):
        raise ValueError(f'probe_radii needs one radius per probe topic ({len(topics)}) or one '
                         f'for all, got {len(radii)}')
    if any(not (math.isfinite(radius) and 0 < radius <= 10.0) for radius in radii):
        raise ValueError(f'probe radii must be in (0, 10] m, got {list(radii)}')
    return NodeSettings(
        simulation=simulation,
        frame_id=frame_id,
        physics_rate=physics_rate,
        publish_rate=_rate(values, 'publish_rate'),
        markers_rate=_rate(values, 'markers_rate'),
        diagnostics_rate=_rate(values, 'diagnostics_rate'),
        max_catchup_frames=int(values['max_catchup_frames']),
        strain_warning=float(values['strain_warning']),
        publish_clock=bool(values['publish_clock']),
        max_real_time_factor=_rate(values, 'max_real_time_factor'),
        material=material,
        appearance=appearance,
        pin_mode=pin_mode,
        probe_topics=topics,
        probe_radii=radii[:len(topics)],
        probe_timeout=float(values['probe_timeout']),
        crumple_count=int(values['crumple_count']),
        crumple_seed=int(values['crumple_seed']),
        dense_samples=int(values['points.dense_samples']),
        noise_stddev=float(values['points.noise_stddev']),
        noise_seed=int(values['points.noise_seed']),
        hinge_springs=bool(values['markers.hinge_springs']),
        aux_springs=bool(values['markers.aux_springs']),
        bend_springs=bool(values['markers.bend_springs']),
        rerun_path=str(values['rerun_path']),
        rerun_connect=str(values['rerun_connect']),
        cameras=tuple(camera_from_values(values, name) for name in camera_names),
        bag_path=str(values['bag_path']),
    )
