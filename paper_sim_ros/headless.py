"""Run a scenario without ROS: batch runs, benchmarks, regression tests.

    python -m paper_sim_ros.headless --scenario hanging --grid 65 --duration 10 \\
        --metrics-json out/hanging.json --rrd out/hanging.rrd

Exit status 0 on success, 2 with a one-line reason on bad input.
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import time
from typing import Callable

import yaml

from .core import kernels
from .core.damage import damage_metrics
from .core.scenarios import (BUILTIN_SCENARIOS, Scenario, builtin_mapping,
                             scenario_from_mapping, with_overrides)
from .core.simulator import Simulator
from .warmup import warm_up


def build_simulator(scenario: Scenario) -> Simulator:
    simulator = Simulator(scenario.config, initial_sheet=scenario.initial_sheet())
    simulator.set_pinned(scenario.pinned_mask(simulator.sheet))
    if scenario.crumple and scenario.config.damage.enabled:
        simulator.crumple(scenario.crumple, scenario.config.seed)
    return simulator


def run_scenario(scenario: Scenario,
                 on_frame: Callable[[Simulator, float], None] | None = None,
                 simulator: Simulator | None = None) -> dict:
    """Step ``scenario`` to its end; ``on_frame(simulator, step_seconds)`` after each frame.
    Returns the metrics of the run (see README)."""
    simulator = simulator if simulator is not None else build_simulator(scenario)
    sheet = simulator.sheet
    dt = scenario.config.solver.dt
    max_strain = 0.0
    max_penetration = 0.0
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
        'max_strain': max_strain,
        'max_probe_penetration_m': max_penetration,
        'nan': bool(nan_seen),
        'total_mass': sheet.total_mass,
        'final_positions_sha256': sheet.positions_sha256(),
        **damage_metrics(simulator),
    }


def load_scenario_mapping(name_or_path: str) -> dict:
    """A built-in scenario by name, or a scenario YAML file."""
    if name_or_path in BUILTIN_SCENARIOS:
        return builtin_mapping(name_or_path)
    if not os.path.isfile(name_or_path):
        raise ValueError(f'unknown scenario {name_or_path!r} (not a built-in: '
                         f'{", ".join(BUILTIN_SCENARIOS)}; not a file)')
    with open(name_or_path, encoding='utf-8') as stream:
        try:
            mapping = yaml.safe_load(stream)
        except yaml.YAMLError as error:
            raise ValueError(f'{name_or_path}: malformed YAML: {error}'.splitlines()[0]) from None
    if not isinstance(mapping, dict):
        raise ValueError(f'{name_or_path}: a scenario file must hold a mapping')
    mapping.setdefault('name', os.path.splitext(os.path.basename(name_or_path))[0])
    return mapping


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog='paper_sim_headless', description=__doc__.split('\n')[0])
    parser.add_argument('--scenario', default='hanging',
                        help=f'built-in ({", ".join(BUILTIN_SCENARIOS)}) or a YAML file')
    parser.add_argument('--grid', type=int, help='vertices per side (default 65)')
    parser.add_argument('--duration', type=float, help='simulated seconds')
    parser.add_argument('--dt', type=float, help='frame step [s] (default 1/60)')
    parser.add_argument('--substeps', type=int, help='integration sub-steps per frame')
    parser.add_argument('--seed', type=int, help='random seed')
    parser.add_argument('--solver', choices=('constrained', 'paper', 'explicit'),
                        help='time stepping method (default constrained)')
    parser.add_argument('--no-damage', action='store_true',
                        help='switch breaks and folds off (the sheet behaves like rubber)')
    parser.add_argument('--metrics-json', help='write the metrics to this JSON file')
    parser.add_argument('--rrd', help='record the run to this Rerun .rrd file')
    parser.add_argument('--replay', metavar='FILE.rrd',
                        help='re-run a recorded session: its scenario, parameters and seed, '
                             'driven by its recorded probe inputs')
    return parser.parse_args(argv)


def _recording_callback(recorder, dt: float) -> Callable[[Simulator, float], None]:
    def log(simulator: Simulator, step_seconds: float) -> None:
        recorder.log_frame(simulator.time, simulator, scalars={
            'step_time': step_seconds,
            'real_time_factor': dt / step_seconds if step_seconds > 0 else 0.0,
            'energy': simulator.energy(),
            'max_strain': simulator.max_strain(),
        })
    return log


def _raise_keyboard_interrupt(signum, frame) -> None:
    raise KeyboardInterrupt


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    if args.replay:
        from .rerun_replay import replay_command
        return replay_command(args)
    recorder = None
    # from here on SIGTERM unwinds like Ctrl-C, so a recording is always closed
    signal.signal(signal.SIGTERM, _raise_keyboard_interrupt)
    try:
        mapping = with_overrides(load_scenario_mapping(args.scenario), grid=args.grid,
                                 duration=args.duration, dt=args.dt, substeps=args.substeps,
                                 seed=args.seed, method=args.solver)
        if args.no_damage:
            mapping['damage'] = {**(mapping.get('damage') or {}), 'enabled': False}
        scenario = scenario_from_mapping(mapping)
        simulator = build_simulator(scenario)
        check_metrics_path(args.metrics_json)
        on_frame = None
        if args.rrd:
            from .rerun_logger import RerunRecorder
            recorder = RerunRecorder('paper_sim_headless', path=args.rrd,
                                     recording_info={'scenario': scenario.mapping})
            on_frame = _recording_callback(recorder, scenario.config.solver.dt)
    except (ValueError, OSError) as error:
        print(f'paper_sim_headless: error: {error}', file=sys.stderr)
        if recorder is not None:
            recorder.close()
        return 2
    except KeyboardInterrupt:
        print('paper_sim_headless: interrupted', file=sys.stderr)
        if recorder is not None:
            recorder.close()
        return 130
    try:
        warm_up()
        metrics = run_scenario(scenario, on_frame=on_frame, simulator=simulator)
    except KeyboardInterrupt:
        print('paper_sim_headless: interrupted', file=sys.stderr)
        return 130
    finally:
        if recorder is not None:
            recorder.close()
    emit_metrics(metrics, args.metrics_json)
    return 0


def check_metrics_path(path: str | None) -> None:
    """Refuse, before running, a metrics file that could not be written."""
    if path and not os.access(os.path.dirname(os.path.abspath(path)), os.W_OK):
        raise ValueError(f'cannot write metrics to {path}')


def emit_metrics(metrics: dict, path: str | None) -> None:
    """Print the metrics as JSON, and write them to ``path`` if given."""
    text = json.dumps(metrics, indent=2)
    if path:
        with open(path, 'w', encoding='utf-8') as stream:
            stream.write(text + '\n')
    print(text)


if __name__ == '__main__':
    sys.exit(main())
