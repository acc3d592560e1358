"""The demo's physics without ROS: what `make demo` steps each frame, timed alone.

    .venv/bin/python bench/bench_demo.py [--grids 33 65] [--duration 20] [--membrane 30]

The scene of paper_sim_ros.demo: an A4 sheet clamped along its short edge, the table
0.2 m below (its far end drapes onto it), the scripted probe's path (ScriptedProbe's
ProbePath, a 2 cm probe) pushing into the hanging part and dragging across it, damage
on. Single thread, kernels compiled before timing. Prints, per grid: real-time factor
of the stepping alone, mean and 95th-percentile frame time, the springs' local/global
iterations a frame (Simulator.spring_iterations), and the max HINGE strain over the run
and over its last second. The node adds its publishing and recording on
top (the demo prints its own factor). A script that prints figures, not a test.
"""
from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault('NUMBA_NUM_THREADS', '1')

import numpy as np  # noqa: E402

from paper_sim_ros.core import build_simulator, load_scenario  # noqa: E402
from paper_sim_ros.scripted_probe import ProbePath  # noqa: E402

PROBE_RADIUS = 0.02
"""The demo's probe radius [m] (config/paper_sim.yaml, probe_radii)."""


def demo_mapping(grid: int, duration: float, membrane: float | None = None) -> dict:
    """The demo's scenario mapping: the node's defaults with the demo's overrides (demo.py);
    ``membrane``: the membrane's weight in every sub-step (None: the solver's default)."""
    return {'name': 'demo', 'duration': duration, 'pin': 'short_edge',
            'sheet': {'nx': grid, 'ny': grid, 'elevation': 0.0},
            'solver': ({} if membrane is None
                       else {'membrane_weight': membrane, 'membrane_scope': 'always'}),
            'contact': {'ground_enabled': True, 'ground_height': -0.2}}


def demo_scene(grid: int, duration: float, membrane: float | None = None):
    """The demo's scenario (``demo_mapping``)."""
    return load_scenario(demo_mapping(grid, duration, membrane))


def demo_probe_inputs(path: ProbePath, t: float) -> tuple:
    """Simulator.set_probes' (centres, radii, active) for the scripted probe at time ``t``
    [s] of ``path`` (inactive where the path has no probe)."""
    centre = path.position(t)
    return (np.zeros((1, 3)) if centre is None else np.asarray(centre)[None],
            np.array([PROBE_RADIUS]), np.array([centre is not None]))


def run(grid: int, duration: float, membrane: float | None = None) -> dict:
    """Step the demo's scene; frame times [s] and strains per frame."""
    scenario = demo_scene(grid, duration, membrane)
    simulator = build_simulator(scenario)
    path = ProbePath()
    dt = scenario.config.solver.dt
    frame_seconds, strain = [], []
    for frame in range(scenario.frame_count):
        simulator.set_probes(*demo_probe_inputs(path, (frame + 1) * dt))
        started = time.perf_counter()
        simulator.step_frame()
        frame_seconds.append(time.perf_counter() - started)
        strain.append(simulator.max_strain())
    return {'frame_seconds': np.array(frame_seconds), 'strain': np.array(strain), 'dt': dt,
            'iterations_per_frame': simulator.spring_iterations / scenario.frame_count}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--grids', type=int, nargs='+', default=[33, 65])
    parser.add_argument('--duration', type=float, default=20.0)
    parser.add_argument('--membrane', type=float, default=None,
                        help="the membrane at this weight in every sub-step (membrane_scope "
                        "'always'; 0: none; default: the solver's)")
    args = parser.parse_args()
    run(17, 1.0, args.membrane)  # numba compilation
    print('| grid | real-time factor | ms a frame (p95) | spring iterations a frame '
          '| max strain, run | last second |')
    print('|---|---|---|---|---|---|')
    for grid in args.grids:
        result = run(grid, args.duration, args.membrane)
        seconds, strain = result['frame_seconds'], result['strain']
        last_second = int(round(1.0 / result['dt']))
        print(f'| {grid}² | {seconds.size * result["dt"] / seconds.sum():.2f} '
              f'| {1e3 * seconds.mean():.1f} ({1e3 * np.percentile(seconds, 95):.1f}) '
              f'| {result["iterations_per_frame"]:.2f} '
              f'| {100 * strain.max():.2f} % | {100 * strain[-last_second:].max():.2f} % |',
              flush=True)


if __name__ == '__main__':
    main()
