"""Cost of one virtual-camera frame: render (core/camera.py), its four messages
(msg_adapters/camera.py) and its images to a Rerun recording (rerun_logger.py), for a 65²
sheet on the table with a probe, 640 × 480.

    .venv/bin/python bench/bench_camera.py [--grid 65] [--width 640] [--height 480]
        [--frames 50] [--demo]

``--demo``: the node demo's scene instead (bench/bench_demo.py: the sheet clamped and
draping onto the table, the scripted probe), stepped 2 s first, seen by the node's
default camera.

Single thread, kernels compiled before timing; prints median and 95th-percentile
milliseconds per stage. A script, not a test.
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

os.environ.setdefault('NUMBA_NUM_THREADS', '1')

import numpy as np  # noqa: E402
from std_msgs.msg import Header  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import bench_demo  # noqa: E402
from paper_sim_ros.core import build_simulator, load_scenario  # noqa: E402
from paper_sim_ros.core.camera import CameraConfig, look_at, render  # noqa: E402
from paper_sim_ros.rerun_logger import RerunRecorder  # noqa: E402
from paper_sim_ros.scripted_probe import ProbePath  # noqa: E402
from paper_sim_ros.msg_adapters.camera import (camera_info, color_image,  # noqa: E402
                                               depth_image, organized_cloud)


def demo_simulator(grid: int):
    """The node demo's scene (bench/bench_demo.py) stepped 2 s along the scripted path."""
    scenario = bench_demo.demo_scene(grid, 3.0)
    simulator = build_simulator(scenario)
    path = ProbePath()
    for frame in range(round(2.0 / scenario.config.solver.dt)):
        simulator.set_probes(*bench_demo.demo_probe_inputs(
            path, (frame + 1) * scenario.config.solver.dt))
        simulator.step_frame()
    return simulator


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--grid', type=int, default=65)
    parser.add_argument('--width', type=int, default=640)
    parser.add_argument('--height', type=int, default=480)
    parser.add_argument('--frames', type=int, default=50)
    parser.add_argument('--demo', action='store_true',
                        help="the node demo's scene after 2 s instead of a sheet on the table")
    args = parser.parse_args(argv)
    eye = (0.3, -0.35, 0.5)
    config = CameraConfig(width=args.width, height=args.height, position=eye,
                          orientation=look_at(eye, (0.0, 0.0, 0.0)))
    if args.demo:
        simulator = demo_simulator(args.grid)
        sheet, probes = simulator.sheet, simulator.probes
        probe = (probes.end, probes.radius, probes.active)
        table_height = simulator.config.contact.ground_height
    else:
        simulator = build_simulator(load_scenario({
            'name': 'flat', 'sheet': {'nx': args.grid, 'ny': args.grid, 'elevation': 0.0},
            'contact': {'ground_enabled': True, 'ground_height': 0.0}}))
        sheet = simulator.sheet
        probe = (np.array([[0.02, -0.03, 0.012]]), np.array([0.015]), np.array([True]))
        table_height = 0.0
    labels = np.zeros(sheet.vertex_count, np.uint16)
    colors = np.full((sheet.vertex_count, 3), 240, np.uint8)
    header = Header(frame_id='camera_optical_frame')
    stages = {'render': [], 'depth Image': [], 'rgb Image': [], 'CameraInfo': [],
              'organised cloud': [], 'to Rerun': []}
    recording = tempfile.TemporaryDirectory()
    recorder = RerunRecorder('bench_camera', os.path.join(recording.name, 'camera.rrd'))
    for frame_index in range(args.frames + 3):
        started = time.perf_counter()
        frame = render(config, sheet.positions, sheet.triangles, sheet.material, labels,
                       colors, *probe, table_height)
        marks = [time.perf_counter()]
        depth_image(header, frame)
        marks.append(time.perf_counter())
        color_image(header, frame)
        marks.append(time.perf_counter())
        camera_info(header, config)
        marks.append(time.perf_counter())
        organized_cloud(header, config, frame)
        marks.append(time.perf_counter())
        recorder.log_camera(0.0, simulator, config, frame)
        marks.append(time.perf_counter())
        if frame_index < 3:  # compilation and first-touch
            continue
        for name, begin, end in zip(stages, [started] + marks[:-1], marks):
            stages[name].append(1e3 * (end - begin))
    recorder.close()
    recording.cleanup()
    scene = "the demo's scene" if args.demo else 'a sheet on the table'
    print(f'{args.grid}², {scene}, {args.width} × {args.height}, {args.frames} frames, '
          '1 thread')
    total = np.sum([values for values in stages.values()], axis=0)
    for name, values in list(stages.items()) + [('total', total)]:
        print(f'{name:<16} median {np.median(values):7.2f} ms   p95 '
              f'{np.percentile(values, 95):7.2f} ms')
    return 0


if __name__ == '__main__':
    sys.exit(main())
