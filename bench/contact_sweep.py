"""Contact over scenarios, grids and seeds: what issue 13 asks of every built-in scenario.

    .venv/bin/python bench/contact_sweep.py [--scenarios press drag ...] [--grids 33 65]
        [--seeds 0 1 2 3 4] [--jobs 2] [--no-damage] [--substeps 4] [--energy-restoring]
        [--length-projection] [--membrane 30 [--membrane-iterations 10]]
        [--set release_substeps=4 ...]

Per run: max HINGE strain over the run, deepest vertex inside a probe and below the table
(beyond a pressed probe's dimple), breaks, folds, relaxed deviation, mesh validity, mass
error, the share of the fingertip's travel the sheet's centroid followed (probe scenarios)
the real-time factor (single thread; timings are noisy when runs share the cores) and the
99th-percentile vertex speed at the end.
Then the worst over seeds per scenario and grid. A script, not a test.
"""
from __future__ import annotations

import argparse
import json
from concurrent.futures import ProcessPoolExecutor
import os
import sys

os.environ.setdefault('NUMBA_NUM_THREADS', '1')
os.environ.setdefault('OMP_NUM_THREADS', '1')
os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')

import numpy as np  # noqa: E402

from paper_sim_ros.core import load_scenario, run_scenario  # noqa: E402
from paper_sim_ros.core.runner import build_simulator  # noqa: E402
from paper_sim_ros.core.scenarios import (BUILTIN_SCENARIOS, builtin_mapping,  # noqa: E402
                                          with_overrides)


def measure(name: str, grid: int, seed: int, damage: bool, substeps: int | None,
            solver_options: dict | None = None) -> dict:
    """One run; ``solver_options``: solver settings overridden (e.g.
    {'energy_restoring': True})."""
    mapping = with_overrides(builtin_mapping(name), grid=grid, seed=seed,
                             damage_enabled=damage, substeps=substeps)
    mapping['solver'] = {**(mapping.get('solver') or {}),
                         **(solver_options or {})}
    scenario = load_scenario(mapping)
    simulator = build_simulator(scenario)
    mass = simulator.sheet.vertex_mass

    def centroid() -> np.ndarray:
        sheet = simulator.sheet
        return (sheet.vertex_mass[:, None] * sheet.positions).sum(0) / sheet.vertex_mass.sum()

    start = centroid()
    first = scenario.probe_inputs(scenario.config.solver.dt)
    last = scenario.probe_inputs(scenario.frame_count * scenario.config.solver.dt)
    metrics = run_scenario(scenario, simulator=simulator)
    follow = float('nan')
    if len(first[0]) and first[2].any():
        travel = (last[0] - first[0])[first[2]][0, :2]
        if np.linalg.norm(travel) > 1e-3:
            moved = (centroid() - start)[:2]
            follow = float(moved @ travel / (travel @ travel))
    metrics['follow'] = follow
    metrics['mass_error'] = abs(simulator.sheet.total_mass - float(mass.sum()))
    metrics['seed'] = seed
    return metrics


def row(metrics: dict) -> str:
    return (f"{metrics['scenario']:<9} {metrics['grid'][0]:>4}² seed {metrics['seed']}  "
            f"strain {metrics['max_strain']:8.3%}  in probe "
            f"{1e3 * metrics['max_probe_penetration_m']:6.2f} mm  below table "
            f"{1e3 * metrics['max_table_penetration_m']:6.2f} mm  breaks {metrics['breaks']:>4}"
            f"  folds {metrics['folds']:>4}  relaxed {1e3 * metrics['relaxed_deviation_m']:6.2f}"
            f" mm  follow {metrics['follow']:5.2f}  valid {metrics['mesh_valid']!s:>5}  "
            f"mass err {metrics['mass_error']:.1e}  RTF {metrics['realtime_factor']:5.2f}  "
            f"asleep {metrics['frames_asleep'] / metrics['steps']:4.0%}  final p99 speed "
            f"{1e3 * metrics['final_p99_speed_mps']:.3f} mm/s")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--scenarios', nargs='+', default=list(BUILTIN_SCENARIOS))
    parser.add_argument('--grids', type=int, nargs='+', default=[65])
    parser.add_argument('--seeds', type=int, nargs='+', default=[0, 1, 2, 3, 4])
    parser.add_argument('--jobs', type=int, default=1)
    parser.add_argument('--no-damage', action='store_true')
    parser.add_argument('--substeps', type=int, default=None,
                        help="sub-steps per frame (default: each scenario's own)")
    parser.add_argument('--energy-restoring', action='store_true',
                        help='solver.energy_restoring on (docs/solver.md)')
    parser.add_argument('--length-projection', action='store_true',
                        help='solver.length_projection on (docs/solver.md)')
    parser.add_argument('--no-sleep', action='store_true',
                        help='solver.sleep_speed 0: the sheet never sleeps (docs/solver.md)')
    parser.add_argument('--membrane', type=float, default=None,
                        help="the membrane at this weight in every sub-step (membrane_scope "
                        "'always'; 0: none; default: the solver's)")
    parser.add_argument('--membrane-iterations', type=int, default=None,
                        help='solver.membrane_iterations (default: the solver\'s)')
    parser.add_argument('--set', nargs='+', default=[], metavar='NAME=VALUE',
                        help='solver settings overridden, each NAME=VALUE (a JSON value)')
    args = parser.parse_args(argv)
    options = {option: True for option in ('energy_restoring', 'length_projection')
               if getattr(args, option)}
    if args.no_sleep:
        options['sleep_speed'] = 0.0
    if args.membrane is not None:
        options.update(membrane_weight=args.membrane, membrane_scope='always')
    if args.membrane_iterations is not None:
        options['membrane_iterations'] = args.membrane_iterations
    for setting in args.set:
        name, _, value = setting.partition('=')
        options[name] = json.loads(value)
    runs = [(name, grid, seed, not args.no_damage, args.substeps, options)
            for name in args.scenarios for grid in args.grids for seed in args.seeds]
    results = []
    with ProcessPoolExecutor(args.jobs) as pool:
        for metrics in pool.map(measure, *zip(*runs)):
            print(row(metrics), flush=True)
            results.append(metrics)
    print('worst over seeds')
    for name in args.scenarios:
        for grid in args.grids:
            group = [m for m in results if m['scenario'] == name and m['grid'][0] == grid]
            print(f"{name:<9} {grid:>4}²  strain {max(m['max_strain'] for m in group):8.3%}  "
                  f"in probe {1e3 * max(m['max_probe_penetration_m'] for m in group):6.2f} mm"
                  f"  below table {1e3 * max(m['max_table_penetration_m'] for m in group):6.2f}"
                  f" mm  breaks {min(m['breaks'] for m in group)}–"
                  f"{max(m['breaks'] for m in group)}  relaxed "
                  f"{1e3 * min(m['relaxed_deviation_m'] for m in group):.2f}–"
                  f"{1e3 * max(m['relaxed_deviation_m'] for m in group):.2f} mm  follow "
                  f"{min(m['follow'] for m in group):.2f}  all valid "
                  f"{all(m['mesh_valid'] for m in group)}  RTF "
                  f"{min(m['realtime_factor'] for m in group):.2f}–"
                  f"{max(m['realtime_factor'] for m in group):.2f}  asleep "
                  f"{min(m['frames_asleep'] / m['steps'] for m in group):.0%}–"
                  f"{max(m['frames_asleep'] / m['steps'] for m in group):.0%}", flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
