"""A run's folder, ``DIR/runs/<id>/``: what is in it, whether it is complete, how it is written.

    scenario.yaml   the resolved scenario: ``paper_sim_headless --scenario`` it to redo the run
    metrics.json    the headless runner's metrics (always)
    bag/            rosbag2 (MCAP), when the spec asks for it
    recording.rrd   Rerun recording, when the spec asks for it
    run.json        the run's manifest record but its metrics: written last

A folder is complete only when every file wanted reads back (``output_problem``): a folder
that is merely there may be the remains of a machine that died while writing. Folders are
written whole under a temporary name and renamed (``publish``), so a complete folder never
stands beside a half-written one of the same name. A worker that shares the driver's file
system writes its run's folder itself; any other sends the files back and the driver writes
them (``Destination``, ``write_run``).
"""
from __future__ import annotations

from dataclasses import dataclass
import json
import os
import shutil
import tempfile
import uuid

import yaml
from rosbags.rosbag2 import Reader

from ..rerun_replay import is_complete
from .spec import Outputs

SCENARIO_FILE = 'scenario.yaml'
METRICS_FILE = 'metrics.json'
BAG_DIR = 'bag'
RRD_FILE = 'recording.rrd'
RECORD_FILE = 'run.json'
PARTIAL_PREFIX = '.partial-'
BATCH_MARKER_PREFIX = '.batch-'


def output_files(outputs: Outputs) -> dict[str, str]:
    """Each output of a run (scenario, metrics, bag, rrd) and its path in the run's folder."""
    files = {'scenario': SCENARIO_FILE, 'metrics': METRICS_FILE}
    if outputs.bag:
        files['bag'] = BAG_DIR
    if outputs.rrd:
        files['rrd'] = RRD_FILE
    return files


def read_metrics(directory: str) -> dict:
    with open(os.path.join(directory, METRICS_FILE), encoding='utf-8') as stream:
        return json.load(stream)


def output_problem(directory: str, outputs: Outputs) -> str | None:
    """Why the outputs in ``directory`` are not those of a complete run, None when they are:
    the scenario and the metrics parse, the bag opens and every message in it reads, the
    recording has its footer (it was closed)."""
    try:
        with open(os.path.join(directory, SCENARIO_FILE), encoding='utf-8') as stream:
            if not isinstance(yaml.safe_load(stream), dict):
                return f'{SCENARIO_FILE} holds no scenario'
        metrics = read_metrics(directory)
    except (OSError, ValueError, yaml.YAMLError) as error:
        return f'unreadable: {error}'
    if not isinstance(metrics, dict) or len(str(metrics.get('final_positions_sha256'))) != 64:
        return f'{METRICS_FILE} has no final_positions_sha256'
    if outputs.bag:
        problem = _bag_problem(os.path.join(directory, BAG_DIR))
        if problem:
            return problem
    if outputs.rrd and not is_complete(os.path.join(directory, RRD_FILE)):
        return f'{RRD_FILE} is missing or was not closed'
    return None


def _bag_problem(path: str) -> str | None:
    try:
        with Reader(path) as reader:
            expected = reader.message_count
            read = sum(1 for _ in reader.messages())
    except Exception as error:  # rosbags raises its own types, and struct/OS errors inside
        return f'{BAG_DIR} does not read: {type(error).__name__}: {error}'
    if read == 0 or read != expected:
        return f'{BAG_DIR}: {read} messages read, {expected} in its metadata'
    return None


def read_tree(directory: str) -> dict[str, bytes]:
    """Every file under ``directory`` by its relative path: a run's outputs as they travel
    from a worker, wherever it is, to the driver that writes the dataset."""
    files = {}
    for root, _, names in os.walk(directory):
        for name in names:
            path = os.path.join(root, name)
            with open(path, 'rb') as stream:
                files[os.path.relpath(path, directory)] = stream.read()
    return files


@dataclass(frozen=True)
class Destination:
    """Where the runs' folders go: ``runs_dir`` (absolute) on the driver's machine, and
    ``marker``, a file the driver made in it for this batch. A worker that sees the marker
    shares the driver's file system (the same machine, or a shared mount at the same path)
    and writes its run's folder in place; one that does not sends it back through Ray."""

    runs_dir: str
    marker: str

    def shared(self) -> bool:
        return os.path.isfile(os.path.join(self.runs_dir, self.marker))


def open_destination(runs_dir: str) -> Destination:
    """Mark ``runs_dir`` for a batch (``close_destination`` removes the mark)."""
    marker = f'{BATCH_MARKER_PREFIX}{uuid.uuid4().hex}'
    with open(os.path.join(runs_dir, marker), 'w', encoding='utf-8'):
        pass
    return Destination(os.path.abspath(runs_dir), marker)


def close_destination(destination: Destination) -> None:
    os.remove(os.path.join(destination.runs_dir, destination.marker))


def new_partial(runs_dir: str, run_id: str) -> str:
    """A new temporary folder for run ``run_id`` in ``runs_dir``, to be ``publish``ed."""
    return tempfile.mkdtemp(prefix=f'{PARTIAL_PREFIX}{run_id}-', dir=runs_dir)


def publish(partial: str, runs_dir: str, run_id: str, record: dict) -> None:
    """Make the complete outputs in ``partial`` the folder of run ``run_id``: ``run.json``
    (``record`` without its metrics, which are in metrics.json) written last, the folder
    renamed into place; an earlier incomplete folder of the run is replaced."""
    stored = {key: value for key, value in record.items() if key != 'metrics'}
    with open(os.path.join(partial, RECORD_FILE), 'w', encoding='utf-8') as stream:
        stream.write(json.dumps(stored, indent=1) + '\n')
    final = os.path.join(runs_dir, run_id)
    if os.path.exists(final):
        shutil.rmtree(final)
    os.rename(partial, final)


def write_run(runs_dir: str, run_id: str, files: dict[str, bytes], record: dict) -> None:
    """Write the folder of run ``run_id`` from its files as ``read_tree`` read them on a
    worker elsewhere, and ``publish`` it."""
    partial = new_partial(runs_dir, run_id)
    for relative, data in files.items():
        path = os.path.join(partial, relative)
        os.makedirs(os.path.dirname(path), exist_ok=True)
        with open(path, 'wb') as stream:
            stream.write(data)
    publish(partial, runs_dir, run_id, record)


def completed_record(runs_dir: str, run_id: str, outputs: Outputs) -> tuple[dict | None, str]:
    """The manifest record of run ``run_id`` when its folder holds a complete run with every
    output wanted, else None and why not ('' when there is no folder); an incomplete folder
    is removed, to be redone."""
    directory = os.path.join(runs_dir, run_id)
    if not os.path.isdir(directory):
        return None, ''
    try:
        with open(os.path.join(directory, RECORD_FILE), encoding='utf-8') as stream:
            record = json.load(stream)
        problem = (None if record.get('id') == run_id and record.get('status') == 'ok'
                   else f'{RECORD_FILE} is not that of a finished run {run_id}')
    except (OSError, ValueError) as error:
        problem = f'{RECORD_FILE} unreadable: {error}'
    # outputs asked for now that the earlier batch did not write are missing too
    problem = problem or output_problem(directory, outputs)
    if problem:
        shutil.rmtree(directory)
        return None, problem
    record['metrics'] = read_metrics(directory)
    return record, ''


def remove_partials(runs_dir: str) -> None:
    """Remove what batches that were cut short left: runs' temporary folders, marks."""
    for name in os.listdir(runs_dir):
        path = os.path.join(runs_dir, name)
        if name.startswith(PARTIAL_PREFIX):
            shutil.rmtree(path)
        elif name.startswith(BATCH_MARKER_PREFIX):
            os.remove(path)
