"""The held springs' membrane in the bending solve (core/membrane.py): its terms, and the
conjugate gradients against a direct solve of the coupled system under constraint rows."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sparse
import scipy.sparse.linalg as sparse_linalg

from paper_sim_ros.core import (ContactConfig, DamageConfig, SheetConfig, SimulationConfig,
                                Simulator, SolverConfig, build_simulator, load_scenario,
                                run_scenario)
from paper_sim_ros.core.membrane import (Membrane, add_membrane_product, add_membrane_rhs,
                                         membrane_weights)
from paper_sim_ros.core.scenarios import builtin_mapping, with_overrides


def membrane_energy(membrane: Membrane, positions: np.ndarray) -> float:
    ends, unit = membrane.ends, membrane.unit
    along = np.einsum('ea,ea->e', unit, positions[ends[:, 1]] - positions[ends[:, 0]])
    return 0.5 * float(np.sum(membrane.weight * (along - membrane.rest_length) ** 2))


def bent_simulator(grid: int = 13) -> Simulator:
    """A sheet pinned along one edge that has swung for a few frames (bent, its edges
    turned), its bending factored."""
    simulator = Simulator(SimulationConfig(
        sheet=SheetConfig(nx=grid, ny=grid, width=0.2, height=0.2),
        solver=SolverConfig(membrane_weight=30.0),
        contact=ContactConfig(ground_enabled=False), damage=DamageConfig(enabled=False)))
    along = simulator.sheet.material[:, 1]
    simulator.set_pinned(along <= along.min() + 1e-9)
    for _ in range(6):
        simulator.step_frame()
    return simulator


def test_the_membrane_terms_are_its_energys_gradient():
    """H x − b of add_membrane_product and add_membrane_rhs is ∇ ½ Σ w (uᵀ(x_j − x_i) − l0)²
    (central differences), and the energy is zero for the edges at their rest lengths
    along u, whatever else moves across them."""
    simulator = bent_simulator(7)
    sheet = simulator.sheet
    rng = np.random.default_rng(4)
    membrane = Membrane(simulator._held_ends, simulator._held_rest,
                        simulator._membrane_weight, sheet.positions)
    assert np.all(membrane.weight > 0.0)
    assert membrane_energy(membrane, sheet.positions) == pytest.approx(
        0.5 * np.sum(membrane.weight * (np.linalg.norm(
            sheet.positions[membrane.ends[:, 1]] - sheet.positions[membrane.ends[:, 0]],
            axis=1) - membrane.rest_length) ** 2), rel=1e-9)
    x = sheet.positions + 1e-3 * rng.standard_normal(sheet.positions.shape)
    gradient = np.zeros_like(x)
    add_membrane_product(membrane.ends, membrane.unit, membrane.weight, x, gradient)
    rhs = np.zeros_like(x)
    add_membrane_rhs(membrane.ends, membrane.unit, membrane.weight, membrane.rest_length, rhs)
    gradient -= rhs
    step = 1e-7
    for vertex, axis in ((0, 0), (10, 2), (24, 1), (48, 2)):
        plus, minus = x.copy(), x.copy()
        plus[vertex, axis] += step
        minus[vertex, axis] -= step
        numeric = (membrane_energy(membrane, plus) - membrane_energy(membrane, minus)) \
            / (2 * step)
        assert gradient[vertex, axis] == pytest.approx(numeric, rel=1e-5, abs=1e-9)


def test_the_weight_is_a_share_of_the_bending_stiffness_per_edge():
    rest = np.array([0.002, 0.004])
    assert np.allclose(membrane_weights(rest, 4e-4, 30.0), 30.0 * 4e-4 / rest ** 2)


def test_conjugate_gradients_reach_the_coupled_solution_under_the_rows():
    """From the bending solve's answer, the conjugate gradients preconditioned by the
    bending solve under rows (two probe contacts along skew normals, a vertex held on all
    three axes) reach the direct solution of the KKT system of bending ⊗ I₃ + membrane
    with those rows, the pinned edge held, and every iterate meets the rows."""
    simulator = bent_simulator()
    sheet = simulator.sheet
    positions = sheet.positions.copy()
    constrained = simulator._bending_step
    step = constrained.step
    pinned = step.pinned_mask
    vertex_count = sheet.vertex_count
    rng = np.random.default_rng(7)
    normals = rng.standard_normal((2, 3))
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    row_vertex = np.array([150, 100, 60, 60, 60])
    row_direction = np.vstack([normals, np.eye(3)])
    row_value = np.einsum('ra,ra->r', row_direction, positions[row_vertex]) \
        + 1e-3 * rng.standard_normal(5)
    rhs = (sheet.vertex_mass / (simulator.config.solver.dt ** 2))[:, None] \
        * (positions + 1e-3 * rng.standard_normal(positions.shape))
    membrane = Membrane(simulator._held_ends, simulator._held_rest,
                        simulator._membrane_weight, positions)
    solution = positions.copy()
    constrained.solve(rhs, solution, row_vertex, row_direction, row_value)
    free_values = np.zeros(5)

    def precondition(residual, out):
        constrained.solve(residual, out, row_vertex, row_direction, free_values)
    ran = membrane.solve(step.system, precondition, rhs, solution, pinned, 200)
    assert ran < 200  # stopped at its tolerance
    assert np.allclose(np.einsum('ra,ra->r', row_direction, solution[row_vertex]), row_value,
                       atol=1e-10)
    assert np.array_equal(solution[pinned], positions[pinned])

    # the direct solve: unknowns the free vertices' coordinates, then one multiplier a row
    ends, unit, weight = membrane.ends, membrane.unit, membrane.weight
    rows, columns, values = [], [], []
    for first_sign, first in ((-1.0, ends[:, 0]), (1.0, ends[:, 1])):
        for second_sign, second in ((-1.0, ends[:, 0]), (1.0, ends[:, 1])):
            for a in range(3):
                for b in range(3):
                    rows.append(3 * first + a)
                    columns.append(3 * second + b)
                    values.append(first_sign * second_sign * weight * unit[:, a] * unit[:, b])
    coupled = (sparse.kron(step.system, sparse.identity(3)) + sparse.coo_matrix(
        (np.concatenate(values), (np.concatenate(rows), np.concatenate(columns))),
        shape=(3 * vertex_count, 3 * vertex_count))).tocsr()
    right = rhs.copy()
    add_membrane_rhs(ends, unit, weight, membrane.rest_length, right)
    free = np.repeat(~pinned, 3)
    held = positions.reshape(-1)
    reduced = coupled[free][:, free]
    reduced_right = right.reshape(-1)[free] - coupled[free][:, ~free] @ held[~free]
    constraint = np.zeros((5, 3 * vertex_count))
    for r in range(5):
        constraint[r, 3 * row_vertex[r]:3 * row_vertex[r] + 3] = row_direction[r]
    constraint = sparse.csr_matrix(constraint[:, free])
    kkt = sparse.bmat([[reduced, constraint.T], [constraint, None]]).tocsc()
    direct = sparse_linalg.spsolve(kkt, np.concatenate([reduced_right, row_value]))
    expected = held.copy()
    expected[free] = direct[:free.sum()]
    expected = expected.reshape(-1, 3)
    assert np.abs(solution - expected).max() < 1e-6
    # the membrane changed the answer far beyond that: the rows' solve alone is not it
    alone = positions.copy()
    constrained.solve(rhs, alone, row_vertex, row_direction, row_value)
    assert np.abs(alone - expected).max() > 1e-4


@pytest.mark.parametrize('seed', [0, 4])
def test_a_squeezed_sheet_arches_instead_of_crushing(seed):
    """`squeeze` at 33², one sub-step, as built: the two fingertips push the sheet together
    on the table, and while they do the bending solve takes the held springs as a membrane
    (``membrane_scope`` 'squeezed'). Without it the split solve crushes the sheet
    (measured 114.9 / 230.1 % at seeds 0 / 4, 1 / 8 breaks, 60 / 102 folds); with it the
    arch carries the thrust: measured 20.1 / 22.1 %, no fold, 0 / 1 break, nothing inside
    a fingertip or the table, the mesh valid. Since the table's friction acts while the
    fingertips push and the strain band lets a gripped sheet buckle (2026-11-29): 12.2 /
    12.6 %, no fold, 0 / 2 breaks."""
    metrics = run_scenario(load_scenario(with_overrides(builtin_mapping('squeeze'), grid=33,
                                                        seed=seed)))
    assert metrics['max_strain'] < 0.25
    assert metrics['folds'] == 0 and metrics['breaks'] <= 2
    assert metrics['max_probe_penetration_m'] < 5e-4
    assert metrics['max_table_penetration_m'] < 5e-4
    assert metrics['mesh_valid'] and not metrics['nan']


def test_a_sheet_no_probe_squeezes_steps_as_without_the_membrane():
    """The membrane's scope: a hanging sheet, and one a probe pushes into and sweeps across
    without pinching it (`poke`, whole runs at 17²), step to the same bits with the
    membrane as built ('squeezed') as with none, so they pay nothing for it; in every
    sub-step ('always') the same sheet moves otherwise."""
    def final(name: str, **solver) -> np.ndarray:
        mapping = with_overrides(builtin_mapping(name), grid=17)
        mapping['solver'] = {**(mapping.get('solver') or {}), **solver}
        scenario = load_scenario(mapping)
        simulator = build_simulator(scenario)
        run_scenario(scenario, simulator=simulator)
        return simulator.sheet.positions.copy()
    for name in ('hanging', 'poke'):
        as_built = final(name)
        assert np.array_equal(as_built, final(name, membrane_weight=0.0))
        assert not np.array_equal(as_built, final(name, membrane_scope='always'))


def test_a_sheet_landing_on_the_table_with_the_membrane_stays_above_it():
    """`aged` at 33², seed 0: the wavy sheet falls 5 mm onto the table. In the sub-step it
    lands, the sheet's own torque taken out by a rigid turn (Simulator._keep_angular_
    momentum) would carry a corner into the table, more so with the membrane's forces along
    the sub-step's starting directions (0.49 mm below it, measured): a landing's turn is
    the table's. Every frame keeps every vertex above the table within 0.05 mm."""
    mapping = with_overrides(builtin_mapping('aged'), grid=33, seed=0)
    mapping['solver'] = {**(mapping.get('solver') or {}), 'membrane_weight': 30.0,
                         'membrane_scope': 'always'}
    simulator = build_simulator(load_scenario(mapping))
    for _ in range(30):
        simulator.step_frame()
        assert simulator.max_table_penetration() < 5e-5
