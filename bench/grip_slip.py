"""Grips that cannot be followed (docs/contact.md, "A grip slips"): a fingertip pulling a
sheet pinned at its far edge 8 cm away from the pin, the same fingertip dragged 6 cm along
the pinned edge (in the sheet's middle, and 3.85 cm from the edge), and two fingertips
moving 4 cm apart each, on the `drag` scenario's A4 sheet (no damage).

    .venv/bin/python bench/grip_slip.py [--grids 33 65] [--substeps 1 4]

Per scene, grid and sub-step count: the max HINGE strain over the run and how far the
sheet moved (median and largest vertex displacement). A script that prints figures, not
a test.
"""
from __future__ import annotations

import argparse
import os

os.environ.setdefault('NUMBA_NUM_THREADS', '1')

import numpy as np  # noqa: E402

from paper_sim_ros.core import build_simulator  # noqa: E402
from paper_sim_ros.core.scenarios import (builtin_mapping, scenario_from_mapping,  # noqa: E402
                                          with_overrides)


def fingertip(name: str, start_y: float, end_y: float, start_x: float = 0.0,
              end_x: float = 0.0) -> dict:
    """A 1 cm fingertip that lands at (``start_x``, ``start_y``), pressed 1 mm into the
    table, moves to (``end_x``, ``end_y``) in 1 s and lifts off."""
    return {'name': name, 'radius': 0.01, 'keyframes': [
        [0.0, start_x, start_y, 0.05], [0.5, start_x, start_y, 0.009],
        [1.5, end_x, end_y, 0.009], [2.0, end_x, end_y, 0.05]]}


SCENES = {
    'pinned pull': ('short_edge', [fingertip('finger', 0.0, 0.08)]),
    'along the pins': ('short_edge', [fingertip('finger', 0.0, 0.0, -0.03, 0.03)]),
    'along, near them': ('short_edge', [fingertip('finger', -0.11, -0.11, -0.03, 0.03)]),
    'apart': ('none', [fingertip('low', -0.03, -0.07), fingertip('high', 0.03, 0.07)]),
}


def run(scene: str, grid: int, substeps: int) -> tuple[float, np.ndarray]:
    """Max HINGE strain over the run and each vertex's displacement [m]."""
    pin, probes = SCENES[scene]
    mapping = with_overrides(builtin_mapping('drag'), grid=grid, substeps=substeps,
                             duration=2.5, damage_enabled=False)
    mapping.update(pin=pin, probes=probes)
    scenario = scenario_from_mapping(mapping)
    simulator = build_simulator(scenario)
    start = simulator.sheet.positions.copy()
    strain = 0.0
    for frame in range(scenario.frame_count):
        simulator.set_probes(*scenario.probe_inputs((frame + 1) * scenario.config.solver.dt))
        simulator.step_frame()
        strain = max(strain, simulator.max_strain())
    return strain, np.linalg.norm(simulator.sheet.positions - start, axis=1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--grids', type=int, nargs='+', default=[33, 65])
    parser.add_argument('--substeps', type=int, nargs='+', default=[1, 4])
    args = parser.parse_args()
    print('| scene | grid | sub-steps | max strain | sheet moved (median, most) |')
    print('|---|---|---|---|---|')
    for scene in SCENES:
        for grid in args.grids:
            for substeps in args.substeps:
                strain, moved = run(scene, grid, substeps)
                print(f'| {scene} | {grid}² | {substeps} | {100 * strain:.2f} % '
                      f'| {1e3 * np.median(moved):.1f}, {1e3 * moved.max():.1f} mm |',
                      flush=True)


if __name__ == '__main__':
    main()
