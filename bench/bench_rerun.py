"""What recording to Rerun costs: frames per second with the recorder on and off.

    .venv/bin/python bench/bench_rerun.py --grid 65 129 --frames 120 --hinge-every 1 10 0

For each grid: the built-in 'hanging' scenario (the sheet moves every frame) is stepped
``--frames`` frames with no recorder, then again with a recorder saving an .rrd file (and, with
``--hinge-every``, HINGE springs logged every n-th frame only). Frames per second count the
whole loop (step + log_frame, the flush at close included); CPU time per frame counts every
thread of the process (rerun encodes and writes in its own threads); the .rrd size per frame and
the time ``log_frame`` itself took (wall, and CPU of the calling thread) are printed too. The
first frame (numba compilation, the static texture) is excluded. On a shared machine the CPU
times are the figures to compare: wall-clock rates follow the other load.
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..'))

from paper_sim_ros.core import build_simulator, load_scenario  # noqa: E402
from paper_sim_ros.rerun_logger import RerunRecorder  # noqa: E402


def run(grid: int, frames: int, path: str | None, hinge_every: int) -> dict:
    scenario = load_scenario('hanging', grid=grid)
    simulator = build_simulator(scenario)
    dt = scenario.config.solver.dt
    recorder = RerunRecorder('bench_rerun', path=path,
                             recording_info={'scenario': scenario.mapping},
                             hinge_every=hinge_every)
    # warm-up outside the measurement: numba compilation, the first (static) frame's texture
    simulator.step_frame()
    recorder.log_frame(simulator.time, simulator)
    logging = logging_cpu = 0.0
    started = time.perf_counter()
    cpu_started = time.process_time()  # all threads of the process: rerun's encoders too
    for _ in range(frames):
        simulator.set_probes(*scenario.probe_inputs(simulator.time + dt))
        step_started = time.perf_counter()
        simulator.step_frame()
        step_seconds = time.perf_counter() - step_started
        log_started = time.perf_counter()
        log_cpu_started = time.thread_time()
        recorder.log_frame(simulator.time, simulator, scalars={
            'step_time': step_seconds,
            'real_time_factor': dt / step_seconds if step_seconds > 0 else 0.0})
        logging += time.perf_counter() - log_started
        logging_cpu += time.thread_time() - log_cpu_started
    recorder.close()
    elapsed = time.perf_counter() - started
    cpu = time.process_time() - cpu_started
    size = os.path.getsize(path) if path else 0
    return {'fps': frames / elapsed, 'log_ms': 1e3 * logging / frames,
            'cpu_ms': 1e3 * cpu / frames, 'log_cpu_ms': 1e3 * logging_cpu / frames,
            'kib_per_frame': size / 1024 / frames}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--grid', type=int, nargs='+', default=[65])
    parser.add_argument('--frames', type=int, default=120)
    parser.add_argument('--hinge-every', type=int, nargs='+', default=[1])
    parser.add_argument('--rounds', type=int, default=3,
                        help='alternate off/on this many times; the best round counts (the '
                             'machine is shared: the best is the least disturbed)')
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as directory:
        for grid in args.grid:
            settings = [('off', None, 1)] + [
                (f'on, hinge springs every {n} frame(s)' if n else 'on, no hinge springs',
                 os.path.join(directory, f'{grid}_{n}.rrd'), n) for n in args.hinge_every]
            best: dict[str, dict] = {}
            for _ in range(args.rounds):
                for label, path, hinge_every in settings:
                    result = run(grid, args.frames, path, hinge_every)
                    if label not in best or result['fps'] > best[label]['fps']:
                        best[label] = result
            off = best['off']['fps']
            for label, path, _ in settings:
                result = best[label]
                line = (f'{grid}x{grid}: recording {label:36s} {result["fps"]:6.1f} frames/s, '
                        f'CPU {result["cpu_ms"]:6.1f} ms/frame')
                if path:
                    line += (f' ({result["fps"] / off:.2f}x the frame rate off; log_frame '
                             f'{result["log_ms"]:.1f} ms wall, {result["log_cpu_ms"]:.1f} ms '
                             f'CPU in the caller; {result["kib_per_frame"]:.0f} KiB/frame)')
                print(line, flush=True)


if __name__ == '__main__':
    main()
