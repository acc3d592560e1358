"""`make demo`: the paper_sim node and the scripted probe together for a fixed time.

    python -m paper_sim_ros.demo [--duration 20] [--out out] [--grid 33] [--report-every 60]

The node runs in this process and the scripted probe in a child process, as a robot's
driver would: the probe publishes its poses at its own rate also while the simulation steps
a tick (on the node's executor it published once a tick, and the poses came too seldom for
the node to place the probe evenly between them), and its Python does not take turns with
the stepping for the interpreter's lock (on a thread of this process it did: 0.66–0.74×
real time at 65² against 0.76–0.80× as a process, alternated). An A4 sheet, clamped at one
short edge 0.2 m above a table, swings down, hangs and drapes onto the table; then the
scripted probe pushes into its hanging part and drags across it, again and again. The node
publishes paper/markers, paper/points and /diagnostics as usual (watch them with RViz and
config/paper_sim.rviz from another shell on the same ROS_DOMAIN_ID), and records every
published frame to ``<out>/demo.rrd`` (open it with ``rerun out/demo.rrd``). Ctrl-C ends it
early; the recording is complete either way. The grid is 33 x 33 by default so that the demo
keeps up with the wall clock on two cores; ``--grid 65`` is the node's own default. With
``--sim-time`` the simulation is the clock (``publish_clock``): it publishes /clock and the
probe runs on it (``use_sim_time``), so a grid the machine cannot keep up with runs slower
than real time, with the probe's path in simulated time as it would be in real time, instead
of slipping (which shares the path the simulation could not follow out over fewer frames).
"""
from __future__ import annotations

import argparse
import math
import os
from pathlib import Path
import subprocess
import sys
import time

from ament_index_python.packages import get_package_share_directory
import numpy as np
import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.parameter import Parameter

from .node import PaperSimNode, StartupError


def default_params_file() -> Path:
    """config/paper_sim.yaml: installed (share/paper_sim_ros) or in the source tree."""
    try:
        installed = Path(get_package_share_directory('paper_sim_ros')) / 'config' / \
            'paper_sim.yaml'
        if installed.is_file():
            return installed
    except (LookupError, ValueError, OSError):  # not installed: run from the source tree
        pass
    return Path(__file__).resolve().parents[1] / 'config' / 'paper_sim.yaml'


def parse_arguments(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--duration', type=float, default=20.0,
                        help='wall-clock seconds to run (default 20)')
    parser.add_argument('--out', default='out', help='output directory (default out)')
    parser.add_argument('--grid', type=int, default=33, help='vertices a side (default 33)')
    parser.add_argument('--no-record', action='store_true', help='do not write demo.rrd')
    parser.add_argument('--sim-time', action='store_true',
                        help='the simulation publishes /clock and the probe follows it')
    parser.add_argument('--camera-rate', type=float, default=10.0,
                        help='the virtual camera (paper/camera/...) [Hz] (default 10; 0: off)')
    parser.add_argument('--report-every', type=float, default=0.0, metavar='SECONDS',
                        help='print the real-time factor over each such interval, the '
                        'vertices and the memory (default 0: only the summary at the end)')
    arguments = parser.parse_args(argv)
    if not (arguments.duration > 0):
        parser.error('--duration must be > 0')
    if not (0 <= arguments.camera_rate <= 1000):
        parser.error('--camera-rate must be in [0, 1000] Hz')
    if not (0 <= arguments.report_every < math.inf):
        parser.error('--report-every must be >= 0 s')
    return arguments


def main(argv: list[str] | None = None) -> int:
    arguments = parse_arguments(argv)
    # a demo talks to this machine only unless the user says otherwise
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    out = Path(arguments.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    recording = '' if arguments.no_record else str(out / 'demo.rrd')
    rclpy.init(args=['--ros-args', '--params-file', str(default_params_file())])
    executor = SingleThreadedExecutor()
    nodes = []
    probe = None
    started = time.monotonic()
    interrupted = False
    try:
        simulation = PaperSimNode(parameter_overrides=[
            Parameter('sheet.nx', value=arguments.grid),
            Parameter('sheet.ny', value=arguments.grid),
            Parameter('pin_mode', value='short_edge'),
            Parameter('contact.ground_height', value=-0.2),
            Parameter('publish_rate', value=15.0),
            Parameter('camera.rate', value=arguments.camera_rate),
            Parameter('rerun_path', value=recording),
            Parameter('publish_clock', value=arguments.sim_time),
        ])
        nodes.append(simulation)
        executor.add_node(simulation)
        probe = _start_probe(arguments.sim_time)
        print(f'paper_sim demo: {arguments.duration:g} s, grid {arguments.grid}, ROS domain '
              f'{os.environ.get("ROS_DOMAIN_ID", "0")}; topics /paper/markers /paper/points '
              f'/paper/camera/... /diagnostics', flush=True)
        started = time.monotonic()
        end = started + arguments.duration
        report = _Report(simulation, started, arguments.report_every)
        while time.monotonic() < end and rclpy.ok():
            executor.spin_once(timeout_sec=0.05)
            report.due(time.monotonic())
    except (KeyboardInterrupt, ExternalShutdownException):
        interrupted = True
    except StartupError as error:
        print(f'paper_sim demo: cannot start: {error}', file=sys.stderr)
        return 1
    finally:
        summary = _summary(nodes[0], time.monotonic() - started) if nodes else None
        if probe is not None:
            _stop_probe(probe)
        for node in reversed(nodes):
            node.destroy_node()
        executor.shutdown()
        rclpy.try_shutdown()
    print(f'paper_sim demo {"interrupted" if interrupted else "finished"}: {summary}')
    if recording:
        size = Path(recording).stat().st_size if Path(recording).exists() else 0
        print(f'Rerun recording: {recording} ({size / 1e6:.1f} MB); replay with: '
              f'rerun {recording}')
    return 0


def _start_probe(sim_time: bool) -> subprocess.Popen:
    """The scripted probe (paper_sim_probe) as a process of its own, on this process's ROS
    environment; with ``sim_time`` it runs on the simulation's /clock."""
    return subprocess.Popen([sys.executable, '-m', 'paper_sim_ros.scripted_probe', '--ros-args',
                             '-p', f'use_sim_time:={"true" if sim_time else "false"}'])


def _stop_probe(probe: subprocess.Popen) -> None:
    """Stop the probe's process (SIGTERM: an orderly stop, paper_sim_ros.node_runner), and
    say so if it had ended on its own with an error (the demo then ran without a probe)."""
    ended = probe.poll()
    if ended is not None and ended != 0:
        print(f'paper_sim demo: the scripted probe exited with status {ended}', file=sys.stderr)
    probe.terminate()
    try:
        probe.wait(timeout=5.0)
    except subprocess.TimeoutExpired:
        probe.kill()
        probe.wait()


class _Report:
    """``--report-every``: a line per interval of wall-clock time, for long runs (does the
    node keep up, does the sheet stay under ``max_vertices``, does the memory stay flat)."""

    def __init__(self, simulation: PaperSimNode, started: float, interval: float) -> None:
        self._simulation = simulation
        self._interval = interval
        self._since, self._simulated = started, simulation.simulator.time

    def due(self, now: float) -> None:
        if self._interval <= 0.0 or now - self._since < self._interval:
            return
        simulator = self._simulation.simulator
        factor = (simulator.time - self._simulated) / (now - self._since)
        print(f'paper_sim demo: {factor:.2f}× real time over the last {now - self._since:.0f} s'
              f' ({simulator.time:.1f} s simulated), {simulator.sheet.vertex_count} vertices, '
              f'breaks {simulator.breaks}, folds {simulator.folds}, '
              f'RSS {_resident_megabytes()}', flush=True)
        self._since, self._simulated = now, simulator.time


def _resident_megabytes() -> str:
    """The process's resident memory now (Linux's /proc), e.g. '372 MB'; '?' elsewhere."""
    try:
        with open('/proc/self/status') as status:
            for line in status:
                if line.startswith('VmRSS:'):
                    return f'{int(line.split()[1]) / 1024:.0f} MB'
    except OSError:
        pass
    return '?'


def _summary(simulation: PaperSimNode, wall_seconds: float) -> str:
    simulator = simulation.simulator
    sheet = simulator.sheet
    counters = simulation.counters()
    last_second_strain, run_strain = simulation.strain_summary()
    return (f'{simulator.frame} frames ({simulator.time:.1f} s simulated in '
            f'{wall_seconds:.1f} s: real-time factor {simulator.time / wall_seconds:.2f}; '
            f'{counters["slipped_frames"]} frames behind the clock, '
            f'{counters["dropped_frames"]} publications dropped), '
            f'{counters["poses_received"]} probe poses, '
            f'{sheet.vertex_count} vertices, breaks {simulator.breaks}, '
            f'folds {simulator.folds}, max strain {last_second_strain:.2%} over the last '
            f'second, {run_strain:.2%} over the run, '
            f'all finite: {bool(np.isfinite(sheet.positions).all())}')


if __name__ == '__main__':
    sys.exit(main())
