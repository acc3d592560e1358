"""One run, on a worker: the resolved scenario through the headless runner's run path
(``core.load_scenario``, ``core.run_scenario``, ``run_outputs.RunOutputs``: the headless
runner's recording and bag), its outputs written to a temporary folder and checked. A worker
that shares the driver's file system then renames that folder into the dataset; one on
another machine hands the files back as bytes (``outputs.Destination``).

A run's outputs are those of ``paper_sim_headless --scenario runs/<id>/scenario.yaml
--metrics-json ... [--bag ...] [--rrd ...]``: the same final positions, to the bit.
"""
from __future__ import annotations

from dataclasses import dataclass
import os
import shutil
import tempfile
import time

import yaml

from ..core import (Scenario, Simulator, build_simulator, load_scenario, run_scenario,
                    write_metrics)
from ..run_outputs import RunOutputs
from .manifest import run_record
from .outputs import (BAG_DIR, METRICS_FILE, RRD_FILE, SCENARIO_FILE, Destination,
                      new_partial, output_problem, publish, read_tree)
from .spec import Outputs, RunRequest

TEST_PID_DIR_ENV = 'PAPER_SIM_DATASET_TEST_PID_DIR'
"""For tests only: a folder where each run, as it starts, leaves ``<id>.<pid>.pid`` and, on
its first attempt, waits ``TEST_HOLD_S``, so that a test can kill its worker mid-run. The
driver reads it from its environment and hands it to the runs (``run_batch``)."""
TEST_HOLD_S = 2.0


@dataclass(frozen=True)
class RunResult:
    id: str
    status: str
    """'ok', or 'failed' (the scenario was refused; ``reason`` says why)."""
    wall_s: float
    """Seconds the run took on its worker, outputs written and checked."""
    metrics: dict | None = None
    files: dict[str, bytes] | None = None
    """The run's folder, by relative path (``outputs.read_tree``), unless ``in_place``."""
    in_place: bool = False
    """The worker published the run's folder in the dataset itself."""
    reason: str | None = None


def execute_run(request: RunRequest, outputs: Outputs, destination: Destination,
                test_pid_dir: str | None) -> RunResult:
    """Run ``request``: its folder published in ``destination`` when the worker shares the
    driver's file system, else its files returned. A scenario that cannot be loaded or
    built (``ValueError``: an unknown key, a value out of range) is a failed run at once:
    trying again cannot help. Anything else that goes wrong raises, and the batch retries
    it."""
    started = time.perf_counter()
    if test_pid_dir:
        _announce_for_tests(test_pid_dir, request.id)
    try:
        scenario = load_scenario(request.scenario)
        simulator = build_simulator(scenario)
    except ValueError as error:
        return RunResult(request.id, 'failed', time.perf_counter() - started,
                         reason=f'scenario refused: {error}')
    in_place = destination.shared()
    directory = (new_partial(destination.runs_dir, request.id) if in_place
                 else tempfile.mkdtemp(prefix='paper_sim_run_'))
    try:
        with open(os.path.join(directory, SCENARIO_FILE), 'w', encoding='utf-8') as stream:
            yaml.safe_dump(request.scenario, stream, sort_keys=False)
        metrics = produce(scenario, simulator, outputs, directory)
        problem = output_problem(directory, outputs)
        if problem:
            raise RuntimeError(f'run {request.id} wrote incomplete outputs: {problem}')
        wall_s = time.perf_counter() - started
        if not in_place:
            return RunResult(request.id, 'ok', wall_s, metrics, files=read_tree(directory))
        publish(directory, destination.runs_dir, request.id,
                run_record(request, 'ok', outputs=outputs, wall_s=wall_s, metrics=metrics))
        return RunResult(request.id, 'ok', wall_s, metrics, in_place=True)
    finally:
        shutil.rmtree(directory, ignore_errors=True)  # gone already once published


def produce(scenario: Scenario, simulator: Simulator, outputs: Outputs, directory: str) -> dict:
    """Run ``scenario`` on ``simulator`` (fresh from ``build_simulator``), writing the
    outputs wanted into ``directory`` as ``paper_sim_headless --rrd/--bag`` does; the
    metrics."""
    run_outputs = RunOutputs(
        scenario, simulator, application_id='paper_sim_dataset',
        rrd=os.path.join(directory, RRD_FILE) if outputs.rrd else None,
        bag=os.path.join(directory, BAG_DIR) if outputs.bag else None)
    try:
        metrics = run_scenario(scenario, simulator=simulator, on_frame=run_outputs.on_frame)
    finally:
        run_outputs.close()
    write_metrics(metrics, os.path.join(directory, METRICS_FILE))
    return metrics


def _announce_for_tests(pid_dir: str, run_id: str) -> None:
    first_attempt = not any(name.startswith(f'{run_id}.') for name in os.listdir(pid_dir))
    with open(os.path.join(pid_dir, f'{run_id}.{os.getpid()}.pid'), 'w') as stream:
        stream.write(str(os.getpid()))
    if first_attempt:
        time.sleep(TEST_HOLD_S)
