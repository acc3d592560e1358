"""Measuring a sheet: mesh validity, crease ridges, flatness, and the headless runner's
test of whether damage stayed (the sheet is let go and relaxes; a creased sheet stays
bumpy, an undamaged one springs back flat).
"""
from __future__ import annotations

from dataclasses import replace
import math

import numpy as np

from .sheet import Sheet
from .simulator import Simulator
from .topology import check_mesh, vertex_normals


def mesh_problems(sheet: Sheet) -> list[str]:
    """Every SPEC §4.4 invariant that fails on ``sheet`` (empty: valid)."""
    return check_mesh(sheet.triangles, sheet.vertex_count, sheet.positions,
                      sheet.spring_vertices, spring_kind=sheet.spring_kind)


def ridge_heights(positions: np.ndarray, creases: list[tuple[int, int, int]]) -> np.ndarray:
    """Height of every crease's ridge vertex m over the midpoint of its ends i, j [m]."""
    if not creases:
        return np.zeros(0)
    i, m, j = np.asarray(creases, dtype=np.int64).T
    return np.linalg.norm(positions[m] - 0.5 * (positions[i] + positions[j]), axis=1)


def plane_deviation(positions: np.ndarray) -> float:
    """RMS distance of the points from their least-squares plane [m]."""
    centred = positions - positions.mean(axis=0)
    _, singular, _ = np.linalg.svd(centred, full_matrices=False)
    return float(singular[-1] / math.sqrt(len(positions)))


def relax(simulator: Simulator, seconds: float = 3.0, air_damping: float = 3.0,
          jitter: float = 1e-9) -> Simulator:
    """A free, damped copy of ``simulator`` after ``seconds`` of relaxation: gravity,
    table, probes and pins off, damage off (the damage already done stays in the mesh, and
    the bending rest shape, creases and plastic set included, is the original's),
    velocities zeroed, air drag ``air_damping`` [1/s]. The original is untouched.

    The vertices start displaced by a seeded random ``jitter`` [m] out of their plane: a
    creased sheet pressed exactly flat (by the table) sits in an unstable equilibrium
    that only in-plane forces can never leave; any real disturbance lets it pop up. An
    undamaged sheet is stable when flat and the jitter dies away."""
    config = simulator.config
    relaxed_config = replace(
        config,
        solver=replace(config.solver, gravity=(0.0, 0.0, 0.0), air_damping=air_damping),
        contact=replace(config.contact, ground_enabled=False),
        damage=replace(config.damage, enabled=False))
    sheet = simulator.sheet.copy()
    sheet.velocities[:] = 0.0
    sheet.pinned[:] = False
    noise = np.random.default_rng([config.seed, 0x5E7]).uniform(-1.0, 1.0, sheet.vertex_count)
    sheet.positions += jitter * noise[:, None] * vertex_normals(sheet.positions, sheet.triangles)
    relaxed = Simulator(relaxed_config, initial_sheet=sheet)
    relaxed.take_rest_shape(simulator)  # what the sheet remembers, not how it lies now
    for _ in range(int(round(seconds / config.solver.dt))):
        relaxed.step_frame()
    return relaxed


def relaxed_deviation(simulator: Simulator, seconds: float = 3.0) -> float:
    """RMS distance from the best-fit plane after ``relax`` [m]: ~0 for a sheet that
    springs back flat, millimetres for one that kept its creases."""
    return plane_deviation(relax(simulator, seconds).sheet.positions)


def damage_metrics(simulator: Simulator, relax_seconds: float = 3.0) -> dict:
    """The damage metrics of a run: ``breaks``, ``folds``, ``mesh_valid``,
    ``mesh_problems`` and ``relaxed_deviation_m`` (after ``relax_seconds`` of ``relax``)."""
    problems = mesh_problems(simulator.sheet)
    return {
        'breaks': int(simulator.breaks),
        'folds': int(simulator.folds),
        'mesh_valid': not problems,
        'mesh_problems': problems,
        'relaxed_deviation_m': relaxed_deviation(simulator, relax_seconds),
    }
