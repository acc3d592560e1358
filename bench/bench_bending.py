"""The bending's per-hinge and per-patch kernels (core/bending.py, core/patches.py), each
timed alone on a sheet where they have work: an aged sheet (every patch curved) and a
crumpled one (curved hinges, many near their yield).

    .venv/bin/python bench/bench_bending.py [--grid 65] [--repeats 100]

Single thread, kernels compiled before timing; prints milliseconds a call (the best of
three rounds of ``--repeats`` calls). To compare two trees, run this file from either with
PYTHONPATH set to the tree. A script that prints figures, not a test.
"""
from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault('NUMBA_NUM_THREADS', '1')

import numpy as np  # noqa: E402

from paper_sim_ros.core import bending, build_simulator, load_scenario, patches  # noqa: E402

STATES = (('aged', 0.5), ('crumple', 1.0))
"""Built-in scenario and the simulated time [s] its sheet is taken at."""


def best_ms(call, repeats: int) -> float:
    call()
    rounds = []
    for _ in range(3):
        started = time.perf_counter()
        for _ in range(repeats):
            call()
        rounds.append((time.perf_counter() - started) / repeats)
    return 1e3 * min(rounds)


def kernels(simulator) -> dict:
    """name -> a call of that kernel on the simulator's sheet (outputs into copies)."""
    model = simulator._bending
    positions = simulator.sheet.positions
    yield_curvature = simulator.config.damage.yield_curvature
    rhs = np.zeros_like(positions)
    hinge_args = (positions, model.quads, model.weights, model._hinge_stiffness)
    patch_args = (positions, model.stencil, model.rows, model.tangents)
    every_patch = model._patches
    return {
        'yield_hinges': lambda: bending.yield_hinges(
            *hinge_args, model.rest_curvature.copy(), yield_curvature),
        'add_bending_targets': lambda: bending.add_bending_targets(
            *hinge_args, model.rest_curvature, model._curved, rhs),
        'bending_energy': lambda: bending.bending_energy(*hinge_args, model.rest_curvature),
        'hinge_rest_state': lambda: bending.hinge_rest_state(
            positions, model.quads, 1.0, model.weights.copy(), model._hinge_stiffness.copy(),
            model.rest_curvature.copy()),
        'add_patch_targets': lambda: patches.add_patch_targets(
            *patch_args, model.patch_weight, model.patch_rest, model._curved_patches, rhs),
        'patch_energy': lambda: patches.patch_energy(
            *patch_args, model.patch_weight, model.patch_rest, every_patch),
        'patch_rest_state': lambda: patches.patch_rest_state(
            *patch_args, every_patch, model.patch_rest.copy()),
        'patches_beyond': lambda: patches.patches_beyond(
            *patch_args, model.patch_rest, every_patch, yield_curvature),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--grid', type=int, default=65)
    parser.add_argument('--repeats', type=int, default=100)
    args = parser.parse_args(argv)
    print('| sheet | curved hinges | curved patches | kernel | ms a call |')
    print('|---|---|---|---|---|')
    for name, seconds in STATES:
        scenario = load_scenario(name, grid=args.grid, seed=0, duration=seconds)
        simulator = build_simulator(scenario)
        for frame in range(scenario.frame_count):
            simulator.set_probes(*scenario.probe_inputs((frame + 1) * scenario.config.solver.dt))
            simulator.step_frame()
        model = simulator._bending
        for kernel, call in kernels(simulator).items():
            milliseconds = best_ms(call, args.repeats)
            print(f'| {name} {args.grid}² at {seconds:g} s | {model._curved.size} '
                  f'| {model._curved_patches.size} | {kernel} | {milliseconds:.3f} |')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
