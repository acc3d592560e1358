"""A prototype, not the solver: the bending solve with a membrane that lets the edges turn.

    .venv/bin/python bench/membrane_bending.py cantilever [--membrane 60]
        [--overhangs 0.06 0.1 0.15 0.2] [--spacings 0.0025 0.005 0.01]
    .venv/bin/python bench/membrane_bending.py squeeze [--grid 33] [--seed 0]
        [--substeps 1] [--no-damage] [--membrane 60]
    .venv/bin/python bench/membrane_bending.py cost [--grid 65]
    .venv/bin/python bench/membrane_bending.py cantilever --membrane 6 --cg 10

The 'constrained' solver splits a sub-step in two: a bending solve that sees no membrane,
then the springs' local/global iterations, which rebuild the sheet from the directions its
edges have after the bending solve (docs/solver.md, "The cantilever"). Here the bending
solve of each sub-step (``Simulator._bending_solve``, patched) gets every held spring as a
membrane term ½ w (uᵀ(x_j − x_i) − l0)², u its direction at the sub-step's start: stiff
along the edge, free to turn. That couples x, y and z, so the system is 3V × 3V, assembled
and factorised by SciPy in every solve (seconds a frame; a measurement, not a method). Pins
and grips hold their coordinates; the table holds z by an active set (vertices pushed up
stay held, those pulled down go, those below come in); a probe's contact row along a
general normal is left out, so scenes where a probe touches without pressing into the table
(poke) are not measured. ``--membrane 0`` runs the solver as it is, for comparison.
``--cg K`` solves the coupled system (without the table) by K conjugate-gradient
iterations preconditioned by the bending system alone, per coordinate, instead.
Prints the elastica table of bench/bench_cantilever.py, or a scenario's metrics, or
(``cost``) what the coupled system costs against today's bending system on the `hanging`
sheet: factor entries and SciPy's factorisation and solve times, the unknowns of a vertex
kept together in the scalar system's minimum-degree order.
"""
from __future__ import annotations

import argparse
import os
import runpy
import sys
import time

os.environ.setdefault('NUMBA_NUM_THREADS', '1')

import numpy as np  # noqa: E402
import scipy.sparse as sparse  # noqa: E402
import scipy.sparse.linalg as sparse_linalg  # noqa: E402

from paper_sim_ros.core import build_simulator, load_scenario, run_scenario  # noqa: E402
from paper_sim_ros.core import simulator as simulator_module  # noqa: E402
from paper_sim_ros.core.scenarios import builtin_mapping, with_overrides  # noqa: E402

TABLE_PASSES = 8
"""Active-set passes for the table's z rows, at most."""


def coupled_system(simulator, rhs: np.ndarray, weight: float):
    """(M/h² + Q) ⊗ I₃ plus the held springs' membrane along their directions at the
    sub-step's start, and its right-hand side (the bending solve's plus w l0 u per end)."""
    system = simulator._bending_step.step.system.tocsr()
    vertex_count = system.shape[0]
    ends, rest = simulator._held_ends, simulator._held_rest
    edge = simulator._membrane_directions_from[ends[:, 1]] \
        - simulator._membrane_directions_from[ends[:, 0]]
    unit = edge / np.maximum(np.linalg.norm(edge, axis=1), 1e-12)[:, None]
    rows, columns, values = [], [], []
    for sign_i, first in ((1.0, ends[:, 0]), (-1.0, ends[:, 1])):
        for sign_j, second in ((1.0, ends[:, 0]), (-1.0, ends[:, 1])):
            for a in range(3):
                for b in range(3):
                    rows.append(3 * first + a)
                    columns.append(3 * second + b)
                    values.append(sign_i * sign_j * weight * unit[:, a] * unit[:, b])
    membrane = sparse.coo_matrix(
        (np.concatenate(values), (np.concatenate(rows), np.concatenate(columns))),
        shape=(3 * vertex_count, 3 * vertex_count))
    matrix = (sparse.kron(system, sparse.identity(3)) + membrane).tocsr()
    right = rhs.reshape(-1).copy()
    for a in range(3):
        np.add.at(right, 3 * ends[:, 1] + a, weight * rest * unit[:, a])
        np.add.at(right, 3 * ends[:, 0] + a, -weight * rest * unit[:, a])
    return matrix, right


def solve_held(matrix, right: np.ndarray, held: np.ndarray, values: np.ndarray) -> np.ndarray:
    """The unknowns not ``held`` solved for, the held ones at ``values``."""
    free = ~held
    solution = values.copy()
    solution[free] = sparse_linalg.spsolve(
        matrix[free][:, free].tocsc(), right[free] - matrix[free][:, held] @ values[held])
    return solution


def conjugate_gradients(simulator, matrix, right: np.ndarray, positions: np.ndarray,
                        iterations: int) -> None:
    """``iterations`` of conjugate gradients on the coupled system from ``positions``,
    preconditioned per coordinate by the bending system M/h² + Q alone (factored once per
    factor of the simulator's; pins held, no table)."""
    step = simulator._bending_step.step
    free = ~simulator.sheet.pinned
    if getattr(simulator, '_membrane_preconditioned', None) is not step:
        simulator._membrane_preconditioner = sparse_linalg.splu(
            step.system[free][:, free].tocsc())
        simulator._membrane_preconditioned = step
    preconditioner = simulator._membrane_preconditioner

    def precondition(residual):
        out = np.zeros_like(residual)
        out[free] = preconditioner.solve(residual[free])
        return out
    solution = positions.copy()
    residual = (right - matrix @ solution.reshape(-1)).reshape(-1, 3)
    residual[~free] = 0.0
    direction = precondition(residual)
    along = float(np.sum(residual * direction))
    for _ in range(iterations):
        product = (matrix @ direction.reshape(-1)).reshape(-1, 3)
        product[~free] = 0.0
        step_length = along / float(np.sum(direction * product))
        solution += step_length * direction
        residual -= step_length * product
        preconditioned = precondition(residual)
        next_along = float(np.sum(residual * preconditioned))
        direction = preconditioned + (next_along / along) * direction
        along = next_along
    positions[:] = solution


def membrane_bending_solve(weight: float, iterations: int = 0):
    """A replacement for ``Simulator._bending_solve`` with the membrane of ``weight`` [N/m],
    solved directly, or (``iterations``, without the table) by conjugate gradients."""
    def bending_solve(self, rhs, positions, mass_over_h2) -> None:
        vertex_count = positions.shape[0]
        matrix, right = coupled_system(self, rhs, weight)
        if iterations and not self.config.contact.ground_enabled:
            conjugate_gradients(self, matrix, right, positions, iterations)
            return
        values = positions.reshape(-1).copy()
        held = np.zeros(3 * vertex_count, dtype=bool)
        pinned = self.sheet.pinned | self._grip_pinned
        held[np.repeat(pinned, 3)] = True
        vertex, direction, value = self._rows
        for row in range(vertex.size):  # grips (axis rows); contact rows are left out
            axis = int(np.argmax(np.abs(direction[row])))
            if abs(direction[row, axis]) > 0.999:
                held[3 * vertex[row] + axis] = True
                values[3 * vertex[row] + axis] = value[row] / direction[row, axis]
        contact = self.config.contact
        if not contact.ground_enabled:
            positions[:] = solve_held(matrix, right, held, values).reshape(vertex_count, 3)
            return
        ground = contact.ground_height
        eligible = ~pinned
        eligible[vertex] = False
        on_table = eligible & (self._table_reaction > 0.0)
        z_index = 3 * np.arange(vertex_count) + 2
        for _ in range(TABLE_PASSES):
            held_now = held.copy()
            held_now[z_index[on_table]] = True
            values[z_index[on_table]] = ground
            solution = solve_held(matrix, right, held_now, values)
            push = (matrix @ solution - right)[z_index]
            pulling = on_table & (push < 0.0)
            below = eligible & ~on_table & (solution[z_index] < ground - 1e-6)
            if not (pulling.any() or below.any()):
                break
            on_table = (on_table & ~pulling) | below
        positions[:] = solution.reshape(vertex_count, 3)
        self._table_reaction[:] = 0.0
        self._table_reaction[on_table] = np.maximum(push[on_table], 0.0)
    return bending_solve


def patch(weight: float, iterations: int = 0) -> None:
    """Patch the simulator's bending solve (and note each sub-step's starting positions)."""
    if weight <= 0.0:
        return
    substep = simulator_module.Simulator._substep

    def noting_substep(self, h, probe_from, probe_to):
        self._membrane_directions_from = self.sheet.positions.copy()
        return substep(self, h, probe_from, probe_to)
    simulator_module.Simulator._substep = noting_substep
    simulator_module.Simulator._bending_solve = membrane_bending_solve(weight, iterations)


def cost(grid: int, weight: float) -> None:
    """The coupled system's factor against the bending system's, on a hanging sheet."""
    simulator = build_simulator(load_scenario('hanging', grid=grid, duration=0.1))
    simulator.step_frame()
    simulator._membrane_directions_from = simulator.sheet.positions.copy()
    system = simulator._bending_step.step.system
    free = ~simulator.sheet.pinned
    scalar = system[free][:, free].tocsc()
    order = sparse_linalg.splu(scalar, permc_spec='MMD_AT_PLUS_A', diag_pivot_thresh=0.0,
                               options={'SymmetricMode': True}).perm_c
    by_position = np.argsort(order)  # the vertices in elimination order
    rhs = np.zeros((system.shape[0], 3))
    coupled, _ = coupled_system(simulator, rhs, weight)
    unknowns = (3 * np.flatnonzero(free)[by_position][:, None] + np.arange(3)).reshape(-1)
    for name, matrix, columns in (
            ('bending (V, three right-hand sides)', scalar[by_position][:, by_position], 3),
            ('coupled (3V, one right-hand side)', coupled[unknowns][:, unknowns], 1)):
        started = time.perf_counter()
        factor = sparse_linalg.splu(matrix.tocsc(), permc_spec='NATURAL',
                                    diag_pivot_thresh=0.0, options={'SymmetricMode': True})
        factorised = time.perf_counter() - started
        right = np.random.default_rng(0).random((matrix.shape[0], columns))
        best = np.inf
        for _ in range(20):
            started = time.perf_counter()
            factor.solve(right)
            best = min(best, time.perf_counter() - started)
        print(f'{grid}² {name}: {factor.L.nnz} factor entries, factorised in '
              f'{1e3 * factorised:.0f} ms, a solve {1e3 * best:.2f} ms (SciPy)')


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('what', help="'cantilever', or a built-in scenario")
    parser.add_argument('--membrane', type=float, default=60.0, help='w [N/m]; 0: as built')
    parser.add_argument('--grid', type=int, default=33)
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--substeps', type=int, default=None)
    parser.add_argument('--duration', type=float, default=None, help='[s] (the scenario\'s)')
    parser.add_argument('--no-damage', action='store_true')
    parser.add_argument('--cg', type=int, default=0,
                        help='conjugate-gradient iterations a solve instead of the direct '
                             'solve (no table: cantilever, hanging)')
    arguments, rest = parser.parse_known_args()
    if arguments.what == 'cost':
        cost(arguments.grid, arguments.membrane or 60.0)
        return
    patch(arguments.membrane, arguments.cg)
    if arguments.what == 'cantilever':
        sys.argv = ['bench_cantilever.py'] + rest
        runpy.run_path(os.path.join(os.path.dirname(__file__), 'bench_cantilever.py'),
                       run_name='__main__')
        return
    mapping = with_overrides(builtin_mapping(arguments.what), grid=arguments.grid,
                             seed=arguments.seed, duration=arguments.duration)
    if arguments.substeps:
        mapping['solver'] = {**(mapping.get('solver') or {}), 'substeps': arguments.substeps}
    if arguments.no_damage:
        mapping['damage'] = {'enabled': False}
    started = time.perf_counter()
    metrics = run_scenario(load_scenario(mapping))
    print(f"{arguments.what} {arguments.grid}² seed {arguments.seed} membrane "
          f"{arguments.membrane:g} N/m: max strain {100 * metrics['max_strain']:.2f} %, "
          f"breaks {metrics.get('breaks')}, folds {metrics.get('folds')}, relaxed "
          f"{1e3 * metrics['relaxed_deviation_m']:.2f} mm, in a probe "
          f"{1e3 * metrics['max_probe_penetration_m']:.2f} mm, under the table "
          f"{1e3 * metrics['max_table_penetration_m']:.2f} mm, "
          f"{time.perf_counter() - started:.0f} s")


if __name__ == '__main__':
    main()
