"""The global steps' triangular solves alone: what one solve of each system costs.

    .venv/bin/python bench/bench_solve.py [--grids 33 65 129] [--repeats 50]

The `hanging` sheet after one frame: its springs' system (M/h² + Σ w AᵀA) and its bending
system (M/h² + Q), each factorised once; one solve is a forward and a backward substitution
over the factor on three right-hand sides. Single thread. Prints, per grid and system, the
factor's entries and the mean time of a solve; every iteration of the 'constrained' solver
pays one (docs/solver.md). A script that prints figures, not a test: on a machine whose
speed varies, run it on the two trees to compare, alternately.
"""
from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault('NUMBA_NUM_THREADS', '1')

import numpy as np  # noqa: E402

from paper_sim_ros.core import build_simulator, load_scenario  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--grids', type=int, nargs='+', default=[33, 65, 129])
    parser.add_argument('--repeats', type=int, default=50)
    args = parser.parse_args(argv)
    print('| grid | system | factor entries | ms a solve |')
    print('|---|---|---|---|')
    for grid in args.grids:
        simulator = build_simulator(load_scenario('hanging', grid=grid, duration=0.1))
        simulator.step_frame()
        vertex_count = simulator.sheet.vertex_count
        for name, step in (('springs', simulator._global_step.step),
                           ('bending', simulator._bending_step.step)):
            rhs = np.random.default_rng(0).random((vertex_count, 3))
            positions = simulator.sheet.positions.copy()
            step.solve(rhs, positions)  # compiled before timing
            start = time.perf_counter()
            for _ in range(args.repeats):
                step.solve(rhs, positions)
            seconds = (time.perf_counter() - start) / args.repeats
            print(f'| {grid}² | {name} | {step.factor_entries} | {1e3 * seconds:.3f} |')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
