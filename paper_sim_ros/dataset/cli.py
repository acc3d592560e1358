"""``paper_sim_dataset SPEC --out DIR``: generate a dataset, resumably (issue 17).

    paper_sim_dataset config/dataset_example.yaml --out out/dataset            # this machine
    paper_sim_dataset config/dataset_example.yaml --out out/dataset --address auto

Exit status 0 when every run is ok, 1 when some failed (the others are written), 2 with a
one-line reason on bad input (spec, options, a cluster that cannot be joined), 130 when
interrupted (run the same command again to finish).
"""
from __future__ import annotations

import argparse
import os
import signal
import sys
import time

import ray

from .batch import Cluster, connect, run_batch
from .manifest import RUNS_DIR, run_record, summarize, summary_text, write_manifest
from .outputs import completed_record, remove_partials
from .progress import Progress
from .spec import Outputs, RunRequest, expand, load_spec

MANIFEST_EVERY_S = 2.0
"""The manifest is rewritten at most this often while runs finish, and at the end."""


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog='paper_sim_dataset',
                                     description=__doc__.split('\n')[0].strip('`'))
    parser.add_argument('spec', help='dataset spec (YAML): scenarios, sweep, outputs')
    parser.add_argument('--out', required=True, metavar='DIR',
                        help='the dataset folder: runs/<id>/, manifest.jsonl, summary.json; '
                             'runs already complete there are kept')
    parser.add_argument('--address',
                        help="join a Ray cluster: 'auto' (the one started on this machine "
                             "with ray start), HOST:PORT, or ray://HOST:PORT (Ray Client); "
                             'default: start a local Ray instance')
    parser.add_argument('--workers', type=int,
                        help="CPUs of the local Ray instance: runs at once (default: this "
                             "machine's cores)")
    parser.add_argument('--max-retries', type=int, default=2,
                        help='times a run is tried again when its worker dies or it raises '
                             '(default 2)')
    return parser.parse_args(argv)


def _error(message: object) -> int:
    print(f'paper_sim_dataset: error: {message}', file=sys.stderr)
    return 2


def _raise_keyboard_interrupt(signum, frame) -> None:
    raise KeyboardInterrupt


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        if args.workers is not None and args.address is not None:
            raise ValueError('--workers sizes the local Ray instance; with --address the '
                             "cluster's CPUs run the batch")
        if args.workers is not None and args.workers < 1:
            raise ValueError(f'--workers must be at least 1, got {args.workers}')
        if args.max_retries < 0:
            raise ValueError(f'--max-retries must be at least 0, got {args.max_retries}')
        spec = load_spec(args.spec)
        requests, duplicates = expand(spec)
        runs_dir = os.path.join(args.out, RUNS_DIR)
        os.makedirs(runs_dir, exist_ok=True)
    except (ValueError, OSError) as error:
        return _error(error)
    # a batch stopped by SIGTERM (a CI timeout, a scheduler) ends as one stopped by Ctrl-C
    signal.signal(signal.SIGTERM, _raise_keyboard_interrupt)
    try:
        records = resume_records(requests, runs_dir, spec.outputs)
    except KeyboardInterrupt:
        print('paper_sim_dataset: interrupted', file=sys.stderr)
        return 130
    already_complete = sum(record['status'] == 'ok' for record in records.values())
    todo = [request for request in requests if records[request.id]['status'] != 'ok']
    write_manifest(args.out, list(records.values()))

    cluster = Cluster('nothing (every run was complete)', 0.0)
    finished, batch_s = True, 0.0
    if todo:
        try:
            cluster = connect(args.address, args.workers)
            # ray.init makes SIGTERM exit the process at once: take it back
            signal.signal(signal.SIGTERM, _raise_keyboard_interrupt)
        except KeyboardInterrupt:
            ray.shutdown()
            return 130
        except Exception as error:  # ray.init raises many types: any is a cluster not reached
            ray.shutdown()
            return _error(f'cannot start or join Ray: {type(error).__name__}: {error}')
        print(f'paper_sim_dataset: {len(todo)} runs to do ({already_complete} of '
              f'{len(requests)} already complete) on {cluster.description}, '
              f'{cluster.cpus:g} CPUs', flush=True)
        writer = ThrottledManifest(args.out, records)
        started = time.monotonic()
        try:
            finished = run_batch(todo, runs_dir, spec.outputs, args.max_retries,
                                 Progress(len(todo)), writer.update)
            batch_s = time.monotonic() - started
        finally:
            ray.shutdown()

    write_manifest(args.out, list(records.values()))
    summary = summarize(list(records.values()), already_complete, duplicates, batch_s,
                        cluster.description, cluster.cpus, interrupted=not finished)
    summary.write(args.out)
    print(summary_text(summary, list(records.values()), args.out))
    if not finished:
        return 130
    return 1 if summary.failed else 0


def resume_records(requests: list[RunRequest], runs_dir: str, outputs: Outputs) -> dict:
    """The manifest record of each run, by id in the spec's order: the stored one of a run
    whose folder is complete (how this spec names it: another spec may have asked for the
    same run), else 'pending' (an incomplete folder is removed, and said)."""
    remove_partials(runs_dir)
    records = {}
    for request in requests:
        record, problem = completed_record(runs_dir, request.id, outputs)
        if problem:
            print(f'redoing {request.id}: {problem}')
        pending = run_record(request, 'pending')
        records[request.id] = pending if record is None else {
            **record, **{key: pending[key] for key in ('scenario', 'source', 'parameters')}}
    return records


class ThrottledManifest:
    """Keeps ``records`` (by id) up to date as runs finish, and the manifest on disk with
    them at most every ``MANIFEST_EVERY_S``: a batch that dies leaves a recent one."""

    def __init__(self, out_dir: str, records: dict) -> None:
        self.out_dir = out_dir
        self.records = records
        self._written = time.monotonic()

    def update(self, record: dict) -> None:
        self.records[record['id']] = record
        if time.monotonic() - self._written >= MANIFEST_EVERY_S:
            write_manifest(self.out_dir, list(self.records.values()))
            self._written = time.monotonic()


if __name__ == '__main__':
    sys.exit(main())
