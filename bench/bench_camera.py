"""Cost of one virtual-camera frame: render (core/camera.py) and its four messages
(msg_adapters/camera.py), for a 65² sheet on the table with a probe, 640 × 480.

    .venv/bin/python bench/bench_camera.py [--grid 65] [--width 640] [--height 480]
        [--frames 50]

Single thread, kernels compiled before timing; prints median and 95th-percentile
milliseconds per stage. A script, not a test.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

os.environ.setdefault('NUMBA_NUM_THREADS', '1')

import numpy as np  # noqa: E402
from std_msgs.msg import Header  # noqa: E402

from paper_sim_ros.core import SheetConfig  # noqa: E402
from paper_sim_ros.core.camera import CameraConfig, look_at, render  # noqa: E402
from paper_sim_ros.core.sheet import build_flat_sheet  # noqa: E402
from paper_sim_ros.msg_adapters.camera import (camera_info, color_image,  # noqa: E402
                                               depth_image, organized_cloud)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--grid', type=int, default=65)
    parser.add_argument('--width', type=int, default=640)
    parser.add_argument('--height', type=int, default=480)
    parser.add_argument('--frames', type=int, default=50)
    args = parser.parse_args(argv)
    sheet = build_flat_sheet(SheetConfig(nx=args.grid, ny=args.grid))
    eye = (0.3, -0.35, 0.5)
    config = CameraConfig(width=args.width, height=args.height, position=eye,
                          orientation=look_at(eye, (0.0, 0.0, 0.0)))
    labels = np.zeros(sheet.vertex_count, np.uint16)
    colors = np.full((sheet.vertex_count, 3), 240, np.uint8)
    probe = (np.array([[0.02, -0.03, 0.012]]), np.array([0.015]), np.array([True]))
    header = Header(frame_id='camera_optical_frame')
    stages = {'render': [], 'depth Image': [], 'rgb Image': [], 'CameraInfo': [],
              'organised cloud': []}
    for frame_index in range(args.frames + 3):
        started = time.perf_counter()
        frame = render(config, sheet.positions, sheet.triangles, sheet.material, labels,
                       colors, *probe, 0.0)
        marks = [time.perf_counter()]
        depth_image(header, frame)
        marks.append(time.perf_counter())
        color_image(header, frame)
        marks.append(time.perf_counter())
        camera_info(header, config)
        marks.append(time.perf_counter())
        organized_cloud(header, config, frame)
        marks.append(time.perf_counter())
        if frame_index < 3:  # compilation and first-touch
            continue
        for name, begin, end in zip(stages, [started] + marks[:-1], marks):
            stages[name].append(1e3 * (end - begin))
    print(f'{args.grid}² sheet, {args.width} × {args.height}, {args.frames} frames, 1 thread')
    total = np.sum([values for values in stages.values()], axis=0)
    for name, values in list(stages.items()) + [('total', total)]:
        print(f'{name:<16} median {np.median(values):7.2f} ms   p95 '
              f'{np.percentile(values, 95):7.2f} ms')
    return 0


if __name__ == '__main__':
    sys.exit(main())
