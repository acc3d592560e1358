"""Scenarios as data: a sheet, a solver, contact, pins and probe tracks over time.

A scenario is a plain mapping (the same shape as a scenario YAML file), so built-in
scenarios, user files and recorded sessions all go through one loader
(``core.runner.load_scenario``):

    name: press
    description: a fingertip presses the centre of a sheet lying on a table
    duration: 3.0            # s
    seed: 0
    pin: none                # none | short_edge (see pin_mask)
    material: cardboard      # optional: printer_paper | cardboard | banknote (core/materials.py)
    sheet: {nx: 65, ny: 65}  # any SheetConfig field (these win over the material's)
    solver: {dt: 0.0166667}  # any SolverConfig field
    contact: {ground_enabled: true}   # any ContactConfig field
    damage: {fragility: 1.0} # any DamageConfig field (these win over the material's)
    appearance: {normal_level: 2}     # any AppearanceConfig field
    crumple: 0               # random damage events before the first frame
    aged: {amplitude: 0.01}  # optional: start from the fractal aged sheet (SPEC §5)
    probes:
      - name: finger
        radius: 0.01         # m
        keyframes: [[0.0, 0.0, 0.0, 0.05], [1.0, 0.0, 0.0, 0.011]]   # [t, x, y, z]
    cameras:                 # optional (absent: one default camera; []: none)
      - name: top            # topics paper/top/..., frame top_optical_frame
        position: [0.0, 0.0, 0.5]    # m
        target: [0.0, 0.0, 0.0]      # the optical axis goes through it
        width: 640           # pixels (also height, horizontal_fov [rad])
        rate: 15.0           # Hz of simulated time
        depth_noise_stddev: 0.0      # m, seeded by the scenario's seed

Pin modes (``PIN_MODES``, ``pin_mask``): ``none`` pins nothing; ``short_edge`` clamps the
edge at y = −height/2 (the lowest material y of the sheet: a short edge of the portrait A4
sheet, width along x, height along y). The node uses the same definition.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass, field
import math
from typing import Any

import numpy as np

from .appearance import AppearanceConfig
from .camera import CameraConfig, camera_looking_at
from .config import (ContactConfig, DamageConfig, SheetConfig, SimulationConfig, SolverConfig,
                     from_mapping)
from .fractal import build_aged_sheet
from .materials import material_preset
from .sheet import Sheet, build_flat_sheet

PIN_MODES = ('none', 'short_edge')
"""What a scenario (and the node) can pin: see ``pin_mask``."""

SCENARIO_KEYS = ('name', 'description', 'duration', 'seed', 'pin', 'material', 'cameras',
                 'sheet',
                 'solver', 'contact', 'damage', 'appearance', 'crumple', 'aged', 'probes')
"""The keys a scenario mapping may have."""

BUILTIN_SCENARIOS: dict[str, dict[str, Any]] = {
    'hanging': {
        'description': 'A4 sheet pinned along one short edge, released flat and horizontal, '
                       'swings down under gravity (a cantilever: bending and stretch).',
        'duration': 10.0,
        'pin': 'short_edge',
        'sheet': {'elevation': 0.5},
        'contact': {'ground_enabled': False},
    },
    'press': {
        'description': 'A4 sheet flat on a table; a 1 cm probe descends on its centre, '
                       'presses it 1 mm into the table surface, and lifts off.',
        'duration': 3.0,
        'contact': {'ground_enabled': True},
        'probes': [{
            'name': 'finger',
            'radius': 0.01,
            'keyframes': [[0.0, 0.0, 0.0, 0.05], [1.0, 0.0, 0.0, 0.009],
                          [1.5, 0.0, 0.0, 0.009], [2.5, 0.0, 0.0, 0.05]],
        }],
    },
    # two fingertips rest on the sheet 1 cm in from its short edges, pressed 3 mm into the
    # table, and slide towards each other by 30 % of the length (2 × 44.55 mm)
    # in 2 s, then lift off
    'squeeze': {
        'description': 'A4 sheet flat on a table; two 1.5 cm probes rest on it near its short '
                       'edges, slide towards each other by 30 % of its length in 2 s (the '
                       'sheet buckles between them), then lift off.',
        'duration': 4.0,
        'contact': {'ground_enabled': True},
        'probes': [{
            'name': f'finger_{side}',
            'radius': 0.015,
            'keyframes': [[0.0, 0.0, sign * 0.1385, 0.05], [0.5, 0.0, sign * 0.1385, 0.012],
                          [2.5, 0.0, sign * 0.09395, 0.012], [3.0, 0.0, sign * 0.09395, 0.05]],
        } for side, sign in (('low', -1.0), ('high', 1.0))],
    },
    'aged': {
        'description': 'An aged sheet (the fractal surface of paper §3.4, 10 mm at the top '
                       'level) settling on a table: its waviness is its own rest shape.',
        'duration': 3.0,
        'aged': {'amplitude': 0.01, 'levels': None},
        'sheet': {'elevation': 0.005},
        'contact': {'ground_enabled': True},
    },
    # a fingertip rests on the table 15 mm beside the sheet's short edge, pressed 1 mm into
    # the table, slides into the sheet and pushes it 10 cm along the table
    'slide': {
        'description': 'A4 sheet flat on a table; a 1 cm fingertip rests on the table beside '
                       'its short edge, pressed 1 mm in, slides into the sheet and pushes it '
                       '10 cm, then lifts off.',
        'duration': 3.5,
        'contact': {'ground_enabled': True},
        'probes': [{
            'name': 'finger',
            'radius': 0.01,
            'keyframes': [[0.0, 0.0, -0.1635, 0.05], [0.5, 0.0, -0.1635, 0.009],
                          [2.5, 0.0, -0.0485, 0.009], [3.0, 0.0, -0.0485, 0.05]],
        }],
    },
    # a fingertip presses the sheet's middle 1 mm into the table and drags it
    # 10 cm across the table (it grips better than the table: 0.6 against 0.4)
    'drag': {
        'description': 'A4 sheet flat on a table; a 1 cm fingertip presses its middle 1 mm '
                       'into the table, drags it 10 cm across the table, and lifts off.',
        'duration': 3.0,
        'contact': {'ground_enabled': True},
        'probes': [{
            'name': 'finger',
            'radius': 0.01,
            'keyframes': [[0.0, 0.0, 0.0, 0.05], [0.5, 0.0, 0.0, 0.009],
                          [2.0, 0.1, 0.0, 0.009], [2.5, 0.1, 0.0, 0.05]],
        }],
    },
    # the sheet of 'hanging', damped so that it hangs still by 2.5 s (in the plane
    # y = -0.1485, its free edge ~0.3 m below the pins); then a 1.5 cm probe pushes 1.5 cm
    # past that plane from +y, halfway down, sweeps across it and withdraws
    'poke': {
        'description': 'A4 sheet pinned along one short edge hangs down; a 1.5 cm probe '
                       'pushes into it halfway down, sweeps across it and withdraws.',
        'duration': 5.0,
        'pin': 'short_edge',
        'sheet': {'elevation': 0.5},
        'contact': {'ground_enabled': False},
        'probes': [{
            'name': 'probe',
            'radius': 0.015,
            'keyframes': [[2.5, -0.09, -0.1035, 0.35], [3.0, -0.09, -0.1785, 0.35],
                          [4.0, 0.09, -0.1785, 0.35], [4.5, 0.09, -0.1035, 0.35]],
        }],
    },
    'crumple': {
        'description': 'Random damage (breaks and folds, paper Fig. 8) on a flat sheet, '
                       'then free relaxation without gravity.',
        'duration': 3.0,
        'crumple': 300,
        'solver': {'gravity': [0.0, 0.0, 0.0], 'air_damping': 3.0},
    },
}


def pin_mask(sheet: Sheet, mode: str) -> np.ndarray:
    """(V,) bool: the vertices ``mode`` pins. ``none``: none; ``short_edge``: the edge at
    y = −height/2, the vertices at the lowest material y (material coordinates, so a vertex
    that damage inserts on that edge is clamped too)."""
    if mode not in PIN_MODES:
        raise ValueError(f'pin mode must be one of {", ".join(PIN_MODES)}, got {mode!r}')
    if mode == 'short_edge':
        edge = sheet.material[:, 1].min()
        return np.isclose(sheet.material[:, 1], edge, rtol=0.0, atol=1e-9)
    return np.zeros(sheet.vertex_count, dtype=bool)


@dataclass(frozen=True)
class ProbeTrack:
    """A sphere probe moving through keyframes; active from its first to its last one."""

    name: str
    radius: float
    keyframes: np.ndarray
    """(K, 4) float64: t [s], x, y, z [m], times strictly increasing."""

    def center_at(self, time: float) -> tuple[np.ndarray, bool]:
        """Linearly interpolated centre at ``time`` and whether the probe is active."""
        times = self.keyframes[:, 0]
        active = bool(times[0] <= time <= times[-1])
        center = np.array([np.interp(time, times, self.keyframes[:, k]) for k in (1, 2, 3)])
        return center, active


@dataclass(frozen=True)
class ScenarioCamera:
    """A virtual camera of a scenario (what a headless bag holds; core/camera.py)."""

    config: CameraConfig
    rate: float = 15.0
    """Frames per second of simulated time [Hz]."""
    depth_noise_stddev: float = 0.0
    """Gaussian noise on its depth [m]."""


DEFAULT_CAMERAS = (ScenarioCamera(camera_looking_at()),)
"""A scenario without a ``cameras`` section has this one: above the table, oblique,
640 × 480 at 15 Hz."""


@dataclass(frozen=True)
class Scenario:
    """A validated scenario: what ``core.runner.build_simulator`` and ``run_scenario`` run."""

    name: str
    description: str
    duration: float
    pin: str
    config: SimulationConfig
    probes: tuple[ProbeTrack, ...]
    mapping: dict
    """The mapping this scenario was built from (recorded so a session can be re-run)."""
    crumple: int = 0
    """Random damage events (SPEC §4.3) applied to the sheet before the first frame."""
    aged_amplitude: float = 0.0
    """Top-level displacement d_max [m] of the aged (fractal) initial sheet; 0: flat."""
    aged_levels: int | None = None
    """Fractal iterations of the aged sheet (None: all, down to single vertices)."""
    material: str | None = None
    """The material preset applied (core/materials.py), or None."""
    appearance: AppearanceConfig = field(default_factory=AppearanceConfig)
    """How the sheet looks (texture, shading); no effect on the physics."""
    cameras: tuple[ScenarioCamera, ...] = DEFAULT_CAMERAS
    """Its virtual cameras; no effect on the physics."""

    def initial_sheet(self) -> Sheet:
        """The sheet the scenario starts from: flat, or aged (SPEC §5)."""
        if self.aged_amplitude > 0:
            return build_aged_sheet(self.config.sheet, self.aged_amplitude, self.aged_levels,
                                    self.config.seed)
        return build_flat_sheet(self.config.sheet)

    @property
    def frame_count(self) -> int:
        return int(round(self.duration / self.config.solver.dt))

    def pinned_mask(self, sheet: Sheet) -> np.ndarray:
        """(V,) bool: the vertices of ``sheet`` this scenario pins (``pin_mask``)."""
        return pin_mask(sheet, self.pin)

    def probe_inputs(self, time: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Centres (P,3), radii (P,) and active flags (P,) of every probe at ``time``."""
        centers = np.zeros((len(self.probes), 3))
        active = np.zeros(len(self.probes), dtype=bool)
        for index, probe in enumerate(self.probes):
            centers[index], active[index] = probe.center_at(time)
        radii = np.array([probe.radius for probe in self.probes], dtype=np.float64)
        return centers, radii, active


def _probe_from_mapping(values: dict) -> ProbeTrack:
    unknown = sorted(set(values) - {'name', 'radius', 'keyframes'})
    if unknown:
        raise ValueError(f'unknown probe keys: {", ".join(unknown)}')
    name = str(values.get('name', 'probe'))
    radius = float(values['radius'])
    if not (math.isfinite(radius) and 0 < radius <= 1.0):
        raise ValueError(f'probe {name}: radius must be in (0, 1] m, got {radius}')
    keyframes = np.asarray(values['keyframes'], dtype=np.float64)
    if keyframes.ndim != 2 or keyframes.shape[1] != 4 or len(keyframes) < 1:
        raise ValueError(f'probe {name}: keyframes must be a list of [t, x, y, z]')
    if not np.all(np.isfinite(keyframes)):
        raise ValueError(f'probe {name}: keyframes must be finite')
    if np.any(np.diff(keyframes[:, 0]) <= 0):
        raise ValueError(f'probe {name}: keyframe times must increase')
    return ProbeTrack(name=name, radius=radius, keyframes=keyframes)


CAMERA_KEYS = ('name', 'position', 'target', 'width', 'height', 'horizontal_fov', 'fx', 'fy',
               'cx', 'cy', 'rate', 'depth_noise_stddev')


def _camera_from_mapping(values: dict) -> ScenarioCamera:
    if not isinstance(values, dict):
        raise ValueError(f'a camera must be a mapping, got {values!r}')
    unknown = sorted(set(values) - set(CAMERA_KEYS))
    if unknown:
        raise ValueError(f'unknown camera keys: {", ".join(unknown)}; known: '
                         f'{", ".join(CAMERA_KEYS)}')
    default = DEFAULT_CAMERAS[0]
    name = values.get('name', default.config.name)
    config = camera_looking_at(
        name, values.get('position', default.config.position),
        values.get('target', (0.0, 0.0, 0.0)), values.get('width', default.config.width),
        values.get('height', default.config.height),
        values.get('horizontal_fov', default.config.horizontal_fov),
        **{key: values[key] for key in ('fx', 'fy', 'cx', 'cy') if key in values})
    rate = float(values.get('rate', default.rate))
    noise = float(values.get('depth_noise_stddev', 0.0))
    if not (math.isfinite(rate) and 0 < rate <= 1000):
        raise ValueError(f'camera {name}: rate must be in (0, 1000] Hz, got {rate}')
    if not (math.isfinite(noise) and 0 <= noise <= 0.1):
        raise ValueError(f'camera {name}: depth_noise_stddev must be in [0, 0.1] m, '
                         f'got {noise}')
    return ScenarioCamera(config, rate, noise)


def _cameras_from_mapping(mapping: dict) -> tuple[ScenarioCamera, ...]:
    if 'cameras' not in mapping:
        return DEFAULT_CAMERAS
    items = mapping['cameras'] or []
    if not isinstance(items, list):
        raise ValueError(f'cameras must be a list, got {items!r}')
    cameras = tuple(_camera_from_mapping(item) for item in items)
    names = [camera.config.name for camera in cameras]
    if len(set(names)) != len(names):
        raise ValueError(f'camera names must be distinct, got {names}')
    return cameras


def _section(mapping: dict, key: str) -> dict:
    """The mapping under ``key`` ({} when absent or empty)."""
    value = mapping.get(key) or {}
    if not isinstance(value, dict):
        raise ValueError(f'{key} must be a mapping, got {value!r}')
    return value


def scenario_from_mapping(mapping: dict, name: str = 'custom') -> Scenario:
    """Build and validate a scenario; raises ValueError naming what is wrong."""
    if not isinstance(mapping, dict):
        raise ValueError('a scenario must be a mapping')
    unknown = sorted(set(mapping) - set(SCENARIO_KEYS))
    if unknown:
        raise ValueError(f'unknown scenario keys: {", ".join(unknown)}; '
                         f'known: {", ".join(SCENARIO_KEYS)}')
    duration = float(mapping.get('duration', 5.0))
    if not (math.isfinite(duration) and 0 < duration <= 3600):
        raise ValueError(f'duration must be in (0, 3600] s, got {duration}')
    pin = mapping.get('pin', 'none')
    if pin not in PIN_MODES:
        raise ValueError(f'pin must be one of {PIN_MODES}, got {pin!r}')
    material = mapping.get('material')
    if material is not None and not isinstance(material, str):
        raise ValueError(f'material must be a name, got {material!r}')
    # the material's sheet and damage values, each overridden by the scenario's own
    preset = material_preset(material) if material is not None else {}
    config = SimulationConfig(
        sheet=from_mapping(SheetConfig, {**preset.get('sheet', {}), **_section(mapping, 'sheet')}),
        solver=from_mapping(SolverConfig, _section(mapping, 'solver')),
        contact=from_mapping(ContactConfig, _section(mapping, 'contact')),
        seed=int(mapping.get('seed', 0)),
        damage=from_mapping(DamageConfig,
                            {**preset.get('damage', {}), **_section(mapping, 'damage')}),
    )
    appearance = from_mapping(AppearanceConfig, _section(mapping, 'appearance'))
    crumple = mapping.get('crumple', 0)
    if not (isinstance(crumple, int) and 0 <= crumple <= 1_000_000):
        raise ValueError(f'crumple must be an integer in [0, 1000000], got {crumple!r}')
    aged = dict(_section(mapping, 'aged'))
    unknown = sorted(set(aged) - {'amplitude', 'levels'})
    if unknown:
        raise ValueError(f'unknown aged keys: {", ".join(unknown)}')
    amplitude = float(aged.get('amplitude', 0.0))
    if not (math.isfinite(amplitude) and 0 <= amplitude <= 0.1):
        raise ValueError(f'aged amplitude must be in [0, 0.1] m, got {amplitude}')
    probes = tuple(_probe_from_mapping(p) for p in mapping.get('probes') or [])
    cameras = _cameras_from_mapping(mapping)
    return Scenario(name=str(mapping.get('name', name)),
                    description=str(mapping.get('description', '')),
                    duration=duration, pin=pin, config=config, probes=probes,
                    mapping=copy.deepcopy(mapping), crumple=crumple,
                    aged_amplitude=amplitude, aged_levels=aged.get('levels'),
                    material=material, appearance=appearance, cameras=cameras)


def builtin_mapping(name: str) -> dict:
    """A copy of the built-in scenario ``name``, with its name."""
    if name not in BUILTIN_SCENARIOS:
        raise ValueError(f'unknown scenario {name!r}; built-in: {", ".join(BUILTIN_SCENARIOS)}')
    mapping = copy.deepcopy(BUILTIN_SCENARIOS[name])
    mapping['name'] = name
    return mapping


def with_overrides(mapping: dict, grid: int | None = None, duration: float | None = None,
                   dt: float | None = None, substeps: int | None = None,
                   seed: int | None = None, method: str | None = None,
                   damage_enabled: bool | None = None, material: str | None = None) -> dict:
    """A copy of ``mapping`` with the command-line overrides applied (None: unchanged):
    ``grid`` vertices per side, ``duration`` [s], frame step ``dt`` [s], ``substeps``,
    ``seed``, solver ``method``, damage on or off, ``material`` preset."""
    mapping = copy.deepcopy(mapping)
    sheet = dict(_section(mapping, 'sheet'))
    solver = dict(_section(mapping, 'solver'))
    if grid is not None:
        sheet['nx'] = sheet['ny'] = grid
    if dt is not None:
        solver['dt'] = dt
    if substeps is not None:
        solver['substeps'] = substeps
    if method is not None:
        solver['method'] = method
    if duration is not None:
        mapping['duration'] = duration
    if seed is not None:
        mapping['seed'] = seed
    if damage_enabled is not None:
        mapping['damage'] = {**_section(mapping, 'damage'), 'enabled': damage_enabled}
    if material is not None:
        mapping['material'] = material
    mapping['sheet'], mapping['solver'] = sheet, solver
    return mapping
