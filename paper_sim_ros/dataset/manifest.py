"""The dataset's manifest, ``DIR/manifest.jsonl``: one JSON object per run of the spec, in
the spec's order, and the summary printed at the end of a batch.

A record: ``id``, ``scenario`` (its name), ``source`` (the spec's entry), ``parameters``
(the sweep's values), ``status`` ('ok', 'failed', or 'pending': not run yet, the batch was
interrupted), ``reason`` (why it failed), ``wall_s`` (the run on its worker), ``metrics``
(the headless runner's) and ``outputs`` (paths relative to DIR). The file is rewritten
whole and renamed into place, so a reader never sees half of it.
"""
from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
import json
import os

from .outputs import output_files
from .progress import format_duration
from .spec import Outputs, RunRequest, describe_run

MANIFEST_FILE = 'manifest.jsonl'
RUNS_DIR = 'runs'
SUMMARY_FILE = 'summary.json'
FAILURES_SHOWN = 8


def run_record(request: RunRequest, status: str, *, outputs: Outputs | None = None,
               wall_s: float | None = None, metrics: dict | None = None,
               reason: str | None = None) -> dict:
    """The manifest record of ``request``; ``outputs``: what its folder holds (status ok)."""
    return {
        'id': request.id,
        'scenario': request.name,
        'source': request.source,
        'parameters': request.parameters,
        'status': status,
        'reason': reason,
        'wall_s': wall_s,
        'metrics': metrics,
        'outputs': None if outputs is None else {
            name: f'{RUNS_DIR}/{request.id}/{path}'
            for name, path in output_files(outputs).items()},
    }


def write_manifest(out_dir: str, records: list[dict]) -> None:
    path = os.path.join(out_dir, MANIFEST_FILE)
    with open(f'{path}.tmp', 'w', encoding='utf-8') as stream:
        for record in records:
            stream.write(json.dumps(record, sort_keys=True) + '\n')
    os.replace(f'{path}.tmp', path)


def read_manifest(out_dir: str) -> list[dict]:
    with open(os.path.join(out_dir, MANIFEST_FILE), encoding='utf-8') as stream:
        return [json.loads(line) for line in stream if line.strip()]


@dataclass(frozen=True)
class BatchSummary:
    """What a batch did: counts, the time its runs took, where it ran."""

    runs: int
    ok: int
    failed: int
    pending: int
    already_complete: int
    """Runs found complete in DIR and not run again."""
    ran: int
    """Runs that finished in this batch, ok or failed."""
    duplicates: int
    """Combinations of the spec that were the same run as an earlier one."""
    batch_s: float
    """From the first run submitted to the last one finished."""
    cluster: str
    cpus: float
    interrupted: bool

    @property
    def runs_per_minute(self) -> float:
        return 60.0 * self.ran / self.batch_s if self.batch_s > 0 else 0.0

    def write(self, out_dir: str) -> None:
        """``DIR/summary.json``: the figures, for scripts (the benchmark reads it)."""
        values = {**self.__dict__, 'runs_per_minute': self.runs_per_minute}
        with open(os.path.join(out_dir, SUMMARY_FILE), 'w', encoding='utf-8') as stream:
            stream.write(json.dumps(values, indent=1) + '\n')


def summarize(records: list[dict], already_complete: int, duplicates: int, batch_s: float,
              cluster: str, cpus: float, interrupted: bool) -> BatchSummary:
    counts = Counter(record['status'] for record in records)
    return BatchSummary(
        runs=len(records), ok=counts['ok'], failed=counts['failed'],
        pending=counts['pending'], already_complete=already_complete,
        ran=counts['ok'] + counts['failed'] - already_complete, duplicates=duplicates,
        batch_s=batch_s, cluster=cluster, cpus=cpus, interrupted=interrupted)


def summary_text(summary: BatchSummary, records: list[dict], out_dir: str) -> str:
    """The one-screen summary: counts, pace, runs by scenario, the first failures."""
    lines = [
        f'paper_sim_dataset: {summary.runs} runs in {out_dir} '
        f'({"interrupted" if summary.interrupted else "finished"}; {MANIFEST_FILE})',
        f'  ok {summary.ok}, failed {summary.failed}, pending {summary.pending}; '
        f'{summary.already_complete} already complete, {summary.ran} ran'
        + (f'; {summary.duplicates} duplicate combinations dropped'
           if summary.duplicates else ''),
        f'  {summary.ran} runs in {format_duration(summary.batch_s)} '
        f'({summary.runs_per_minute:.1f} runs/min) on {summary.cluster}, '
        f'{summary.cpus:g} CPUs' if summary.ran else '  nothing ran',
    ]
    by_scenario: dict[str, Counter] = {}
    for record in records:
        by_scenario.setdefault(record['scenario'], Counter())[record['status']] += 1
    lines.append('  by scenario: ' + ', '.join(
        f'{name} {counts["ok"]}/{sum(counts.values())} ok'
        for name, counts in by_scenario.items()))
    failures = [record for record in records if record['status'] == 'failed']
    for record in failures[:FAILURES_SHOWN]:
        run = describe_run(record['id'], record['scenario'], record['parameters'])
        lines.append(f'  failed {run}: {record["reason"]}')
    if len(failures) > FAILURES_SHOWN:
        lines.append(f'  ... {len(failures) - FAILURES_SHOWN} more failures in '
                     f'{MANIFEST_FILE}')
    if summary.pending:
        lines.append('  run the same command again to finish: complete runs are kept')
    return '\n'.join(lines)
