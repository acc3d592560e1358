"""The global steps' triangular solves and factorisations alone: what each costs.

    .venv/bin/python bench/bench_solve.py [--grids 33 65 129] [--repeats 50]

The `hanging` sheet after one frame: its springs' system (M/h² + Σ w AᵀA) and its bending
system (M/h² + Q), each factorised once; one solve is a forward and a backward substitution
over the factor on three right-hand sides. Single thread. Prints, per grid and system, the
factor's entries and the mean time of a solve; every iteration of the 'constrained' solver
pays one (docs/solver.md). Then what a grip or sub-step length change asks: the same system
with another row of vertices held and half the sub-step, factored in a new minimum degree
order (SuperLU, as a mesh's first factor is) and in the first factor's kept order
(core/sparse_ldl.py, as every later one is), best of five each. A script that prints
figures, not a test: on a machine whose speed varies, run it on the two trees to compare,
alternately.
"""
from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault('NUMBA_NUM_THREADS', '1')

import numpy as np  # noqa: E402
import scipy.sparse as sparse  # noqa: E402

from paper_sim_ros.core import build_simulator, load_scenario  # noqa: E402
from paper_sim_ros.core.projective import GlobalStep  # noqa: E402

FACTOR_REPEATS = 5


def factor_ms(system, pinned: np.ndarray, previous: GlobalStep | None) -> float:
    """Best time [ms] of a factor of ``system`` in ``previous``'s order (None: a new one)."""
    best = np.inf
    for _ in range(FACTOR_REPEATS):
        step = GlobalStep.__new__(GlobalStep)
        start = time.perf_counter()
        step._factor(system, pinned, previous)
        best = min(best, time.perf_counter() - start)
    return 1e3 * best


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--grids', type=int, nargs='+', default=[33, 65, 129])
    parser.add_argument('--repeats', type=int, default=50)
    args = parser.parse_args(argv)
    print('| grid | system | factor entries | ms a solve | ms a factor: new order | kept order |')
    print('|---|---|---|---|---|---|')
    for grid in args.grids:
        simulator = build_simulator(load_scenario('hanging', grid=grid, duration=0.1))
        simulator.step_frame()
        vertex_count = simulator.sheet.vertex_count
        h = simulator.config.solver.dt
        held = simulator.sheet.pinned.copy()
        held[grid:2 * grid] = True  # the next row too, as a grip holds a patch
        for name, step in (('springs', simulator._global_step.step),
                           ('bending', simulator._bending_step.step)):
            rhs = np.random.default_rng(0).random((vertex_count, 3))
            positions = simulator.sheet.positions.copy()
            step.solve(rhs, positions)  # compiled before timing
            start = time.perf_counter()
            for _ in range(args.repeats):
                step.solve(rhs, positions)
            seconds = (time.perf_counter() - start) / args.repeats
            # M/(h/2)² + K: the factored system's diagonal gains 3 M/h²
            changed = (step.system + sparse.diags(3.0 * simulator.sheet.vertex_mass / h ** 2)
                       ).tocsr()
            print(f'| {grid}² | {name} | {step.factor_entries} | {1e3 * seconds:.3f} '
                  f'| {factor_ms(changed, held, None):.1f} '
                  f'| {factor_ms(changed, held, step):.1f} |')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
