"""Compile (and cache on disk) every numba kernel before anything is timed.

``make setup`` runs ``python -m paper_sim_ros.warmup`` once, so the first timer tick of
the node and the first frame of a benchmark load compiled kernels instead of compiling.
"""
from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sparse

from .core import (AppearanceConfig, ContactConfig, SheetConfig, SimulationConfig, Simulator,
                   SolverConfig)
from .core.appearance import PaperAppearance
from .core.camera import CameraConfig, render
from .core.config import SOLVERS
from .core.sparse_ldl import ldl_factor
from .core.topology import spring_end_points


def warm_up() -> float:
    """Step a tiny sheet with every solver, a probe, the table and damage, and shade it;
    returns seconds taken."""
    started = time.perf_counter()
    # the 'constrained' solver twice: with the membrane (core/membrane.py) and without
    for method, membrane_weight in [(method, 0.0) for method in SOLVERS] \
            + [('constrained', 1.0)]:
        simulator = Simulator(SimulationConfig(
            sheet=SheetConfig(nx=5, ny=5),
            solver=SolverConfig(method=method, membrane_weight=membrane_weight),
            contact=ContactConfig(ground_enabled=True)))
        pinned = np.zeros(simulator.sheet.vertex_count, dtype=bool)
        pinned[0] = True
        simulator.set_pinned(pinned)
        simulator.set_probes(np.array([[0.0, 0.0, 0.01]]), np.array([0.02]), np.array([True]))
        simulator.step_frame()
        simulator.max_strain()
        simulator.energy()
        simulator.max_table_penetration()
        simulator.crumple(2, 0)
        simulator.step_frame()
    # a factor in a kept elimination order (a grip or sub-step length change, a reset)
    ldl_factor(sparse.identity(2, format='csc'), np.arange(2))
    # the appearance kernels (the node shades every published frame)
    sheet = simulator.sheet
    colors = PaperAppearance(AppearanceConfig(texture_size=16), sheet).vertex_colors(sheet)
    # what a recording and the markers draw of the springs
    spring_end_points(sheet.positions, sheet.spring_vertices, sheet.spring_kind, 0)
    # the camera's rasteriser and ray caster
    render(CameraConfig(width=8, height=6), sheet.positions, sheet.triangles, sheet.material,
           simulator.damage_labels(), colors, np.zeros((1, 3)), np.ones(1),
           np.ones(1, dtype=bool), 0.0)
    return time.perf_counter() - started


def main() -> None:
    print(f'paper_sim_ros: numba kernels ready ({warm_up():.1f} s)')


if __name__ == '__main__':
    main()
