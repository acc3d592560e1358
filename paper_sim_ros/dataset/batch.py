"""The runs of a dataset as Ray tasks, one CPU each, on a local Ray instance or a cluster.

Each run is a task (``run.execute_run``). A worker on the driver's machine (or sharing its
file system at the same path) writes the run's folder into the dataset itself; one elsewhere
returns the outputs as bytes and the driver writes them, so a cluster needs no shared file
system. Either way a run's folder appears whole or not at all (``outputs.publish``). Ray
retries a task whose worker died (killed, out of memory, its node lost) or that raised, up
to ``max_retries`` times; a run still failing then is recorded as failed with the reason,
and the batch goes on.
"""
from __future__ import annotations

from dataclasses import dataclass
import logging
import os
from typing import Callable

import ray
from ray.exceptions import RayError, RayTaskError

from .manifest import run_record
from .outputs import close_destination, open_destination, write_run
from .progress import Progress
from .run import TEST_PID_DIR_ENV, RunResult, execute_run
from .spec import Outputs, RunRequest

WAIT_S = 0.5
"""How often the driver redraws the progress bar while no run finishes."""
JOIN_ATTEMPTS = 2
"""Attempts to join a cluster by its address before the batch gives up."""


@dataclass(frozen=True)
class Cluster:
    description: str
    cpus: float


def connect(address: str | None, workers: int | None) -> Cluster:
    """Start a local Ray instance with ``workers`` CPUs (None: this machine's), or join the
    cluster at ``address`` ('auto', 'host:port', 'ray://host:port'). Ray's own messages
    below warnings are kept quiet; the workers' output is not forwarded (a run's failure
    reaches the manifest with its reason)."""
    quiet = {'log_to_driver': False, 'logging_level': logging.WARNING}
    if address is None:
        ray.init(num_cpus=workers, include_dashboard=False, **quiet)
        description = 'a local Ray instance'
    else:
        for attempt in range(JOIN_ATTEMPTS):
            try:
                ray.init(address=address, **quiet)
                break
            except ConnectionError:
                # a Ray Client server starts one server per driver, which can fail to come
                # up on a loaded machine ("Starting Ray client server failed"): ask again
                ray.shutdown()
                if attempt == JOIN_ATTEMPTS - 1:
                    raise
        description = f'the Ray cluster at {address}'
    return Cluster(description, float(ray.cluster_resources().get('CPU', 0.0)))


def run_batch(requests: list[RunRequest], runs_dir: str, outputs: Outputs, max_retries: int,
              progress: Progress, on_record: Callable[[dict], None]) -> bool:
    """Run ``requests``, writing each finished run's folder into ``runs_dir`` and handing its
    manifest record to ``on_record``, as runs finish. Returns False when interrupted
    (KeyboardInterrupt: the runs not finished are cancelled; the finished ones are kept)."""
    task = ray.remote(num_cpus=1, max_retries=max_retries, retry_exceptions=True)(execute_run)
    test_pid_dir = os.environ.get(TEST_PID_DIR_ENV)
    destination = open_destination(runs_dir)
    pending = {task.remote(request, outputs, destination, test_pid_dir): request
               for request in requests}
    progress.start()
    try:
        while pending:
            # the first run to finish at once, with every other finished by then
            ready, _ = ray.wait(list(pending), num_returns=1, timeout=WAIT_S)
            if ready:
                ready, _ = ray.wait(list(pending), num_returns=len(pending), timeout=0)
            for ref in ready:
                request = pending.pop(ref)
                record = _finish(ref, request, runs_dir, outputs, max_retries)
                progress.finished(record['status'] == 'ok',
                                  request.label + (f': {record["reason"]}'
                                                   if record['reason'] else ''))
                on_record(record)
            progress.refresh()
    except KeyboardInterrupt:
        for ref in pending:
            ray.cancel(ref)
        return False
    finally:
        progress.close()
        close_destination(destination)
    return True


def _finish(ref: ray.ObjectRef, request: RunRequest, runs_dir: str, outputs: Outputs,
            max_retries: int) -> dict:
    """The manifest record of a finished task; a successful run's folder written."""
    attempts = f'after {max_retries + 1} attempts'
    try:
        result: RunResult = ray.get(ref)
    except RayTaskError as error:  # the run raised, every attempt
        cause = error.cause if error.cause is not None else error
        return run_record(request, 'failed',
                          reason=f'{type(cause).__name__}: {_first_line(cause)} ({attempts})')
    except RayError as error:  # its worker died every attempt, or its node went away
        return run_record(request, 'failed',
                          reason=f'{type(error).__name__}: {_first_line(error)} ({attempts})')
    if result.status != 'ok':
        return run_record(request, 'failed', wall_s=result.wall_s, reason=result.reason)
    record = run_record(request, 'ok', outputs=outputs, wall_s=result.wall_s,
                        metrics=result.metrics)
    if not result.in_place:
        write_run(runs_dir, request.id, result.files, record)
    return record


def _first_line(error: BaseException) -> str:
    lines = [line for line in str(error).splitlines() if line.strip()]
    return lines[0].strip() if lines else ''
