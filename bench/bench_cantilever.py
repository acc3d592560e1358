"""Bending against thin-plate theory (issue 14): a paper strip clamped at one end droops
under its own weight; its tip angle against the elastica of a self-weighted cantilever.

    .venv/bin/python bench/bench_cantilever.py [--overhangs 0.06 0.1 0.15 0.2]
        [--spacings 0.0025 0.005 0.01] [--width 0.02] [--length-projection]
        [--membrane 8 [--membrane-iterations 10]] [--split-step]
        [--air-damping 6] [--duration 4]

The strip (default office paper: B = 4e-4 N·m, 80 g/m²) is clamped by its first two rows of
vertices (one pinned row is a hinge, not a clamp), released flat and left to settle with air
drag 6/s for 4 s (``--air-damping``, ``--duration``). ``--split-step``: the membrane only
where probes squeeze the sheet (``membrane_scope`` 'squeezed'), not while it settles, which
is the split step's own rest. The sheet between the two pinned rows is flat, so the
cantilever starts at their midpoint: its length L is the overhang beyond the second row plus
half a cell.
The elastica, θ'' = −(q L³ / B)(1 − s) cos θ, θ(0) = 0, θ'(1) = 0 (s the arc length over
L, q the weight per area), is solved by shooting. The tip angle is the slope of the
strip's last row of cells. A script that prints figures, not a test.
"""
from __future__ import annotations

import argparse
import math
import os
import time

os.environ.setdefault('NUMBA_NUM_THREADS', '1')

import numpy as np  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402
from scipy.optimize import brentq  # noqa: E402

from paper_sim_ros.core import build_simulator, load_scenario  # noqa: E402

GRAVITY = 9.81


def elastica_tip_angle(load: float) -> float:
    """Tip angle [rad] of a self-weighted cantilever elastica with load q L³ / B."""
    def shoot(root_curvature: float) -> tuple[float, float]:
        solution = solve_ivp(lambda s, y: [y[1], -load * (1.0 - s) * math.cos(y[0])],
                             (0.0, 1.0), [0.0, root_curvature], rtol=1e-10, atol=1e-12)
        return solution.y[1, -1], solution.y[0, -1]
    root_curvature = brentq(lambda value: shoot(value)[0], 0.0, load)
    return shoot(root_curvature)[1]


def drooped_tip_angle(overhang: float, spacing: float, width: float,
                      solver: dict | None = None, duration: float = 4.0) -> tuple[float, dict]:
    """The simulated strip's tip angle [rad], its sheet settings, its fastest vertex at the
    end [m/s] and the seconds the stepping took."""
    rows = int(round(overhang / spacing)) + 2  # the clamp's two rows, then the overhang
    columns = max(3, int(round(width / spacing)) + 1)
    scenario = load_scenario({
        'name': 'cantilever', 'duration': duration, 'pin': 'none',
        'sheet': {'width': width, 'height': (rows - 1) * spacing, 'nx': columns, 'ny': rows,
                  'elevation': 0.5},
        'solver': {'air_damping': 6.0, **(solver or {})},
        'contact': {'ground_enabled': False},
        'damage': {'enabled': False}})
    simulator = build_simulator(scenario)
    along = simulator.sheet.material[:, 1]
    simulator.set_pinned(along <= along.min() + 1.01 * spacing)
    started = time.perf_counter()
    for _ in range(scenario.frame_count):
        simulator.step_frame()
    seconds = time.perf_counter() - started
    grid = simulator.sheet.positions.reshape(rows, columns, 3)
    tip = grid[-1].mean(axis=0) - grid[-2].mean(axis=0)
    sheet = scenario.config.sheet
    return math.atan2(-tip[2], tip[1]), {
        'rigidity': sheet.bending_rigidity, 'grammage': sheet.grammage,
        'speed': float(np.linalg.norm(simulator.sheet.velocities, axis=1).max()),
        'seconds': seconds}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--overhangs', type=float, nargs='+', default=[0.06, 0.1, 0.15, 0.2])
    parser.add_argument('--spacings', type=float, nargs='+', default=[0.0025, 0.005, 0.01])
    parser.add_argument('--width', type=float, default=0.02)
    parser.add_argument('--length-projection', action='store_true',
                        help='solver.length_projection on (core/length_projection.py)')
    parser.add_argument('--membrane', type=float, default=None,
                        help='the membrane at this weight in every sub-step (solver.'
                        "membrane_weight, membrane_scope 'always'; core/membrane.py)")
    parser.add_argument('--membrane-iterations', type=int, default=None,
                        help='solver.membrane_iterations')
    parser.add_argument('--split-step', action='store_true',
                        help="solver.membrane_scope 'squeezed': no membrane while it settles")
    parser.add_argument('--air-damping', type=float, default=6.0, help='[1/s] (default 6)')
    parser.add_argument('--duration', type=float, default=4.0, help='[s] (default 4)')
    args = parser.parse_args()
    solver = {'length_projection': args.length_projection, 'air_damping': args.air_damping}
    if args.split_step:
        solver['membrane_scope'] = 'squeezed'
    if args.membrane is not None:
        solver.update(membrane_weight=args.membrane, membrane_scope='always')
    if args.membrane_iterations is not None:
        solver['membrane_iterations'] = args.membrane_iterations
    drooped_tip_angle(0.02, 0.01, args.width, solver)  # numba compiled
    print(f'| overhang | spacing | elastica tip angle | simulated | ratio '
          f'| max speed at {args.duration:g} s | s to step {args.duration:g} s |')
    print('|---|---|---|---|---|---|---|')
    for overhang in args.overhangs:
        for spacing in args.spacings:
            angle, sheet = drooped_tip_angle(overhang, spacing, args.width, solver,
                                             args.duration)
            # the strip is flat between its two pinned rows: its slope is zero at their
            # midpoint, where the discrete cantilever starts
            span = overhang + 0.5 * spacing
            load = sheet['grammage'] * GRAVITY * span ** 3 / sheet['rigidity']
            reference = elastica_tip_angle(load)
            print(f'| {1e3 * overhang:.0f} mm | {1e3 * spacing:.1f} mm '
                  f'| {math.degrees(reference):.2f}° | {math.degrees(angle):.2f}° '
                  f'| {angle / reference:.3f} | {1e3 * sheet["speed"]:.2f} mm/s '
                  f'| {sheet["seconds"]:.2f} |', flush=True)


if __name__ == '__main__':
    main()
