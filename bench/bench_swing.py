"""Convergence of motion (issue 14): a 0.2 m square sheet pinned along one edge, released
flat, swings down; how far its lowest point is below the start at 0.17 s and at 0.5 s,
per grid and sub-step count.

    .venv/bin/python bench/bench_swing.py [--grids 33 65 129] [--substeps 1 4 16]
        [--set solver.energy_restoring=true sheet.bending_rigidity=4e-5 ...]

Defaults otherwise (air drag 0.2/s, no table, no damage), or what ``--set`` changes (what
docs/solver.md's search for the damping one sub-step adds changed). The answer with many sub-steps
is the converged one; a grid whose figures at one sub-step stray from it is damped or
stiffened by the time step. A script that prints figures, not a test.
"""
from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault('NUMBA_NUM_THREADS', '1')

from paper_sim_ros.core import build_simulator, load_scenario  # noqa: E402

SAMPLES = {10: '0.17 s', 20: '0.33 s', 30: '0.5 s'}
"""Frames (of 1/60 s) at which the lowest point is read."""


def swing(grid: int, substeps: int,
          overrides: dict[str, dict[str, float]] | None = None) -> dict[int, float]:
    """Depth [m] of the lowest point below the start at each sampled frame. ``overrides``:
    {'solver': {...}, 'sheet': {...}} on top of the scene's."""
    overrides = overrides or {}
    scenario = load_scenario({
        'name': 'swing', 'duration': max(SAMPLES) / 60.0, 'pin': 'short_edge',
        'sheet': {'width': 0.2, 'height': 0.2, 'nx': grid, 'ny': grid, 'elevation': 0.5,
                  **overrides.get('sheet', {})},
        'solver': {'substeps': substeps, **overrides.get('solver', {})},
        'contact': {'ground_enabled': False}, 'damage': {'enabled': False}})
    simulator = build_simulator(scenario)
    start = simulator.sheet.positions[:, 2].min()
    depth = {}
    for frame in range(1, scenario.frame_count + 1):
        simulator.step_frame()
        if frame in SAMPLES:
            depth[frame] = float(start - simulator.sheet.positions[:, 2].min())
    return depth


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--grids', type=int, nargs='+', default=[33, 65, 129])
    parser.add_argument('--substeps', type=int, nargs='+', default=[1, 4, 16])
    parser.add_argument('--set', nargs='+', default=[], metavar='SECTION.NAME=VALUE',
                        help='solver.* or sheet.* values (numbers, true, false) for the scene')
    args = parser.parse_args()
    overrides: dict[str, dict[str, float]] = {}
    for assignment in args.set:
        key, _, value = assignment.partition('=')
        section, _, name = key.partition('.')
        if section not in ('solver', 'sheet') or not name or not value:
            parser.error(f'--set wants solver.NAME=VALUE or sheet.NAME=VALUE, got {assignment!r}')
        if value in ('true', 'false'):
            overrides.setdefault(section, {})[name] = value == 'true'
            continue
        number = float(value)
        overrides.setdefault(section, {})[name] = int(number) if number.is_integer() \
            and (name.endswith('iterations') or name == 'substeps') else number
    print('| grid | sub-steps | ' + ' | '.join(f'lowest at {t}' for t in SAMPLES.values())
          + ' | seconds |')
    print('|---|---|' + '---|' * len(SAMPLES) + '---|')
    for grid in args.grids:
        for substeps in args.substeps:
            started = time.perf_counter()
            depth = swing(grid, substeps, overrides)
            print(f'| {grid}² | {substeps} | '
                  + ' | '.join(f'{1e3 * depth[frame]:.1f} mm' for frame in SAMPLES)
                  + f' | {time.perf_counter() - started:.1f} |', flush=True)


if __name__ == '__main__':
    main()
