"""What recording to Rerun costs: frames per second with the recorder on and off.

    .venv/bin/python bench/bench_rerun.py --grid 65 129 --frames 120

For each grid: the built-in 'hanging' scenario (the sheet moves every frame) is stepped
``--frames`` frames with no recorder, then again with a recorder saving an .rrd file (and, with
``--hinge-every``, HINGE springs logged every n-th frame only). Frames per second count the
whole loop (step + log_frame, the flush at close included); the .rrd size per frame and the time
``log_frame`` itself took are printed too. Warm-up (numba compilation) is excluded.
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..'))

from paper_sim_ros.core.scenarios import builtin_mapping, scenario_from_mapping  # noqa: E402
from paper_sim_ros.headless import build_simulator  # noqa: E402
from paper_sim_ros.rerun_logger import RerunRecorder  # noqa: E402


def run(grid: int, frames: int, path: str | None, hinge_every: int) -> dict:
    mapping = builtin_mapping('hanging')
    mapping.setdefault('sheet', {})
    mapping['sheet'].update({'nx': grid, 'ny': grid})
    scenario = scenario_from_mapping(mapping)
    simulator = build_simulator(scenario)
    dt = scenario.config.solver.dt
    simulator.step_frame()  # warm-up: compile the kernels outside the measurement
    recorder = RerunRecorder('bench_rerun', path=path, recording_info={'scenario': mapping},
                             hinge_every=hinge_every)
    logging = 0.0
    started = time.perf_counter()
    for _ in range(frames):
        simulator.set_probes(*scenario.probe_inputs(simulator.time + dt))
        step_started = time.perf_counter()
        simulator.step_frame()
        step_seconds = time.perf_counter() - step_started
        log_started = time.perf_counter()
        recorder.log_frame(simulator.time, simulator, scalars={
            'step_time': step_seconds,
            'real_time_factor': dt / step_seconds if step_seconds > 0 else 0.0})
        logging += time.perf_counter() - log_started
    recorder.close()
    elapsed = time.perf_counter() - started
    size = os.path.getsize(path) if path else 0
    return {'fps': frames / elapsed, 'log_ms': 1e3 * logging / frames,
            'kib_per_frame': size / 1024 / frames}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--grid', type=int, nargs='+', default=[65])
    parser.add_argument('--frames', type=int, default=120)
    parser.add_argument('--hinge-every', type=int, nargs='+', default=[1])
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as directory:
        for grid in args.grid:
            off = run(grid, args.frames, None, 1)
            print(f'{grid}x{grid}: recording off   {off["fps"]:7.1f} frames/s')
            for hinge_every in args.hinge_every:
                on = run(grid, args.frames, os.path.join(directory, f'{grid}.rrd'), hinge_every)
                print(f'{grid}x{grid}: recording on    {on["fps"]:7.1f} frames/s '
                      f'(hinge springs every {hinge_every} frame(s); log_frame '
                      f'{on["log_ms"]:.2f} ms/frame; {on["kib_per_frame"]:.0f} KiB/frame; '
                      f'{100 * (1 - on["fps"] / off["fps"]):.0f} % slower)', flush=True)


if __name__ == '__main__':
    main()
