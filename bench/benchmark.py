"""Benchmark of the solvers on the `hanging` scenario (and `squeeze`, with damage), and of
every built-in scenario at 65² against issue 13's targets.

    .venv/bin/python bench/benchmark.py [--grids 33 65 129] [--duration 10] [--quick]
        [--builtins-grid 65]

Single-threaded (NUMBA_NUM_THREADS=1), kernels compiled before timing. Prints, per grid
and solver option: real-time factor, mean and 95th-percentile frame time, max strain
over the run, whether anything went non-finite, and the share of frames the sheet slept
through (docs/solver.md, "Sleeping"); then each built-in scenario, damage on, seed 0, its
own duration, at ``--builtins-grid`` (0: none). A script, not a test: timings depend on the
machine and its load.
"""
from __future__ import annotations

import argparse
import os
import sys

os.environ.setdefault('NUMBA_NUM_THREADS', '1')
os.environ.setdefault('OMP_NUM_THREADS', '1')
os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')

import numpy as np  # noqa: E402

from paper_sim_ros.core import BUILTIN_SCENARIOS, load_scenario, run_scenario  # noqa: E402
from paper_sim_ros.core.scenarios import builtin_mapping, with_overrides  # noqa: E402
from paper_sim_ros.warmup import warm_up  # noqa: E402

SOLVER_OPTIONS = {
    'constrained (default)': {},
    'constrained, len. proj.': {'length_projection': True},
    'constrained, no membrane': {'membrane_weight': 0.0},
    'constrained, membrane 30': {'membrane_weight': 30.0, 'membrane_scope': 'always'},
    'paper Eq.6, 10 Jacobi': {'method': 'paper', 'jacobi_iterations': 10},
    'paper Eq.6, 100 Jacobi': {'method': 'paper', 'jacobi_iterations': 100},
}
# explicit Euler is left out: at paper stiffness it diverges within a second
# (test_explicit_euler_diverges_where_the_paper_method_does_not)


def measure(name: str, grid: int, duration: float | None, solver: dict, damage: bool) -> dict:
    mapping = with_overrides(builtin_mapping(name), grid=grid, duration=duration)
    mapping['solver'] = {**(mapping.get('solver') or {}), **solver}
    if not damage:
        mapping['damage'] = {'enabled': False}
    frame_seconds: list[float] = []
    metrics = run_scenario(load_scenario(mapping),
                           on_frame=lambda simulator, seconds: frame_seconds.append(seconds))
    metrics['frame_ms_mean'] = 1e3 * float(np.mean(frame_seconds))
    metrics['frame_ms_p95'] = 1e3 * float(np.percentile(frame_seconds, 95))
    return metrics


def row(label: str, grid: int, metrics: dict) -> str:
    extra = ''
    if 'breaks' in metrics:
        extra = f"  breaks {metrics['breaks']:>5}  folds {metrics['folds']:>5}"
    return (f"{label:<24} {grid:>4}²  RTF {metrics['realtime_factor']:7.2f}  "
            f"frame {metrics['frame_ms_mean']:7.2f} ms (p95 {metrics['frame_ms_p95']:7.2f})  "
            f"max strain {metrics['max_strain']:9.4%}  nan {metrics['nan']!s:>5}  "
            f"asleep {metrics['frames_asleep'] / metrics['steps']:4.0%}{extra}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--grids', type=int, nargs='+', default=[33, 65, 129])
    parser.add_argument('--duration', type=float, default=10.0,
                        help='simulated seconds of hanging per run (default 10)')
    parser.add_argument('--quick', action='store_true',
                        help='default solver only, 2 s per run')
    parser.add_argument('--builtins-grid', type=int, default=65,
                        help='grid of the built-in scenarios section (0: skip it)')
    args = parser.parse_args(argv)
    options = {'constrained (default)': {}} if args.quick else SOLVER_OPTIONS
    duration = 2.0 if args.quick else args.duration
    print(f'warm-up (numba compile/cache load): {warm_up():.1f} s')
    print(f'hanging, {duration:g} s simulated, dt = 1/60 s, 1 thread')
    for grid in args.grids:
        for label, solver in options.items():
            print(row(label, grid, measure('hanging', grid, duration, solver, False)),
                  flush=True)
    print('squeeze (damage on), default solver')
    for grid in args.grids:
        for damage in (False, True):
            label = 'squeeze, damage ' + ('on' if damage else 'off')
            print(row(label, grid, measure('squeeze', grid, 3.0, {}, damage)), flush=True)
    if args.builtins_grid:
        print('every built-in scenario (damage on, seed 0, its own duration), default solver')
        for name in BUILTIN_SCENARIOS:
            print(row(name, args.builtins_grid,
                      measure(name, args.builtins_grid, None, {}, True)), flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
