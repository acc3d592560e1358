"""A fingertip pushing a pinned sheet towards its pin: how long the sheet stays flat and
strained before it buckles (docs/contact.md, "What is wrong").

    .venv/bin/python bench/push_to_pin.py [--grids 25 37 49] [--speeds 0.03 0.1 0.3]
        [--substeps 1]

A 12 x 20 cm sheet lies on the table, pinned along its short edge at y = -10 cm; a 12 mm
fingertip lands on its middle at 0.4 s, pressed 1 mm into the table (it grips the paper:
it grips better than the table), pushes it 4 cm towards the pin and lifts off. Paper
cannot get shorter: it must buckle up between the fingertip and the pin at once. Per run:
the largest HINGE strain over the run and when, the largest while the fingertip pushes
and how high the sheet stands then (the buckle), and the largest after it lifts off.
Damage off, so nothing in it is random. A script that prints figures, not a test.
"""
from __future__ import annotations

import argparse
import os

os.environ.setdefault('NUMBA_NUM_THREADS', '1')

import numpy as np  # noqa: E402

from paper_sim_ros.core import build_simulator, load_scenario  # noqa: E402

RADIUS, PRESS, TRAVEL, LANDED = 0.012, 0.001, 0.04, 0.4
"""The fingertip [m], how far it is pressed into the table [m], how far it pushes [m] and
when it lands [s]."""


def scene(columns: int, rows: int, speed: float, substeps: int) -> dict:
    """The scenario mapping: ``speed`` [m/s] of the push."""
    stop = LANDED + TRAVEL / speed
    height = RADIUS - PRESS
    return {'name': 'push_to_pin', 'duration': stop + 0.6, 'pin': 'short_edge',
            'sheet': {'width': 0.12, 'height': 0.2, 'nx': columns, 'ny': rows},
            'solver': {'substeps': substeps}, 'damage': {'enabled': False},
            'contact': {'ground_enabled': True},
            'probes': [{'name': 'finger', 'radius': RADIUS, 'keyframes': [
                [0.0, 0.0, 0.0, RADIUS + 0.03], [LANDED, 0.0, 0.0, height],
                [stop, 0.0, -TRAVEL, height], [stop + 0.3, 0.0, -TRAVEL, RADIUS + 0.03]]}]}


def run(columns: int, speed: float, substeps: int) -> dict:
    """Step one push; its strains [1] and heights [m]."""
    rows = (columns - 1) * 5 // 3 + 1  # square cells on the 12 x 20 cm sheet
    built = load_scenario(scene(columns, rows, speed, substeps))
    simulator = build_simulator(built)
    dt = built.config.solver.dt
    stop = LANDED + TRAVEL / speed
    worst = {'run': (0.0, 0.0), 'push': (0.0, 0.0, 0.0), 'after': 0.0}
    for frame in range(built.frame_count):
        time = (frame + 1) * dt
        simulator.set_probes(*built.probe_inputs(time))
        simulator.step_frame()
        strain = simulator.max_strain()
        if strain > worst['run'][0]:
            worst['run'] = (strain, time)
        if LANDED < time <= stop and strain > worst['push'][0]:
            worst['push'] = (strain, time, float(np.max(simulator.sheet.positions[:, 2])))
        if time > stop:
            worst['after'] = max(worst['after'], strain)
    worst['rows'] = rows
    return worst


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--grids', type=int, nargs='+', default=[25, 37, 49],
                        help='vertices across the sheet (along it 5/3 as many)')
    parser.add_argument('--speeds', type=float, nargs='+', default=[0.03, 0.1, 0.3])
    parser.add_argument('--substeps', type=int, default=1)
    arguments = parser.parse_args()
    print('| grid | push | max strain (at) | pushing: max (at, sheet height then) '
          '| after lift-off |')
    print('|---|---|---|---|---|')
    for columns in arguments.grids:
        for speed in arguments.speeds:
            worst = run(columns, speed, arguments.substeps)
            strain, at = worst['run']
            pushed, pushed_at, height = worst['push']
            print(f"| {columns} × {worst['rows']} | {100 * speed:.0f} cm/s "
                  f'| {100 * strain:.1f} % ({at:.2f} s) '
                  f'| {100 * pushed:.1f} % ({pushed_at:.2f} s, {1e3 * height:.1f} mm) '
                  f"| {100 * worst['after']:.1f} % |", flush=True)


if __name__ == '__main__':
    main()
