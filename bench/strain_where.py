"""Where a scenario strains the sheet: its worst HINGE spring every few frames, placed
relative to the nearest probe.

    .venv/bin/python bench/strain_where.py squeeze [--grid 65] [--seed 0] [--substeps 4]
        [--every 6] [--membrane 30]
    .venv/bin/python bench/strain_where.py poke:12053 [--every 6]

The scenario is a built-in one or a run of bench/random_scenes.py as ``family:index`` (its
own grid, seed and sub-steps unless given).

Each line: simulated time, the worst spring's strain (signed), how many springs are beyond
2 %, the nearest active probe, the spring's midpoint relative to that probe's centre (x, y)
and its height above z = 0 [mm], its direction, and the highest vertex [mm]. A diagnostic
that prints figures, not a test (docs/contact.md, "What is wrong").
"""
from __future__ import annotations

import argparse
import os
import sys

os.environ.setdefault('NUMBA_NUM_THREADS', '1')

import numpy as np  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import random_scenes  # noqa: E402
from paper_sim_ros.core import build_simulator, load_scenario  # noqa: E402
from paper_sim_ros.core.scenarios import builtin_mapping, with_overrides  # noqa: E402
from paper_sim_ros.core.sheet import HINGE  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('scenario')
    parser.add_argument('--grid', type=int, default=None, help='vertices a side (default 65)')
    parser.add_argument('--seed', type=int, default=None, help='(default 0)')
    parser.add_argument('--substeps', type=int, default=None,
                        help="sub-steps per frame (default: the scenario's own)")
    parser.add_argument('--every', type=int, default=6, help='frames between lines')
    parser.add_argument('--membrane', type=float, default=None,
                        help="the membrane at this weight in every sub-step (membrane_scope "
                        "'always'; 0: none; default: the solver's)")
    arguments = parser.parse_args()
    if ':' in arguments.scenario:  # a random scene: its own settings unless given
        family, index = arguments.scenario.split(':')
        mapping = with_overrides(random_scenes.scene(family, int(index)), grid=arguments.grid,
                                 seed=arguments.seed, substeps=arguments.substeps)
    else:
        mapping = with_overrides(builtin_mapping(arguments.scenario),
                                 grid=arguments.grid or 65, seed=arguments.seed or 0,
                                 substeps=arguments.substeps)
    if arguments.membrane is not None:
        mapping['solver'] = {**(mapping.get('solver') or {}), 'membrane_weight':
                             arguments.membrane, 'membrane_scope': 'always'}
    scenario = load_scenario(mapping)
    simulator = build_simulator(scenario)
    dt = scenario.config.solver.dt
    for frame in range(scenario.frame_count):
        simulator.set_probes(*scenario.probe_inputs((frame + 1) * dt))
        simulator.step_frame()
        if (frame + 1) % arguments.every:
            continue
        sheet = simulator.sheet
        hinge = np.flatnonzero(sheet.spring_kind == HINGE)
        strain = sheet.strain(HINGE)
        worst = int(np.argmax(np.abs(strain)))
        i, j = sheet.spring_vertices[hinge[worst]]
        middle = 0.5 * (sheet.positions[i] + sheet.positions[j])
        edge = sheet.positions[j] - sheet.positions[i]
        edge /= max(float(np.linalg.norm(edge)), 1e-12)
        probes = simulator.probes
        where = 'no probe'
        if np.any(probes.active):
            distance = np.linalg.norm(probes.end[:, :2] - middle[None, :2], axis=1)
            distance[~probes.active] = np.inf
            nearest = int(np.argmin(distance))
            offset = 1e3 * (middle - probes.end[nearest])
            where = f'probe {nearest} at ({offset[0]:+.1f}, {offset[1]:+.1f}) mm'
        print(f't {(frame + 1) * dt:5.2f} s  worst {100 * strain[worst]:+7.1f} %  beyond 2 % '
              f'{int(np.sum(np.abs(strain) > 0.02)):5d}  {where}, z {1e3 * middle[2]:.1f} mm'
              f'  along ({edge[0]:+.2f}, {edge[1]:+.2f}, {edge[2]:+.2f})  highest '
              f'{1e3 * sheet.positions[:, 2].max():.1f} mm', flush=True)


if __name__ == '__main__':
    main()
