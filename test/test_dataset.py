"""Issue 17: datasets at scale. ``paper_sim_dataset`` runs as a separate process on real Ray
(a local instance, and a cluster started with ``ray start``), never mocked: a spec of two
scenarios by four seeds gives eight valid runs; the same spec on one worker, on a cluster and
through the Ray Client gives the same final positions; a worker killed mid-run is retried, a
bad scenario is recorded with its reason; an interrupted batch resumes with only its
unfinished runs, to the manifest of an uninterrupted one.

Ray is kept on loopback and quiet: token authentication with a token of the test's own (so
nothing is written to ~/.ray), no usage stats, every node on 127.0.0.1
(``RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0``: otherwise Ray binds its servers to the machine's
network address, even when told 127.0.0.1), its sessions under a short /tmp folder (Unix
socket paths are limited to ~107 bytes).
"""
from __future__ import annotations

import io
import json
import os
from pathlib import Path
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time

import pytest
from rosbags.rosbag2 import Reader
import yaml

from paper_sim_ros.dataset.manifest import read_manifest, run_record
from paper_sim_ros.dataset.outputs import (close_destination, completed_record,
                                           open_destination, write_run)
from paper_sim_ros.dataset.progress import Progress
from paper_sim_ros.dataset.run import TEST_PID_DIR_ENV, execute_run
from paper_sim_ros.dataset.spec import Outputs, expand, load_spec, run_id, spec_from_mapping
from paper_sim_ros.headless import main as headless_main
from paper_sim_ros.rerun_replay import is_complete

CAMERA = {'name': 'top', 'width': 64, 'height': 48, 'rate': 10.0}
SPEC = {
    'scenarios': ['crumple', 'aged'],
    'sweep': {'grid': 17, 'duration': 0.4, 'seed': [0, 1, 2, 3], 'cameras': [[CAMERA]]},
    'outputs': {'bag': True, 'rrd': True},
}
"""Two scenarios whose end depends on the seed (random damage; a fractal aged sheet)."""
FRAMES = 24  # 0.4 s at 60 Hz
BAG_TOPICS = {'/paper/points': 'sensor_msgs/msg/PointCloud2',
              '/paper/top/depth/image_raw': 'sensor_msgs/msg/Image',
              '/paper/top/color/image_raw': 'sensor_msgs/msg/Image',
              '/paper/top/camera_info': 'sensor_msgs/msg/CameraInfo',
              '/paper/top/points': 'sensor_msgs/msg/PointCloud2',
              '/tf_static': 'tf2_msgs/msg/TFMessage'}
WALL_TIMES = ('wall_s', 'realtime_factor')
"""What differs between two runs of the same scenario: how long they took."""
BATCH_TIMEOUT_S = 240


# ------------------------------------------------------------------------------ helpers
@pytest.fixture(scope='module')
def ray_env():
    """The environment of every batch and cluster of this module (see the docstring)."""
    ray_tmp = tempfile.mkdtemp(prefix='ray', dir='/tmp')
    env = {**os.environ, 'RAY_AUTH_MODE': 'token', 'RAY_AUTH_TOKEN': secrets.token_hex(32),
           'RAY_USAGE_STATS_ENABLED': '0', 'RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER': '0',
           'RAY_TMPDIR': ray_tmp, 'PYTHONUNBUFFERED': '1'}
    env.pop(TEST_PID_DIR_ENV, None)
    yield env
    shutil.rmtree(ray_tmp, ignore_errors=True)


def write_spec(folder: Path, spec: dict, name: str = 'spec.yaml') -> Path:
    path = folder / name
    path.write_text(yaml.safe_dump(spec))
    return path


def dataset_command(spec: Path, out: Path, *options: str) -> list[str]:
    return [sys.executable, '-m', 'paper_sim_ros.dataset', str(spec), '--out', str(out),
            *options]


def run_dataset(spec: Path, out: Path, *options: str, env: dict,
                expected_status: int = 0) -> str:
    """Run a batch to its end; its standard output."""
    run = subprocess.run(dataset_command(spec, out, *options), env=env, capture_output=True,
                         text=True, timeout=BATCH_TIMEOUT_S)
    assert run.returncode == expected_status, run.stdout[-3000:] + run.stderr[-3000:]
    return run.stdout


def without_wall_times(record: dict) -> dict:
    record = {key: value for key, value in record.items() if key != 'wall_s'}
    if record.get('metrics'):
        record['metrics'] = {key: value for key, value in record['metrics'].items()
                             if key not in WALL_TIMES}
    return record


def hashes(out: Path) -> dict[str, str]:
    return {record['id']: record['metrics']['final_positions_sha256']
            for record in read_manifest(str(out))}


def finished_runs(out: Path) -> set[str]:
    runs = out / 'runs'
    return {path.name for path in runs.iterdir()
            if not path.name.startswith('.') and (path / 'run.json').exists()} \
        if runs.exists() else set()


def recorded_ok(out: Path) -> int:
    """Runs the manifest records as done (it is replaced whole: never half-written)."""
    return sum(record['status'] == 'ok' for record in read_manifest(str(out))) \
        if (out / 'manifest.jsonl').exists() else 0


def wait_for(condition, timeout: float, what: str, process: subprocess.Popen | None = None):
    deadline = time.monotonic() + timeout
    while not condition():
        if process is not None and process.poll() is not None:
            raise AssertionError(f'the batch ended (status {process.returncode}) before '
                                 f'{what}:\n{process.stdout.read()[-3000:]}')
        if time.monotonic() > deadline:
            raise AssertionError(f'timed out waiting for {what}')
        time.sleep(0.05)


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(('127.0.0.1', 0))
        return probe.getsockname()[1]


@pytest.fixture(scope='module')
def reference(tmp_path_factory, ray_env) -> tuple[Path, str]:
    """SPEC on a local Ray instance of two workers, uninterrupted: its folder and output."""
    folder = tmp_path_factory.mktemp('reference')
    env = {**ray_env, 'TMPDIR': str(folder)}
    stdout = run_dataset(write_spec(folder, SPEC), folder / 'out', '--workers', '2', env=env)
    return folder / 'out', stdout


# ------------------------------------------------------------------------- the spec alone
def test_a_spec_expands_every_axis_into_runs_with_stable_ids(tmp_path):
    keyframes = [[0.5, 0, 0, 0.05], [1.5, 0, 0, 0.01]]
    (tmp_path / 'mine.yaml').write_text(yaml.safe_dump({
        'duration': 1.0, 'probes': [{'radius': 0.01, 'keyframes': keyframes}]}))
    spec = spec_from_mapping({
        'scenarios': ['hanging', 'mine.yaml'],
        'sweep': {'grid': 9, 'material': ['cardboard', 'banknote'], 'fragility': [0.5, 2.0],
                  'area_conservation': 0.5, 'probe_speed': [1.0, 2.0],
                  'cameras': [[], [CAMERA]]},
        'outputs': {'metrics': True, 'bag': True}}, str(tmp_path))
    runs, duplicates = expand(spec)
    # hanging has no probe: its two probe speeds are one run
    assert len(runs) == 16 + 16 - 8 and duplicates == 8
    assert [run.name for run in runs] == ['hanging'] * 8 + ['mine'] * 16
    assert spec.outputs.bag and not spec.outputs.rrd
    fast = next(run for run in runs if run.source == 'mine.yaml'
                and run.parameters['probe_speed'] == 2.0)
    assert fast.parameters == {'grid': 9, 'material': 'cardboard', 'fragility': 0.5,
                               'area_conservation': 0.5, 'probe_speed': 2.0, 'cameras': []}
    scenario = fast.scenario
    assert scenario['probes'][0]['keyframes'] == [[0.5, 0, 0, 0.05], [1.0, 0, 0, 0.01]]
    assert scenario['sheet'] == {'nx': 9, 'ny': 9} and scenario['material'] == 'cardboard'
    assert scenario['damage'] == {'fragility': 0.5, 'area_conservation': 0.5}
    assert scenario['cameras'] == []
    # an id is a hash of the resolved scenario: the same again, and the same when the
    # scenario is read back from its YAML
    assert expand(spec)[0] == runs
    assert fast.id == run_id(yaml.safe_load(yaml.safe_dump(scenario)))
    assert len({run.id for run in runs}) == len(runs)


@pytest.mark.parametrize('spec, reason', [
    ({'scenarios': []}, 'scenarios must be a non-empty list'),
    ({'scenarios': ['nope']}, "scenario 'nope' is neither a built-in"),
    ({'scenarios': ['press'], 'sweep': {'colour': [1]}}, "unknown sweep axis 'colour'"),
    ({'scenarios': ['press'], 'sweep': {'probe_speed': [0]}}, 'probe_speed must be factors'),
    ({'scenarios': ['press'], 'sweep': {'cameras': [CAMERA]}}, 'a list of camera lists'),
    ({'scenarios': ['press'], 'outputs': {'bag': 'yes'}}, 'outputs bag must be true or false'),
    ({'scenarios': ['press'], 'outputs': {'video': True}}, 'unknown outputs: video'),
    ({'scenarios': ['press'], 'extra': 1}, 'unknown dataset spec keys: extra'),
    ({'scenarios': [{'sheet': 3}], 'sweep': {'grid': 9}}, 'cannot set grid = 9'),
])
def test_a_bad_spec_is_refused_with_the_reason(tmp_path, spec, reason):
    with pytest.raises(ValueError, match=reason.replace('(', r'\(')):
        expand(spec_from_mapping(spec, str(tmp_path)))


def test_bad_options_and_specs_exit_2_before_ray_starts(tmp_path):
    spec = write_spec(tmp_path, {'scenarios': ['press']})
    for command, reason in [
            (dataset_command(spec, tmp_path / 'out', '--workers', '2', '--address', 'auto'),
             '--workers sizes the local Ray instance'),
            (dataset_command(spec, tmp_path / 'out', '--workers', '0'), '--workers must be'),
            (dataset_command(tmp_path / 'none.yaml', tmp_path / 'out'),
             'cannot read the dataset spec')]:
        run = subprocess.run(command, capture_output=True, text=True, timeout=60)
        assert run.returncode == 2 and reason in run.stderr, run.stderr
    assert not (tmp_path / 'out').exists()


def test_progress_is_a_bar_on_a_terminal_and_lines_in_a_log():
    for interactive in (True, False):
        stream = io.StringIO()
        progress = Progress(3, stream, interactive=interactive)
        progress.start()
        progress.finished(True, 'run a')
        progress.finished(False, 'run b: why')
        progress.close()
        text = stream.getvalue()
        assert '2/3: done 1, failed 1, remaining 1, ETA' in text
        if interactive:
            assert '\r\033[K[################--------] ' in text and 'failed: run b: why\n' in text
        else:
            assert '\r' not in text and text.splitlines()[0].startswith('ok     run a  [1/3')
            assert text.splitlines()[1].startswith('FAILED run b: why  [2/3')


@pytest.mark.parametrize('shared', [True, False],
                         ids=['worker beside the dataset', 'worker on another machine'])
def test_a_run_publishes_its_folder_or_sends_it_back(tmp_path, shared):
    """Without Ray: a worker that sees the batch's mark writes the run's folder into the
    dataset; one that does not (on another machine) returns the files, which the driver
    writes. Either way the folder is complete."""
    runs_dir = tmp_path / 'runs'
    runs_dir.mkdir()
    destination = open_destination(str(runs_dir))
    if not shared:  # a worker elsewhere does not see the mark
        close_destination(destination)
    outputs = Outputs(bag=True, rrd=True)
    request = expand(spec_from_mapping({
        'scenarios': ['press'], 'sweep': {'grid': 9, 'duration': 0.2, 'cameras': [[CAMERA]]},
        'outputs': {'bag': True, 'rrd': True}}, str(tmp_path)))[0][0]
    result = execute_run(request, outputs, destination, None)
    assert result.status == 'ok' and result.in_place == shared
    assert (result.files is None) == shared
    if not shared:
        assert set(result.files) >= {'scenario.yaml', 'metrics.json', 'recording.rrd'}
        assert not (runs_dir / request.id).exists()
        write_run(str(runs_dir), request.id, result.files,
                  run_record(request, 'ok', outputs=outputs, wall_s=result.wall_s,
                             metrics=result.metrics))
    record, problem = completed_record(str(runs_dir), request.id, outputs)
    assert problem == '' and record['metrics'] == result.metrics
    assert record['wall_s'] == result.wall_s
    assert sorted(path.name for path in runs_dir.iterdir()) == sorted(
        [request.id] + ([destination.marker] if shared else []))


# ----------------------------------------------------------------------------- on Ray
@pytest.mark.slow
def test_two_scenarios_by_four_seeds_give_eight_complete_runs(reference):
    out, stdout = reference
    records = read_manifest(str(out))
    assert [(record['scenario'], record['parameters']['seed']) for record in records] == \
        [(name, seed) for name in ('crumple', 'aged') for seed in range(4)]
    assert all(record['status'] == 'ok' and record['reason'] is None for record in records)
    assert len(set(hashes(out).values())) == 8  # every seed ends elsewhere
    for record in records:
        folder = out / 'runs' / record['id']
        assert record['outputs'] == {name: f'runs/{record["id"]}/{path}' for name, path in [
            ('scenario', 'scenario.yaml'), ('metrics', 'metrics.json'), ('bag', 'bag'),
            ('rrd', 'recording.rrd')]}
        scenario = yaml.safe_load((folder / 'scenario.yaml').read_text())
        assert run_id(scenario) == record['id']
        assert (scenario['sheet']['nx'], scenario['sheet']['ny']) == (17, 17)
        assert scenario['cameras'] == [CAMERA]
        metrics = json.loads((folder / 'metrics.json').read_text())
        assert metrics == record['metrics'] and metrics['steps'] == FRAMES
        assert not metrics['nan'] and metrics['mesh_valid']
        assert record['wall_s'] > 0
        with Reader(folder / 'bag') as reader:
            assert {c.topic: c.msgtype for c in reader.connections} == BAG_TOPICS
            counts = {c.topic: c.msgcount for c in reader.connections}
            assert sum(1 for _ in reader.messages()) == reader.message_count
        assert counts['/paper/points'] == FRAMES and counts['/tf_static'] == 1
        assert counts['/paper/top/camera_info'] == 5  # 10 Hz: the first frame, 0.1 ... 0.4 s
        assert is_complete(str(folder / 'recording.rrd'))
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['ok'] == summary['ran'] == 8 and summary['failed'] == 0
    assert summary['cpus'] == 2 and summary['runs_per_minute'] > 0
    # a log gets one plain line per run and the summary
    assert '\r' not in stdout and stdout.count('\nok     ') == 8
    assert 'ok 8, failed 0, pending 0; 0 already complete, 8 ran' in stdout
    assert 'by scenario: crumple 4/4 ok, aged 4/4 ok' in stdout


@pytest.mark.slow
def test_a_run_is_what_the_headless_runner_makes_of_its_scenario(reference, tmp_path):
    out, _ = reference
    record = read_manifest(str(out))[1]
    metrics = tmp_path / 'metrics.json'
    assert headless_main(['--scenario', str(out / record['outputs']['scenario']),
                          '--metrics-json', str(metrics)]) == 0
    assert json.loads(metrics.read_text())['final_positions_sha256'] == \
        record['metrics']['final_positions_sha256']


@pytest.mark.slow
def test_one_worker_makes_the_same_runs_as_two(reference, tmp_path, ray_env):
    out, _ = reference
    run_dataset(write_spec(tmp_path, SPEC), tmp_path / 'out', '--workers', '1',
                env={**ray_env, 'TMPDIR': str(tmp_path)})
    assert hashes(tmp_path / 'out') == hashes(out)


@pytest.mark.slow
def test_an_interrupted_batch_resumes_with_only_its_unfinished_runs(reference, tmp_path,
                                                                    ray_env):
    out = tmp_path / 'out'
    spec = write_spec(tmp_path, SPEC)
    pid_dir = tmp_path / 'pids'
    pid_dir.mkdir()
    # each run holds 2 s at its start (the test hook), so the batch is caught half-way
    env = {**ray_env, 'TMPDIR': str(tmp_path), TEST_PID_DIR_ENV: str(pid_dir)}
    # SIGINT as a terminal sends it, even where the tests run in a background job (which
    # ignores it, and a child Python started so would never see it)
    batch = subprocess.Popen(dataset_command(spec, out, '--workers', '1'), env=env,
                             stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                             preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        # three runs recorded (a run's folder is complete a moment before the driver records
        # it; the next run then holds 2 s at its start, so nothing finishes meanwhile)
        wait_for(lambda: recorded_ok(out) >= 3, BATCH_TIMEOUT_S, 'three runs', batch)
        batch.send_signal(signal.SIGINT)
        output, _ = batch.communicate(timeout=60)
    finally:
        batch.kill()
    assert batch.returncode == 130, output
    kept = finished_runs(out)
    statuses = [record['status'] for record in read_manifest(str(out))]
    assert statuses.count('ok') == len(kept) and 3 <= len(kept) < 8, output
    assert statuses.count('pending') == 8 - len(kept) and '(interrupted;' in output
    assert 'run the same command again to finish' in output
    # what a dead machine leaves: a half-written folder, and a complete-looking run whose
    # bag was cut short; both are redone
    (out / 'runs' / '.partial-0123-x').mkdir()
    damaged = sorted(kept)[0]
    mcap = next((out / 'runs' / damaged / 'bag').glob('*.mcap'))
    mcap.write_bytes(mcap.read_bytes()[:1000])
    untouched = {name: (out / 'runs' / name / 'run.json').stat().st_ino
                 for name in kept - {damaged}}

    output = run_dataset(spec, out, '--workers', '2', env={**ray_env, 'TMPDIR': str(tmp_path)})
    assert f'redoing {damaged}: bag does not read' in output
    assert f'{8 - len(untouched)} runs to do ({len(untouched)} of 8 already complete)' in output
    assert output.count('\nok     ') == 8 - len(untouched)
    assert {name: (out / 'runs' / name / 'run.json').stat().st_ino
            for name in untouched} == untouched
    assert not (out / 'runs' / '.partial-0123-x').exists()
    assert [without_wall_times(record) for record in read_manifest(str(out))] == \
        [without_wall_times(record) for record in read_manifest(str(reference[0]))]

    # and once more: nothing to do, nothing started
    output = run_dataset(spec, out, env=ray_env)
    assert 'ok 8, failed 0, pending 0; 8 already complete, 0 ran' in output
    assert 'nothing ran' in output


@pytest.mark.slow
def test_sigterm_stops_a_batch_as_ctrl_c_does(tmp_path, ray_env):
    """ray.init makes SIGTERM exit at once; a batch stopped by a scheduler or a CI timeout
    still cancels its runs and leaves its manifest."""
    pid_dir = tmp_path / 'pids'
    pid_dir.mkdir()
    out = tmp_path / 'out'
    env = {**ray_env, 'TMPDIR': str(tmp_path), TEST_PID_DIR_ENV: str(pid_dir)}
    batch = subprocess.Popen(dataset_command(write_spec(tmp_path, SPEC), out, '--workers', '1'),
                             env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                             text=True)
    try:
        wait_for(lambda: any(pid_dir.iterdir()), BATCH_TIMEOUT_S, 'a run to start', batch)
        batch.terminate()
        output, _ = batch.communicate(timeout=60)
    finally:
        batch.kill()
    assert batch.returncode == 130, output
    assert [record['status'] for record in read_manifest(str(out))] == ['pending'] * 8
    assert 'ok 0, failed 0, pending 8' in output and finished_runs(out) == set()


@pytest.mark.slow
def test_a_killed_worker_is_retried_and_a_bad_scenario_is_recorded(tmp_path, ray_env):
    (tmp_path / 'bad.yaml').write_text(yaml.safe_dump({'duration': 1.0, 'colour': 'red'}))
    spec = write_spec(tmp_path, {
        'scenarios': ['press', 'bad.yaml'],
        'sweep': {'grid': 17, 'duration': 0.4, 'seed': [0, 1], 'cameras': [[CAMERA]]},
        'outputs': {'bag': True}})
    runs = {run.id: run for run in expand(load_spec(str(spec)))[0]}
    pid_dir = tmp_path / 'pids'
    pid_dir.mkdir()
    out = tmp_path / 'out'
    env = {**ray_env, 'TMPDIR': str(tmp_path), TEST_PID_DIR_ENV: str(pid_dir)}
    batch = subprocess.Popen(dataset_command(spec, out, '--workers', '2'), env=env,
                             stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        def press_pid_files() -> list[Path]:
            return [path for path in pid_dir.iterdir() if runs[path.name[:16]].name == 'press']

        wait_for(press_pid_files, BATCH_TIMEOUT_S, 'a press run to start', batch)
        victim = press_pid_files()[0]
        os.kill(int(victim.read_text()), signal.SIGKILL)  # its worker, mid-run
        output, _ = batch.communicate(timeout=BATCH_TIMEOUT_S)
    finally:
        batch.kill()
    assert batch.returncode == 1, output  # some runs failed; the rest are written
    killed = victim.name[:16]
    attempts = sorted(path.name for path in pid_dir.iterdir() if path.name.startswith(killed))
    assert len(attempts) == 2, attempts  # tried again, in another worker process
    records = {record['id']: record for record in read_manifest(str(out))}
    assert records.keys() == runs.keys()
    for identifier, record in records.items():
        if runs[identifier].name == 'press':
            assert record['status'] == 'ok'
            assert json.loads((out / 'runs' / identifier / 'metrics.json').read_text()) == \
                record['metrics']
            with Reader(out / 'runs' / identifier / 'bag') as reader:
                assert reader.message_count > FRAMES
        else:
            assert record['status'] == 'failed' and record['metrics'] is None
            assert record['reason'].startswith('scenario refused: unknown scenario keys: colour')
            assert not (out / 'runs' / identifier).exists()
    assert 'ok 2, failed 2, pending 0' in output and 'failed ' + next(
        identifier for identifier in runs if runs[identifier].name == 'bad') in output


@pytest.mark.slow
def test_a_batch_joins_a_cluster_started_with_ray_start(reference, tmp_path, ray_env):
    """A real cluster of separate processes on loopback: GCS, raylet and workers from
    ``ray start --head``; the batch joins it as a driver, by its address and through the
    Ray Client, and makes the same runs as the local instance."""
    port, client_port = free_port(), free_port()
    log = tmp_path / 'ray_start.log'
    env = {**ray_env, 'TMPDIR': str(tmp_path)}
    ray_bin = str(Path(sys.executable).parent / 'ray')
    with open(log, 'w') as log_stream:
        head = subprocess.Popen(
            [ray_bin, 'start', '--head', '--block', '--node-ip-address', '127.0.0.1',
             '--port', str(port), '--ray-client-server-port', str(client_port),
             '--num-cpus', '2', '--include-dashboard=false', '--disable-usage-stats',
             '--temp-dir', os.path.join(ray_env['RAY_TMPDIR'], 'cluster')],
            env=env, stdout=log_stream, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        wait_for(lambda: 'Ray runtime started' in log.read_text(), 120, 'the Ray head')
        spec = write_spec(tmp_path, SPEC)
        for address in (f'127.0.0.1:{port}', f'ray://127.0.0.1:{client_port}'):
            out = tmp_path / address.replace(':', '_').replace('/', '')
            stdout = run_dataset(spec, out, '--address', address, env=env)
            assert f'on the Ray cluster at {address}, 2 CPUs' in stdout
            assert hashes(out) == hashes(reference[0])
    finally:
        stop_ray_head(head)
    assert 'Ray runtime started' in log.read_text()


def stop_ray_head(head: subprocess.Popen) -> None:
    """``ray start --block`` shuts its cluster down on SIGTERM; whatever of its process
    group is left after that is killed."""
    head.terminate()
    try:
        head.wait(timeout=60)
    except subprocess.TimeoutExpired:
        head.kill()
        head.wait()
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline:
        try:
            os.killpg(head.pid, 0)
        except ProcessLookupError:
            return
        time.sleep(0.2)
    os.killpg(head.pid, signal.SIGKILL)
