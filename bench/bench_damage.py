"""Damage (issue 3): what it costs per step, and the parameter sweeps of the paper's
Fig. 12–13 in numbers.

    .venv/bin/python bench/bench_damage.py cost --grid 33 65
    .venv/bin/python bench/bench_damage.py fragility --grid 33 --phi 0.5 1 2 4 8
    .venv/bin/python bench/bench_damage.py psi --grid 33 --psi 0 0.25 0.5 1 1.5
    .venv/bin/python bench/bench_damage.py substeps --grid 33 65 [--seed 0]
    .venv/bin/python bench/bench_damage.py drift --grid 65 129

cost: the built-in 'squeeze' stepped with damage on and off; ms per frame for the whole
step, and the part spent in damage (the check, the mesh surgery and the solver's rebuild
after a change); mesh changes (breaks, folds), and the rebuild's ms per change (factor
updates and the refactors they pay for, or a refactor each change); the factors' changes
outside them (patches that yield, taken in place or factored anew; a factor renewed once
its updates have cost one), and their ms each.
fragility: squeeze breaks and folds
per φ. psi: the 'crumple' scenario with breaks only (no folds), mean ridge height of the
creases and the relaxed deviation per ψ. substeps: squeeze breaks, folds, the plastic set
(hinges whose rest shape is bent) and relaxed deviation at 1, 2 and 4 sub-steps. drift: the
squeeze with every factor updated in place checked against its own system (a known x solved
for): how many changes were taken in place, how many left to the Woodbury update, the worst
forward error, the most terms a factor took.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..'))

import numpy as np  # noqa: E402

from paper_sim_ros.core import build_simulator, projective, relaxed_deviation  # noqa: E402
from paper_sim_ros.core.bending import FLAT_REST  # noqa: E402
from paper_sim_ros.core.metrics import ridge_heights  # noqa: E402
from paper_sim_ros.core.scenarios import (builtin_mapping, scenario_from_mapping,  # noqa: E402
                                          with_overrides)


def run(name: str, grid: int, damage: dict, substeps: int = 1, seed: int = 0):
    """Step a built-in scenario; returns the simulator, its frames and the seconds spent
    (``spent``: 'total'; 'damage', the checks, the mesh surgery and every rebuild they
    cause; 'rebuild' and 'changes', the rebuilds after a break or fold and how many;
    'refactor' and 'refactors', the factors' changes outside them: patches that yield, or
    a factor renewed once its updates have cost one; a grip pinned in the factors is not
    damage's)."""
    mapping = with_overrides(builtin_mapping(name), grid=grid, substeps=substeps, seed=seed)
    mapping['damage'] = damage
    scenario = scenario_from_mapping(mapping)
    simulator = build_simulator(scenario)
    spent = {'damage': 0.0, 'rebuild': 0.0, 'changes': 0, 'refactor': 0.0, 'refactors': 0,
             'depth': 0}
    advance, rebuild = simulator.damage.advance, simulator.topology_changed
    factor, grips = simulator._factor_global_steps, simulator._factor_grips

    def timed(function, *keys, count=None):
        def wrapper(*args, **kwargs):
            spent['depth'] += 1
            started = time.perf_counter()
            try:
                return function(*args, **kwargs)
            finally:
                spent['depth'] -= 1
                if spent['depth'] == 0:  # a refactor inside a rebuild counts once
                    for key in keys:
                        spent[key] += time.perf_counter() - started
                    if count:
                        spent[count] += 1
        return wrapper

    simulator.damage.advance = timed(advance, 'damage')
    simulator.topology_changed = timed(rebuild, 'damage', 'rebuild', count='changes')
    simulator._factor_global_steps = timed(factor, 'damage', 'refactor', count='refactors')
    simulator._factor_grips = timed(grips)  # its refactors are the grips', not damage's
    dt = scenario.config.solver.dt
    started = time.perf_counter()
    for frame in range(scenario.frame_count):
        simulator.set_probes(*scenario.probe_inputs((frame + 1) * dt))
        simulator.step_frame()
    spent['total'] = time.perf_counter() - started
    return simulator, scenario.frame_count, spent


def cost(grids: list[int]) -> None:
    run('squeeze', 17, {})  # warm-up: numba compilation
    print('| grid | damage | ms/frame | of which damage | mesh changes | ms per change '
          '| other refactors | ms each | breaks | folds | vertices |')
    print('|---|---|---|---|---|---|---|---|---|---|---|')
    update_limit, in_place = projective.MAX_UPDATE_VERTICES, projective.GlobalStep.updated
    for grid in grids:
        for enabled, updates in ((False, True), (True, True), (True, False)):
            # without updates (in place or by Woodbury), every mesh change factors both
            # systems afresh
            projective.MAX_UPDATE_VERTICES = update_limit if updates else 0
            projective.GlobalStep.updated = in_place if updates else lambda *args: None
            simulator, frames, spent = run('squeeze', grid, {'enabled': enabled})
            label = 'on' if updates else 'on, refactor each change'
            print(f'| {grid} | {label if enabled else "off"} '
                  f'| {1e3 * spent["total"] / frames:.2f} | {1e3 * spent["damage"] / frames:.2f} '
                  f'| {spent["changes"]} | {1e3 * spent["rebuild"] / max(spent["changes"], 1):.1f} '
                  f'| {spent["refactors"]} '
                  f'| {1e3 * spent["refactor"] / max(spent["refactors"], 1):.1f} '
                  f'| {simulator.breaks} | {simulator.folds} | {simulator.sheet.vertex_count} |')
    projective.MAX_UPDATE_VERTICES, projective.GlobalStep.updated = update_limit, in_place


def fragility(grids: list[int], phis: list[float]) -> None:
    print('| grid | φ | breaks | folds | relaxed deviation [mm] |')
    print('|---|---|---|---|---|')
    for grid in grids:
        for phi in phis:
            simulator, *_ = run('squeeze', grid, {'fragility': phi})
            print(f'| {grid} | {phi:g} | {simulator.breaks} | {simulator.folds} '
                  f'| {1e3 * relaxed_deviation(simulator):.2f} |')


def psi(grids: list[int], psis: list[float]) -> None:
    print('| grid | ψ | breaks | mean ridge height [mm] | max ridge [mm] '
          '| relaxed deviation [mm] |')
    print('|---|---|---|---|---|---|')
    for grid in grids:
        for value in psis:
            simulator, *_ = run('crumple', grid, {'area_conservation': value,
                                                  'crumple_fold_fraction': 0.0,
                                                  'fold_threshold': 0.0})
            heights = ridge_heights(simulator.sheet.positions, simulator.damage.creases)
            print(f'| {grid} | {value:g} | {simulator.breaks} | {1e3 * heights.mean():.2f} '
                  f'| {1e3 * heights.max():.2f} | {1e3 * relaxed_deviation(simulator):.2f} |')


def substeps(grids: list[int], seed: int) -> None:
    """The squeeze's damage per sub-step count, and the plastic set it leaves: the hinges
    whose rest shape is bent (by yield or by a fold) and the largest of those bends."""
    print('| grid | substeps | breaks | folds | hinges with a kept bend | largest [°] '
          '| relaxed deviation [mm] |')
    print('|---|---|---|---|---|---|---|')
    for grid in grids:
        for count in (1, 2, 4):
            simulator, *_ = run('squeeze', grid, {}, substeps=count, seed=seed)
            kept = np.linalg.norm(simulator._bending.rest_curvature, axis=1)
            print(f'| {grid} | {count} | {simulator.breaks} | {simulator.folds} '
                  f'| {np.count_nonzero(kept > FLAT_REST)} | {np.degrees(kept.max()):.1f} '
                  f'| {1e3 * relaxed_deviation(simulator):.2f} |')


def drift(grids: list[int]) -> None:
    print('| grid | in place | left to Woodbury | worst forward error | most terms a factor '
          'took | breaks | folds |')
    print('|---|---|---|---|---|---|---|')
    in_place = projective.GlobalStep.updated
    for grid in grids:
        counts = {'in place': 0, 'left': 0, 'error': 0.0, 'terms': 0}

        def checked(step, terms, pinned):
            updated = in_place(step, terms, pinned)
            if updated is None:
                counts['left'] += 1
                return None
            known = np.random.default_rng(1).standard_normal((pinned.size, 3))
            known[pinned] = 0.0
            solved = np.zeros_like(known)
            updated.solve(updated.system @ known, solved)
            counts['in place'] += 1
            counts['error'] = max(counts['error'], float(np.abs(solved - known).max()))
            counts['terms'] = max(counts['terms'], updated.terms_taken)
            return updated

        projective.GlobalStep.updated = checked
        try:
            simulator, *_ = run('squeeze', grid, {})
        finally:
            projective.GlobalStep.updated = in_place
        print(f"| {grid} | {counts['in place']} | {counts['left']} | {counts['error']:.1e} "
              f"| {counts['terms']} | {simulator.breaks} | {simulator.folds} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('what', choices=('cost', 'fragility', 'psi', 'substeps', 'drift'))
    parser.add_argument('--grid', type=int, nargs='+', default=[33])
    parser.add_argument('--phi', type=float, nargs='+', default=[0.5, 1.0, 2.0, 4.0, 8.0])
    parser.add_argument('--psi', type=float, nargs='+', default=[0.0, 0.25, 0.5, 1.0, 1.5])
    parser.add_argument('--seed', type=int, default=0, help='substeps: the squeeze\'s seed')
    args = parser.parse_args()
    if args.what == 'cost':
        cost(args.grid)
    elif args.what == 'fragility':
        fragility(args.grid, args.phi)
    elif args.what == 'psi':
        psi(args.grid, args.psi)
    elif args.what == 'substeps':
        substeps(args.grid, args.seed)
    else:
        drift(args.grid)


if __name__ == '__main__':
    main()
