"""A built-in scenario's largest strain in two phases: while its probes push, and after.

    .venv/bin/python bench/strain_phases.py [--scenario squeeze] [--grids 65] [--seeds 0 1]
        [--substeps 4] [--split-at 2.5]

Per run: the largest HINGE strain up to ``--split-at`` seconds (the squeeze's fingertips
push until 2.5 s) and after it (their lift-off and the sheet's settling), breaks, folds and
the relaxed deviation (core.metrics). Damage on. A script that prints figures, not a test.
"""
from __future__ import annotations

import argparse
import os

os.environ.setdefault('NUMBA_NUM_THREADS', '1')

from paper_sim_ros.core import load_scenario  # noqa: E402
from paper_sim_ros.core.metrics import relaxed_deviation  # noqa: E402
from paper_sim_ros.core.runner import build_simulator  # noqa: E402


def phases(scenario_name: str, grid: int, seed: int, substeps: int | None,
           split_at: float) -> dict:
    """One run: the largest strain before and after ``split_at`` [s], and the damage."""
    scenario = load_scenario(scenario_name, grid=grid, seed=seed, substeps=substeps,
                             damage_enabled=True)
    simulator = build_simulator(scenario)
    dt = scenario.config.solver.dt
    before = after = 0.0
    for frame in range(scenario.frame_count):
        simulator.set_probes(*scenario.probe_inputs((frame + 1) * dt))
        simulator.step_frame()
        strain = simulator.max_strain()
        if (frame + 1) * dt <= split_at:
            before = max(before, strain)
        else:
            after = max(after, strain)
    return {'before': before, 'after': after, 'breaks': simulator.breaks,
            'folds': simulator.folds, 'relaxed': relaxed_deviation(simulator)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--scenario', default='squeeze')
    parser.add_argument('--grids', type=int, nargs='+', default=[65])
    parser.add_argument('--seeds', type=int, nargs='+', default=[0])
    parser.add_argument('--substeps', type=int, default=None)
    parser.add_argument('--split-at', type=float, default=2.5, help='[s] (default 2.5)')
    args = parser.parse_args()
    print('| grid | seed | largest strain, pushing | after | breaks | folds | relaxed |')
    print('|---|---|---|---|---|---|---|')
    for grid in args.grids:
        for seed in args.seeds:
            run = phases(args.scenario, grid, seed, args.substeps, args.split_at)
            print(f'| {grid}² | {seed} | {100 * run["before"]:.2f} % | {100 * run["after"]:.2f} % '
                  f'| {run["breaks"]} | {run["folds"]} | {1e3 * run["relaxed"]:.2f} mm |',
                  flush=True)


if __name__ == '__main__':
    main()
