"""Run a scenario without ROS: batch runs, benchmarks, regression tests.

    python -m paper_sim_ros.headless --scenario hanging --grid 65 --duration 10 \\
        --metrics-json out/hanging.json --rrd out/hanging.rrd

Exit status 0 on success, 2 with a one-line reason on bad input, 130 when interrupted.
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import sys

from .core import (BUILTIN_SCENARIOS, build_simulator, check_metrics_path,
                   load_scenario, run_scenario, write_metrics)
from .rerun_logger import check_writable_rrd
from .rerun_replay import replay
from .run_outputs import RunOutputs
from .warmup import warm_up


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog='paper_sim_headless', description=__doc__.split('\n')[0])
    parser.add_argument('--scenario', default='hanging',
                        help=f'built-in ({", ".join(BUILTIN_SCENARIOS)}) or a YAML file')
    parser.add_argument('--grid', type=int, help='vertices per side (default 65)')
    parser.add_argument('--duration', type=float, help='simulated seconds')
    parser.add_argument('--dt', type=float, help='frame step [s] (default 1/60)')
    parser.add_argument('--substeps', type=int, help='integration sub-steps per frame')
    parser.add_argument('--seed', type=int, help='random seed')
    parser.add_argument('--solver', choices=('constrained', 'paper', 'explicit'),
                        help='time stepping method (default constrained)')
    parser.add_argument('--no-damage', action='store_true',
                        help='switch breaks and folds off (the sheet behaves like rubber)')
    parser.add_argument('--metrics-json', help='write the metrics to this JSON file')
    parser.add_argument('--rrd', help='record the run to this Rerun .rrd file')
    parser.add_argument('--bag', metavar='DIR',
                        help='write what the node would publish (paper/points every frame, the '
                             "scenario's cameras, /tf_static) to this new rosbag2 directory "
                             '(MCAP)')
    parser.add_argument('--camera-rate', type=float,
                        help="every camera's rate [Hz]: in --bag (default: the scenario's; 0: "
                             'no camera) and in --rrd (default: no camera there, as images '
                             'would dwarf the rest of a recording)')
    parser.add_argument('--replay', metavar='FILE.rrd',
                        help='re-run a recorded session: its scenario, parameters and seed, '
                             'driven by its recorded probe inputs')
    return parser.parse_args(argv)


def _raise_keyboard_interrupt(signum, frame) -> None:
    raise KeyboardInterrupt


def _error(message: object) -> int:
    print(f'paper_sim_headless: error: {message}', file=sys.stderr)
    return 2


def _interrupted() -> int:
    print('paper_sim_headless: interrupted', file=sys.stderr)
    return 130


def emit_metrics(metrics: dict, path: str | None) -> None:
    """Print the metrics as JSON, and write them to ``path`` if given."""
    if path:
        write_metrics(metrics, path)
    print(json.dumps(metrics, indent=2))


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    if args.replay:
        return replay_command(args)
    outputs = None
    # from here on SIGTERM unwinds like Ctrl-C, so a recording is always closed
    signal.signal(signal.SIGTERM, _raise_keyboard_interrupt)
    try:
        scenario = load_scenario(args.scenario, grid=args.grid, duration=args.duration,
                                 dt=args.dt, substeps=args.substeps, seed=args.seed,
                                 method=args.solver,
                                 damage_enabled=False if args.no_damage else None)
        simulator = build_simulator(scenario)
        check_metrics_path(args.metrics_json)
        outputs = RunOutputs(scenario, simulator, rrd=args.rrd, bag=args.bag,
                             camera_rate=args.camera_rate)
    except (ValueError, OSError) as error:
        return _error(error)
    except KeyboardInterrupt:
        if outputs is not None:
            outputs.close()
        return _interrupted()
    try:
        warm_up()
        metrics = run_scenario(scenario, simulator=simulator, on_frame=outputs.on_frame)
    except KeyboardInterrupt:
        return _interrupted()
    finally:
        outputs.close()
    emit_metrics(metrics, args.metrics_json)
    return 0


def replay_command(args: argparse.Namespace) -> int:
    """``--replay FILE.rrd [--rrd OUT.rrd] [--metrics-json OUT.json]``: re-run a recorded
    session (``rerun_replay.replay``). Exit status 0, 2 on bad input, 130 when
    interrupted."""
    # every other option would change the run the recording describes
    overrides = [f'--{name.replace("_", "-")}' for name, value in sorted(vars(args).items())
                 if name not in ('replay', 'rrd', 'metrics_json', 'scenario')
                 and value is not None and value is not False]
    try:
        if overrides:
            raise ValueError(f'--replay takes the scenario and every parameter from the '
                             f'recording; it cannot be combined with {", ".join(overrides)}')
        if not os.path.isfile(args.replay):
            raise ValueError(f'no such recording: {args.replay}')
        check_metrics_path(args.metrics_json)
        if args.rrd:
            check_writable_rrd(args.rrd)
        signal.signal(signal.SIGTERM, _raise_keyboard_interrupt)
        metrics = replay(args.replay, rrd=args.rrd)
    except (ValueError, OSError) as error:
        return _error(error)
    except KeyboardInterrupt:
        return _interrupted()
    emit_metrics(metrics, args.metrics_json)
    return 0


if __name__ == '__main__':
    sys.exit(main())
