"""Why the membrane's conjugate gradients converge slowly on fine grids: the spectrum of the
coupled system preconditioned by the bending solve (core/membrane.py).

    .venv/bin/python bench/membrane_spectrum.py [--grids 9 17] [--weights 8 30]

For a `hanging` sheet after 20 frames, the generalised eigenvalues λ of
(B ⊗ I₃ + W) v = λ (B ⊗ I₃) v, B the bending step's system (M/h² + Q) and W the held
springs' membrane, both dense over the free vertices (small grids only: 3V unknowns).
Conjugate gradients need about √(λmax / λmin) iterations. Prints the extremes, the median
and how many exceed 10, 100 and 1000. A script that prints figures, not a test.
"""
from __future__ import annotations

import argparse

import numpy as np
import scipy.linalg as linalg

from paper_sim_ros.core import build_simulator, load_scenario
from paper_sim_ros.core.membrane import Membrane
from paper_sim_ros.core.scenarios import builtin_mapping, with_overrides


def spectrum(grid: int, weight: float) -> np.ndarray:
    mapping = with_overrides(builtin_mapping('hanging'), grid=grid)
    mapping['solver'] = {'membrane_weight': weight}
    simulator = build_simulator(load_scenario(mapping))
    for _ in range(20):
        simulator.step_frame()
    step = simulator._bending_step.step
    free = np.repeat(~step.pinned_mask, 3)
    membrane = Membrane(simulator._held_ends, simulator._held_rest,
                        simulator._membrane_weight, simulator.sheet.positions)
    unknowns = 3 * simulator.sheet.vertex_count
    coupling = np.zeros((membrane.ends.shape[0], unknowns))  # a row g per spring
    for column in range(3):
        rows = np.arange(membrane.ends.shape[0])
        coupling[rows, 3 * membrane.ends[:, 1] + column] = membrane.unit[:, column]
        coupling[rows, 3 * membrane.ends[:, 0] + column] = -membrane.unit[:, column]
    bending = np.kron(step.system.toarray(), np.eye(3))[np.ix_(free, free)]
    coupling = coupling[:, free]
    stiff = coupling.T @ (membrane.weight[:, None] * coupling)
    return np.sort(linalg.eigh(bending + stiff, bending, eigvals_only=True))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--grids', type=int, nargs='+', default=[9, 17])
    parser.add_argument('--weights', type=float, nargs='+', default=[8.0, 30.0])
    args = parser.parse_args()
    for weight in args.weights:
        for grid in args.grids:
            values = spectrum(grid, weight)
            print(f'{grid}², membrane_weight {weight:g}: {values.size} eigenvalues from '
                  f'{values[0]:.3f} to {values[-1]:.3g}, median {np.median(values):.3g}; '
                  f'over 10: {np.sum(values > 10)}, over 100: {np.sum(values > 100)}, '
                  f'over 1000: {np.sum(values > 1000)}', flush=True)


if __name__ == '__main__':
    main()
