"""Dataset throughput: runs per minute of ``paper_sim_dataset`` with 1 and 2 workers on the
example spec, and how it scales (issue 17's goal: 2 workers at least 1.8 times 1 worker).

    .venv/bin/python bench/bench_dataset.py [--spec config/dataset_example.yaml] \\
        [--workers 1 2] [--repeat 1]

Each batch is the command itself, into a new folder, on a new local Ray instance (on
loopback, token authentication with a token of its own). Runs per minute count the runs
over the batch's time from its first run submitted to its last finished (``summary.json``:
Ray's start and stop, about 10 s, are left out, as they are once per batch however big);
the process's whole wall time is printed beside it. ``run s`` is the mean time of a run on
its worker, outputs written and checked: when it grows with the workers, they are competing
for something (the cores with the driver and Ray's own processes, the disk). With
``--repeat`` the best batch of each count is kept. Run it on a quiet machine: the load
average is printed first.
"""
from __future__ import annotations

import argparse
import json
import os
import secrets
import subprocess
import sys
import tempfile
import time

REPOSITORY = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..')
EXAMPLE_SPEC = os.path.join(REPOSITORY, 'config', 'dataset_example.yaml')


def ray_environment(folder: str) -> dict:
    """Ray on loopback, quiet, its sessions under ``folder``; the caller's token
    authentication settings if any, else a token of the benchmark's own."""
    env = {**os.environ, 'RAY_USAGE_STATS_ENABLED': '0',
           'RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER': '0', 'RAY_TMPDIR': folder}
    if 'RAY_AUTH_MODE' not in env:
        env.update(RAY_AUTH_MODE='token', RAY_AUTH_TOKEN=secrets.token_hex(32))
    return env


def batch(spec: str, workers: int, folder: str, env: dict) -> dict:
    """One batch of ``spec`` on ``workers`` into a new folder: its summary, with ``wall_s``
    (the whole process) and ``run_s`` (the mean run on its worker)."""
    out = tempfile.mkdtemp(prefix=f'w{workers}_', dir=folder)
    started = time.perf_counter()
    subprocess.run([sys.executable, '-m', 'paper_sim_ros.dataset', spec, '--out', out,
                    '--workers', str(workers)], env=env, check=True, stdout=subprocess.DEVNULL)
    wall_s = time.perf_counter() - started
    with open(os.path.join(out, 'summary.json'), encoding='utf-8') as stream:
        summary = json.load(stream)
    with open(os.path.join(out, 'manifest.jsonl'), encoding='utf-8') as stream:
        runs = [json.loads(line) for line in stream]
    if summary['failed'] or summary['ran'] != len(runs):
        raise RuntimeError(f'{out}: {summary["failed"]} runs failed, {summary["ran"]} ran')
    return {**summary, 'wall_s': wall_s,
            'run_s': sum(run['wall_s'] for run in runs) / len(runs)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--spec', default=EXAMPLE_SPEC)
    parser.add_argument('--workers', type=int, nargs='+', default=[1, 2])
    parser.add_argument('--repeat', type=int, default=1)
    args = parser.parse_args()
    print(f'spec {os.path.relpath(args.spec)}; {os.cpu_count()} cores; load average '
          f'{" ".join(f"{load:.2f}" for load in os.getloadavg())}')
    print(f'{"workers":>7} {"runs":>5} {"batch s":>8} {"runs/min":>9} {"per core":>9} '
          f'{"run s":>6} {"process s":>10}')
    rates = {}
    # Ray's sessions need short socket paths: a folder of its own right under /tmp
    with tempfile.TemporaryDirectory(prefix='raybench', dir='/tmp') as folder:
        env = ray_environment(folder)
        for workers in args.workers:
            best = max((batch(args.spec, workers, folder, env) for _ in range(args.repeat)),
                       key=lambda summary: summary['runs_per_minute'])
            rates[workers] = best['runs_per_minute']
            print(f'{workers:>7} {best["ran"]:>5} {best["batch_s"]:>8.1f} '
                  f'{best["runs_per_minute"]:>9.1f} {best["runs_per_minute"] / workers:>9.1f} '
                  f'{best["run_s"]:>6.2f} {best["wall_s"]:>10.1f}', flush=True)
    if 1 in rates:
        for workers in sorted(rates):
            if workers > 1:
                print(f'scaling {workers} workers / 1: {rates[workers] / rates[1]:.2f}x '
                      f'(ideal {workers}x)')


if __name__ == '__main__':
    main()
