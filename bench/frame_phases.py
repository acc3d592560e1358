"""Where a frame's time goes: the Simulator's passes timed one by one.

    .venv/bin/python bench/frame_phases.py [hanging | squeeze | ... | demo] [--grid 65]
        [--duration 2] [--no-damage]

Steps a built-in scenario (or ``demo``: the node demo's scene, bench/bench_demo.py) with
each pass below wrapped in a timer, and prints per pass the milliseconds it took per frame
(inclusive: a pass's time holds the passes it calls) and its calls per frame, largest
first. Single thread, kernels compiled before timing. The timers add a few microseconds a
call, so the frame total is a little above bench/benchmark.py's. A diagnostic that prints
figures, not a test.
"""
from __future__ import annotations

import argparse
import collections
import functools
import os
import sys
import time

os.environ.setdefault('NUMBA_NUM_THREADS', '1')
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import bench_demo  # noqa: E402
from paper_sim_ros.core import build_simulator, load_scenario, simulator  # noqa: E402
from paper_sim_ros.core.scenarios import builtin_mapping, with_overrides  # noqa: E402

PASSES = ('step_frame', '_substep', '_projective_step', '_buckling_iterations',
          '_bending_solve', '_table_rows', '_table_uzawa', '_membrane_solve',
          '_spring_iteration', '_global_iteration', '_settle_contact_rows',
          '_set_contact_rows', '_limit_strain', '_contact', '_grip', '_air_drag',
          '_keep_angular_momentum', '_factor_global_steps', 'topology_changed')
"""Simulator methods timed (docs/solver.md describes them in order)."""


def timed_passes(seconds: collections.Counter, calls: collections.Counter) -> None:
    """Wrap each of PASSES in the Simulator class with a timer adding to ``seconds`` and
    ``calls`` (for this process: a diagnostic's patch, not the package's)."""
    for name in PASSES:
        method = getattr(simulator.Simulator, name)

        @functools.wraps(method)
        def timed(*args, _method=method, _name=name, **kwargs):
            started = time.perf_counter()
            try:
                return _method(*args, **kwargs)
            finally:
                seconds[_name] += time.perf_counter() - started
                calls[_name] += 1
        setattr(simulator.Simulator, name, timed)


def scene(name: str, grid: int, duration: float, damage: bool):
    """The scenario and its probe inputs at a frame's end time."""
    if name == 'demo':
        mapping = bench_demo.demo_mapping(grid, duration)
        path = bench_demo.ProbePath()

        def probe_inputs(t: float):
            return bench_demo.demo_probe_inputs(path, t)
    else:
        mapping = with_overrides(builtin_mapping(name), grid=grid, duration=duration)
        probe_inputs = None
    if not damage:
        mapping['damage'] = {'enabled': False}
    scenario = load_scenario(mapping)
    return scenario, probe_inputs or scenario.probe_inputs


def step(name: str, grid: int, duration: float, damage: bool,
         counters: tuple = ()) -> tuple[int, float]:
    """Step the scene; (frames, seconds spent in step_frame). ``counters`` are cleared once
    the simulator is built: what its construction took is not a frame's."""
    scenario, probe_inputs = scene(name, grid, duration, damage)
    sim = build_simulator(scenario)
    for counter in counters:
        counter.clear()
    dt = scenario.config.solver.dt
    stepping = 0.0
    for frame in range(scenario.frame_count):
        sim.set_probes(*probe_inputs((frame + 1) * dt))
        started = time.perf_counter()
        sim.step_frame()
        stepping += time.perf_counter() - started
    return scenario.frame_count, stepping


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('scenario', nargs='?', default='hanging')
    parser.add_argument('--grid', type=int, default=65)
    parser.add_argument('--duration', type=float, default=2.0)
    parser.add_argument('--no-damage', action='store_true')
    args = parser.parse_args()
    step(args.scenario, 17, 0.5, not args.no_damage)  # numba compilation
    seconds, calls = collections.Counter(), collections.Counter()
    timed_passes(seconds, calls)
    frames, stepping = step(args.scenario, args.grid, args.duration, not args.no_damage,
                            (seconds, calls))
    dt = 1.0 / 60.0
    print(f'{args.scenario} at {args.grid}², {frames} frames: {1e3 * stepping / frames:.2f} ms '
          f'a frame ({frames * dt / stepping:.2f}× real time at 60 Hz, timers included)')
    print('| pass | ms a frame | calls a frame |')
    print('|---|---|---|')
    for name, total in seconds.most_common():
        print(f'| {name} | {1e3 * total / frames:.3f} | {calls[name] / frames:.2f} |')


if __name__ == '__main__':
    main()
