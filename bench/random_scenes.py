"""Random scenes no test names: how the core holds up outside the built-in scenarios.

    .venv/bin/python bench/random_scenes.py [--family table pinned poke wild] [--count 40]
        [--start 0] [--jobs 2] [--time-limit 200] [--membrane 30] [--no-sleep]

Each run is drawn from its index alone (reproducible): a sheet of random size (0.1-0.3 m)
and grid (17-65 a side, cells near square), a random material, sub-step count, seed and
damage on or off, and one of four families:

- ``table``: one or two fingertips (5-30 mm) land on a sheet lying on the table, press it
  up to 4 mm into the table, drag it up to 12 cm at 2-30 cm/s and lift off;
- ``pinned``: the same with the sheet's short edge pinned;
- ``poke``: a probe (5-30 mm) pushes up to 4 cm into a hanging sheet at 5-50 cm/s, sweeps
  across it and withdraws (a table below or not);
- ``wild``: anything the scenario format accepts: probes appearing anywhere, inside the
  sheet or the table, at any speed, 3-47 vertices a side, crumples, aged surfaces, odd
  gravity, other frame steps, the solver's switches and membrane. Its strains mean little; it is
  there to find exceptions, non-finite states, invalid meshes and runs that stall.

Per run: max HINGE strain, breaks, folds, deepest vertex in a probe (pinned vertices
included) and under the table, and anything wrong (an exception other than a refused
scenario, NaN, an invalid mesh, mass not conserved, over ``--time-limit`` seconds); and
what the probe nearest the worst spring was doing in the frame of the run's largest strain
(``peak_kind``): moving ``towards`` what else holds the sheet (the pins, else the other
fingertip pressing it onto the table) and so pushing paper together, ``away`` from it and
so pulling the paper behind, ``across`` it, moving on a sheet nothing else holds
(``free``), ``still``, or no probe near (``none``). Then per family the spread of the max
strain, and the kinds of the runs beyond 2 %. A script that prints figures, not a test.
"""
from __future__ import annotations

import argparse
import collections
from concurrent.futures import ProcessPoolExecutor
import math
import os
import signal
import time
import traceback

os.environ.setdefault('NUMBA_NUM_THREADS', '1')

import numpy as np  # noqa: E402

from paper_sim_ros.core import load_scenario, run_scenario  # noqa: E402
from paper_sim_ros.core.runner import build_simulator  # noqa: E402
from paper_sim_ros.core.sheet import HINGE  # noqa: E402

FAMILIES = ('table', 'pinned', 'poke', 'wild')
MATERIALS = ('printer_paper', 'cardboard', 'banknote')


def _sheet_and_settings(rng: np.random.Generator) -> dict:
    width, height = rng.uniform(0.1, 0.3, 2)
    nx = int(rng.integers(17, 66))
    mapping = {'name': 'random', 'seed': int(rng.integers(0, 1000)),
               'sheet': {'width': float(width), 'height': float(height), 'nx': nx,
                         'ny': max(5, int(round(nx * height / width)))},
               'solver': {'substeps': int(rng.choice([1, 1, 2, 4]))},
               'damage': {'enabled': bool(rng.random() < 0.7)}, 'contact': {}}
    if rng.random() < 0.25:
        mapping['material'] = str(rng.choice(MATERIALS))
    return mapping


def _fingertips_on_table(rng: np.random.Generator, pinned: bool) -> dict:
    mapping = _sheet_and_settings(rng)
    width, height = mapping['sheet']['width'], mapping['sheet']['height']
    mapping.update(pin='short_edge' if pinned else 'none', probes=[])
    mapping['contact']['ground_enabled'] = True
    end = 0.0
    for index in range(int(rng.integers(1, 3))):
        radius, press = float(rng.uniform(0.005, 0.03)), float(rng.uniform(0.0, 0.004))
        x0, y0 = float(rng.uniform(-0.4, 0.4) * width), float(rng.uniform(-0.4, 0.4) * height)
        heading, travel = rng.uniform(0.0, 2.0 * math.pi), float(rng.uniform(0.0, 0.12))
        x1, y1 = x0 + travel * math.cos(heading), y0 + travel * math.sin(heading)
        landed = float(rng.uniform(0.5, 0.9))
        stopped = landed + travel / float(rng.uniform(0.02, 0.3))
        mapping['probes'].append({'name': f'finger_{index}', 'radius': radius, 'keyframes': [
            [0.0, x0, y0, radius + 0.03], [landed, x0, y0, radius - press],
            [stopped, x1, y1, radius - press], [stopped + 0.4, x1, y1, radius + 0.03]]})
        end = max(end, stopped + 0.4)
    mapping['duration'] = end + 0.5
    return mapping


def _poke(rng: np.random.Generator) -> dict:
    mapping = _sheet_and_settings(rng)
    width, height = mapping['sheet']['width'], mapping['sheet']['height']
    elevation = float(rng.uniform(0.3, 0.5))
    mapping.update(pin='short_edge')
    mapping['sheet']['elevation'] = elevation
    mapping['contact']['ground_enabled'] = bool(rng.random() < 0.5)
    # the sheet hangs in the plane y = -height/2 below its pinned edge
    plane = -0.5 * height - 0.001
    radius, speed = float(rng.uniform(0.005, 0.03)), float(rng.uniform(0.05, 0.5))
    depth, side = float(rng.uniform(0.0, 0.04)), float(rng.choice([-1.0, 1.0]))
    z = elevation - float(rng.uniform(0.2, 0.8)) * height
    x0, x1 = rng.uniform(-0.3, 0.3, 2) * width
    away = [float(x0), plane + side * (radius + 0.03), z]
    pushed = plane - side * (depth - radius)
    arrive = 1.5 + (0.03 + depth) / speed
    swept = arrive + abs(x1 - x0) / speed + 0.05
    mapping['probes'] = [{'name': 'probe', 'radius': radius, 'keyframes': [
        [1.5, *away], [arrive, float(x0), pushed, z], [swept, float(x1), pushed, z],
        [swept + 0.4, *away]]}]
    mapping['duration'] = swept + 0.9
    return mapping


def _wild(rng: np.random.Generator) -> dict:
    width, height = (float(v) for v in rng.uniform(0.03, 0.5, 2))
    elevation = float(rng.choice([0.0, 0.002, 0.05, 0.3]))
    mapping = {'name': 'random', 'duration': float(rng.uniform(0.3, 2.0)),
               'seed': int(rng.integers(0, 1000)), 'pin': str(rng.choice(['none', 'short_edge'])),
               'sheet': {'width': width, 'height': height, 'nx': int(rng.integers(3, 48)),
                         'ny': int(rng.integers(3, 48)), 'elevation': elevation},
               'solver': {'substeps': int(rng.choice([1, 1, 2, 4])),
                          'dt': float(rng.choice([1 / 60, 1 / 60, 1 / 30, 1 / 120])),
                          'length_projection': bool(rng.random() < 0.15),
                          'energy_restoring': bool(rng.random() < 0.15)},
               'contact': {'ground_enabled': bool(rng.random() < 0.6)},
               'damage': {'enabled': bool(rng.random() < 0.7)}}
    if rng.random() < 0.3:
        mapping['material'] = str(rng.choice(MATERIALS))
    if rng.random() < 0.2:
        mapping['solver']['gravity'] = [float(v) for v in rng.normal(0.0, 5.0, 3)]
    if rng.random() < 0.2:
        mapping['crumple'] = int(rng.integers(1, 400))
    if rng.random() < 0.15:
        mapping['aged'] = {'amplitude': float(rng.uniform(0.0, 0.02))}
    mapping['probes'] = []
    for index in range(int(rng.choice([0, 1, 1, 2, 3]))):
        radius = float(rng.choice([0.002, 0.005, 0.01, 0.015, 0.03, 0.08]))
        times = np.unique(np.sort(rng.uniform(0.0, mapping['duration'], int(rng.integers(1, 5)))))
        mapping['probes'].append({'name': f'probe_{index}', 'radius': radius, 'keyframes': [
            [float(t), float(rng.uniform(-0.6, 0.6) * width),
             float(rng.uniform(-0.6, 0.6) * height),
             float(rng.choice([elevation + 0.5 * radius, elevation - radius, 0.9 * radius,
                               elevation + radius + 0.01, rng.uniform(-0.05, 0.4)]))]
            for t in times]})
    if rng.random() < 0.3:
        mapping['contact']['probe_friction'] = float(rng.uniform(0.0, 1.5))
    if rng.random() < 0.2:  # drawn last: the earlier draws of an index stay as they were
        mapping['solver']['membrane_weight'] = float(rng.choice([0.5, 30.0, 3000.0]))
        mapping['solver']['membrane_scope'] = str(rng.choice(['squeezed', 'always']))
    return mapping


def scene(family: str, index: int) -> dict:
    """The scenario mapping of run ``index`` of ``family``."""
    rng = np.random.default_rng([FAMILIES.index(family), index])
    if family == 'poke':
        return _poke(rng)
    if family == 'wild':
        return _wild(rng)
    return _fingertips_on_table(rng, pinned=family == 'pinned')


PEAK_HEADING = 0.5
"""A probe heads ``towards`` (``away`` from) what holds the sheet where the cosine of its
motion with the direction to it is above this (below minus this); ``across`` between."""
PEAK_STILL = 1e-3
"""[m/s] A probe slower than this stands ``still``."""


def peak_kind(simulator, start: np.ndarray) -> str:
    """What the active probe nearest the worst HINGE spring did in the frame just stepped,
    from ``start`` (the probes' centres at its start) to where they are (the module's
    docstring)."""
    sheet, probes = simulator.sheet, simulator.probes
    hinge = np.flatnonzero(sheet.spring_kind == HINGE)
    worst = hinge[np.argmax(np.abs(sheet.strain(HINGE)))]
    middle = sheet.positions[sheet.spring_vertices[worst]].mean(axis=0)
    active = np.flatnonzero(probes.active)
    if active.size == 0:
        return 'none'
    probe = active[np.argmin(np.linalg.norm(probes.end[active] - middle, axis=1))]
    motion = (probes.end[probe] - start[probe])[:2]
    if np.linalg.norm(motion) < PEAK_STILL * simulator.config.solver.dt:
        return 'still'
    ground = simulator.config.contact.ground_height
    pressing = [p for p in active if p != probe
                and probes.end[p, 2] - probes.radius[p] < ground]
    if np.any(sheet.pinned):
        holder = sheet.positions[sheet.pinned].mean(axis=0)
    elif pressing:
        holder = probes.end[pressing[0]]
    else:
        return 'free'
    towards = (holder - probes.end[probe])[:2]
    cosine = float(np.dot(motion, towards)
                   / (np.linalg.norm(motion) * np.linalg.norm(towards) + 1e-300))
    return 'towards' if cosine > PEAK_HEADING else 'away' if cosine < -PEAK_HEADING \
        else 'across'


class _TooSlow(Exception):
    pass


def _alarm(signum, frame):
    raise _TooSlow()


def measure(family: str, index: int, time_limit: int, membrane: float | None = None,
            sleep: bool = True) -> dict:
    """One run (``membrane``: the membrane's weight in every sub-step, None: the scene's
    own; ``sleep``: False, the sheet never sleeps): its figures, or what went wrong."""
    mapping = scene(family, index)
    if membrane is not None:
        mapping['solver'] = {**(mapping.get('solver') or {}), 'membrane_weight': membrane,
                             'membrane_scope': 'always'}
    if not sleep:
        mapping['solver'] = {**(mapping.get('solver') or {}), 'sleep_speed': 0.0}
    record = {'family': family, 'index': index, 'problems': []}
    signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(time_limit)
    started = time.perf_counter()
    try:
        scenario = load_scenario(mapping)
        simulator = build_simulator(scenario)
        mass = simulator.sheet.total_mass
        peak = {'strain': -1.0, 'kind': 'none', 'start': simulator.probes.end.copy()}

        def on_frame(simulator, seconds) -> None:
            strain = simulator.max_strain()
            if strain > peak['strain'] and peak['start'].shape == simulator.probes.end.shape:
                peak.update(strain=strain, kind=peak_kind(simulator, peak['start']))
            peak['start'] = simulator.probes.end.copy()
        metrics = run_scenario(scenario, simulator=simulator, on_frame=on_frame)
        record.update(strain=metrics['max_strain'], breaks=metrics['breaks'],
                      folds=metrics['folds'], in_probe=metrics['max_probe_penetration_m'],
                      below_table=metrics['max_table_penetration_m'],
                      asleep=metrics['frames_asleep'] / max(metrics['steps'], 1),
                      peak=peak['kind'])
        if metrics['nan']:
            record['problems'].append('non-finite state')
        if not metrics['mesh_valid']:
            record['problems'].append(f'invalid mesh: {metrics["mesh_problems"][:2]}')
        if abs(metrics['total_mass'] - mass) > 1e-12 * mass:
            record['problems'].append(f'mass {mass} -> {metrics["total_mass"]}')
    except ValueError as error:  # a scenario the format refuses, with its reason
        record['refused'] = str(error)
    except _TooSlow:
        record['problems'].append(f'over {time_limit} s')
    except Exception:  # noqa: BLE001 (what this script is for)
        record['problems'].append(traceback.format_exc(limit=-3))
    finally:
        signal.alarm(0)
    record['seconds'] = time.perf_counter() - started
    return record


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--family', nargs='+', default=['table', 'pinned', 'poke'],
                        choices=FAMILIES)
    parser.add_argument('--count', type=int, default=40, help='runs per family')
    parser.add_argument('--start', type=int, default=0, help='first run index')
    parser.add_argument('--jobs', type=int, default=1)
    parser.add_argument('--time-limit', type=int, default=200, help='seconds a run may take')
    parser.add_argument('--membrane', type=float, default=None,
                        help="the membrane at this weight in every sub-step of every run "
                        "(membrane_scope 'always'; 0: none)")
    parser.add_argument('--no-sleep', action='store_true',
                        help='solver.sleep_speed 0 in every run: the sheet never sleeps')
    args = parser.parse_args()
    runs = [(family, index, args.time_limit, args.membrane, not args.no_sleep)
            for family in args.family for index in range(args.start, args.start + args.count)]
    records = []
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        for record in pool.map(measure, *zip(*runs)):
            records.append(record)
            figures = (f"strain {100 * record['strain']:8.2f} %  breaks {record['breaks']:4d}  "
                       f"folds {record['folds']:5d}  in probe {1e3 * record['in_probe']:6.2f} mm  "
                       f"below table {1e3 * record['below_table']:5.2f} mm  "
                       f"asleep {record['asleep']:4.0%}  peak {record['peak']:7s}"
                       if 'strain' in record else f"refused: {record.get('refused', '')}")
            print(f"{record['family']:7s} {record['index']:4d}  {figures}  "
                  f"{record['seconds']:6.1f} s  {'; '.join(record['problems'])}", flush=True)
    print('per family')
    for family in args.family:
        ran = [r for r in records if r['family'] == family and 'strain' in r]
        wrong = [r['index'] for r in records if r['family'] == family and r['problems']]
        if not ran:
            continue
        strain = np.array([r['strain'] for r in ran])
        print(f'{family:7s} {len(ran)} runs: max strain median {100 * np.median(strain):.2f} %, '
              f'90th percentile {100 * np.percentile(strain, 90):.1f} %, '
              f'worst {100 * strain.max():.1f} %, under 2 %: {np.sum(strain < 0.02)}; '
              f'runs with a problem: {wrong or "none"}')
        kinds = collections.Counter(r['peak'] for r in ran if r['strain'] >= 0.02)
        if kinds:
            print(f'{"":7s} beyond 2 %, the peak: '
                  + ', '.join(f'{kind} {count}' for kind, count in kinds.most_common()))


if __name__ == '__main__':
    main()
