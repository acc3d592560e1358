"""Run a scenario to its end without ROS: load it, build its simulator, step it, measure.

    scenario = load_scenario('press', grid=33, duration=1.0)
    metrics = run_scenario(scenario)          # the headless runner's metrics (README)

The headless command line (``paper_sim_ros.headless``), the replay of a recording and the
benchmarks all run scenarios through here.
"""
from __future__ import annotations

from collections.abc import Mapping
import copy
import json
import os
import time
from typing import Any, Callable

import numpy as np
import yaml

from . import kernels
from .metrics import damage_metrics
from .scenarios import (BUILTIN_SCENARIOS, Scenario, builtin_mapping, scenario_from_mapping,
                        with_overrides)
from .simulator import Simulator


def load_scenario(source: str | os.PathLike | Mapping[str, Any], *, grid: int | None = None,
                  duration: float | None = None, dt: float | None = None,
                  substeps: int | None = None, seed: int | None = None,
                  method: str | None = None, damage_enabled: bool | None = None,
                  material: str | None = None) -> Scenario:
    """A validated scenario from a built-in name (``BUILTIN_SCENARIOS``), a scenario YAML
    file, or a mapping of the same shape; the keyword overrides (None: the scenario's own)
    are those of ``core.scenarios.with_overrides``. Raises ``ValueError`` naming what is
    wrong (unknown name, missing file, malformed YAML, unknown key, value out of range)."""
    if isinstance(source, Mapping):
        mapping = copy.deepcopy(dict(source))
    else:
        mapping = scenario_file_mapping(os.fspath(source))
    mapping = with_overrides(mapping, grid=grid, duration=duration, dt=dt, substeps=substeps,
                             seed=seed, method=method, damage_enabled=damage_enabled,
                             material=material)
    return scenario_from_mapping(mapping)


def scenario_file_mapping(name_or_path: str, folder: str = '') -> dict:
    """The mapping of a built-in scenario by name, or of a scenario YAML file (relative to
    ``folder``), named after the file unless it says otherwise. Raises ``ValueError``
    (neither, malformed YAML, not a mapping)."""
    if name_or_path in BUILTIN_SCENARIOS:
        return builtin_mapping(name_or_path)
    path = os.path.join(folder, name_or_path)
    if not os.path.isfile(path):
        raise ValueError(f'scenario {name_or_path!r} is neither a built-in '
                         f'({", ".join(BUILTIN_SCENARIOS)}) nor a file (looked for {path})')
    with open(path, encoding='utf-8') as stream:
        try:
            mapping = yaml.safe_load(stream)
        except yaml.YAMLError as error:
            raise ValueError(f'{name_or_path}: malformed YAML: {error}'.splitlines()[0]) from None
    if not isinstance(mapping, dict):
        raise ValueError(f'{name_or_path}: a scenario file must hold a mapping')
    mapping.setdefault('name', os.path.splitext(os.path.basename(name_or_path))[0])
    return mapping


def build_simulator(scenario: Scenario) -> Simulator:
    """The scenario's simulator at time zero: its initial sheet, pins and crumple."""
    simulator = Simulator(scenario.config, initial_sheet=scenario.initial_sheet())
    simulator.set_pinned(scenario.pinned_mask(simulator.sheet))
    if scenario.crumple and scenario.config.damage.enabled:
        simulator.crumple(scenario.crumple, scenario.config.seed)
    return simulator


def run_scenario(scenario: Scenario,
                 on_frame: Callable[[Simulator, float], None] | None = None,
                 simulator: Simulator | None = None) -> dict:
    """Step ``scenario`` to its end; ``on_frame(simulator, step_seconds)`` after each frame.
    ``simulator``: one ``build_simulator`` made (default: a new one). Returns the metrics
    of the run (README, "The headless runner")."""
    simulator = simulator if simulator is not None else build_simulator(scenario)
    sheet = simulator.sheet
    dt = scenario.config.solver.dt
    max_strain = 0.0
    max_penetration = 0.0
    max_table_penetration = 0.0
    nan_seen = False
    stepping_seconds = 0.0
    for frame in range(scenario.frame_count):
        simulator.set_probes(*scenario.probe_inputs((frame + 1) * dt))
        started = time.perf_counter()
        simulator.step_frame()
        step_seconds = time.perf_counter() - started
        stepping_seconds += step_seconds
        sheet = simulator.sheet
        max_strain = max(max_strain, simulator.max_strain())
        max_penetration = max(max_penetration, simulator.max_probe_penetration())
        max_table_penetration = max(max_table_penetration,
                                    simulator.max_table_penetration())
        nan_seen = nan_seen or simulator.nan_seen or not kernels.all_finite(sheet.positions)
        if on_frame is not None:
            on_frame(simulator, step_seconds)
    sim_seconds = scenario.frame_count * dt
    return {
        'scenario': scenario.name,
        'solver': scenario.config.solver.method,
        'grid': [scenario.config.sheet.nx, scenario.config.sheet.ny],
        'vertices': sheet.vertex_count,
        'springs': sheet.spring_count,
        'steps': scenario.frame_count,
        'substeps': scenario.config.solver.substeps,
        'sim_s': sim_seconds,
        'wall_s': stepping_seconds,
        'realtime_factor': sim_seconds / stepping_seconds if stepping_seconds > 0 else 0.0,
        'frames_asleep': simulator.frames_asleep,
        'max_strain': max_strain,
        'max_probe_penetration_m': max_penetration,
        'max_table_penetration_m': max_table_penetration,
        'nan': bool(nan_seen),
        **final_motion(sheet.velocities, sheet.vertex_mass),
        'total_mass': sheet.total_mass,
        'final_positions_sha256': sheet.positions_sha256(),
        **damage_metrics(simulator),
    }


def final_motion(velocities: np.ndarray, vertex_mass: np.ndarray) -> dict:
    """How still the sheet is at the end of a run: its fastest and 99th-percentile vertex
    speed [m/s] and its kinetic energy [J] (a "static" sheet handed to a perception test
    should not be drifting)."""
    speed = np.linalg.norm(velocities, axis=1)
    return {
        'final_max_speed_mps': float(speed.max(initial=0.0)),
        'final_p99_speed_mps': float(np.percentile(speed, 99)) if speed.size else 0.0,
        'final_kinetic_energy_j': float(0.5 * np.sum(vertex_mass * speed * speed)),
    }


def check_metrics_path(path: str | None) -> None:
    """Refuse, before running, a metrics file that could not be written (``ValueError``)."""
    if path and not os.access(os.path.dirname(os.path.abspath(path)), os.W_OK):
        raise ValueError(f'cannot write metrics to {path}')


def write_metrics(metrics: dict, path: str) -> None:
    """Write ``metrics`` to ``path`` as indented JSON."""
    with open(path, 'w', encoding='utf-8') as stream:
        stream.write(json.dumps(metrics, indent=2) + '\n')
