"""Rerun recording (SPEC §8, issue 6): every test reads the real .rrd back with Rerun's own API
(``rerun.chunk.RrdReader``), never a mock of it."""
from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path
import shutil
import signal
import socket
import subprocess
import sys
import time

import numpy as np
import pytest
from rerun.chunk import RrdReader
import yaml

from paper_sim_ros import rerun_replay
from paper_sim_ros.core import build_simulator, run_scenario
from paper_sim_ros.core.scenarios import scenario_from_mapping
from paper_sim_ros.headless import main as headless_main
from paper_sim_ros.rerun_logger import ENTITY_SPRINGS, RerunRecorder, view_bounds

REPO = Path(__file__).resolve().parents[1]
METRICS = ('step_time', 'real_time_factor', 'energy', 'max_strain', 'breaks', 'folds')

# Two fingertips press a small sheet on a table and push towards each other: it buckles and
# breaks (damage driven by the probe inputs), 17 x 17 vertices, 1 s.
PINCH = {
    'name': 'pinch',
    'description': 'two probes squeeze a small sheet on a table until it creases',
    'duration': 1.0,
    'seed': 7,
    'sheet': {'nx': 17, 'ny': 17, 'width': 0.1, 'height': 0.1},
    'contact': {'ground_enabled': True},
    'damage': {'fragility': 0.5},
    'probes': [
        {'name': 'left', 'radius': 0.012,
         'keyframes': [[0.0, 0.0, -0.04, 0.03], [0.25, 0.0, -0.04, 0.011],
                       [0.9, 0.0, -0.01, 0.011], [1.0, 0.0, -0.01, 0.03]]},
        {'name': 'right', 'radius': 0.012,
         'keyframes': [[0.0, 0.0, 0.04, 0.03], [0.25, 0.0, 0.04, 0.011],
                       [0.9, 0.0, 0.01, 0.011], [1.0, 0.0, 0.01, 0.03]]},
    ],
}


def record(mapping: dict, path: Path, probe_inputs=None, **recorder_options) -> dict:
    """Run ``mapping`` with a recorder; what the simulator was at every frame, for comparing."""
    scenario = scenario_from_mapping(mapping)
    simulator = build_simulator(scenario)
    dt = scenario.config.solver.dt
    truth = {'vertex_counts': [], 'positions': [], 'topology_changes': 0, 'inputs': []}
    triangles = [None]
    recorder = RerunRecorder('paper_sim_test', path=str(path),
                             recording_info={'scenario': scenario.mapping}, **recorder_options)
    try:
        for frame in range(1, scenario.frame_count + 1):
            inputs = (probe_inputs or scenario.probe_inputs)(frame * dt)
            simulator.set_probes(*inputs)
            simulator.step_frame()
            sheet = simulator.sheet
            truth['vertex_counts'].append(sheet.vertex_count)
            truth['positions'].append(sheet.positions.copy())
            truth['inputs'].append(inputs)
            if triangles[0] is None or not np.array_equal(triangles[0], sheet.triangles):
                truth['topology_changes'] += 1
                triangles[0] = sheet.triangles.copy()
            recorder.log_frame(simulator.time, simulator,
                               scalars={'step_time': 1e-3, 'real_time_factor': 16.7})
    finally:
        recorder.close()
    truth['final_sha256'] = simulator.sheet.positions_sha256()
    truth['final_springs'] = (simulator.sheet.spring_vertices.copy(),
                              simulator.sheet.spring_kind.copy())
    truth['breaks'] = simulator.breaks
    truth['frames'] = scenario.frame_count
    truth['dt'] = dt
    truth['config'] = simulator.config
    return truth


@pytest.fixture(scope='module')
def pinch_recording(tmp_path_factory):
    path = tmp_path_factory.mktemp('rerun') / 'pinch.rrd'
    truth = record(PINCH, path)
    assert truth['breaks'] > 0, 'the pinch scenario should damage the sheet'
    return path, truth


def chunks_of(path: Path, entity: str) -> list:
    return [c for c in RrdReader(path).stream() if c.entity_path == '/' + entity]


def last_row_points(path: Path, entity: str, column: str) -> np.ndarray:
    """The points of ``entity``'s ``column`` in its last row on the sim_time timeline."""
    rows = []
    for chunk in chunks_of(path, entity):
        if chunk.is_static:
            continue
        batch = chunk.to_record_batch()
        times = batch.column('sim_time').cast('int64').to_pylist()
        rows.extend((times[row], batch.column(column)[row]) for row in range(batch.num_rows))
    value = max(rows, key=lambda row: row[0])[1]
    return value.values.flatten().flatten().to_numpy(zero_copy_only=False).reshape(-1, 3)


# ------------------------------------------------------------------------- reading back
def test_mesh_has_one_row_per_frame_with_the_simulation_vertex_counts(pinch_recording):
    path, truth = pinch_recording
    store = RrdReader(path).store()  # the footer is there: the recording was finished
    assert '/paper/mesh' in store.summary()
    assert any(column.name.endswith('Mesh3D:vertex_positions')
               for column in store.schema().component_columns()), store.schema()
    rows = []
    for chunk in chunks_of(path, 'paper/mesh'):
        if chunk.is_static:
            continue
        assert 'sim_time' in chunk.timeline_names
        batch = chunk.to_record_batch()
        times = batch.column('sim_time').cast('int64').to_pylist()
        positions = batch.column('Mesh3D:vertex_positions')
        for row in range(batch.num_rows):
            flat = positions[row].values.flatten().to_numpy(zero_copy_only=False)
            rows.append((times[row], flat.reshape(-1, 3)))
    rows.sort(key=lambda row: row[0])
    assert len(rows) == truth['frames'], 'one mesh row per frame'
    expected_times = [round(1e9 * k * truth['dt']) for k in range(1, truth['frames'] + 1)]
    np.testing.assert_allclose([t for t, _ in rows], expected_times, atol=2,
                               err_msg='sim_time of the mesh rows')
    counts = [p.shape[0] for _, p in rows]
    assert counts == truth['vertex_counts'], 'vertex counts per frame'
    assert counts[-1] > counts[0], 'damage grew the mesh during the recording'
    for (_, logged), actual in zip(rows, truth['positions']):
        assert np.all(np.isfinite(logged))
        np.testing.assert_allclose(logged, actual, atol=1e-6, err_msg='logged positions')


def test_topology_is_logged_only_when_the_mesh_changes(pinch_recording):
    path, truth = pinch_recording
    frames = rerun_replay.read_mesh_frames(str(path))
    changed = [mesh for mesh in frames if mesh.triangle_count is not None]
    assert len(changed) == truth['topology_changes']
    assert 1 < len(changed) < len(frames)


def test_scalar_series_are_present(pinch_recording):
    path, truth = pinch_recording
    series = rerun_replay.read_scalars(str(path))
    for name in METRICS + ('vertices',):
        times, values = series[name]
        assert len(values) == truth['frames'], name
        assert np.all(np.isfinite(values)), name
    assert series['breaks'][1][-1] == truth['breaks']
    assert series['vertices'][1].tolist() == truth['vertex_counts']
    assert np.all(np.diff(series['breaks'][1]) >= 0)


def test_recording_is_self_describing(pinch_recording):
    path, truth = pinch_recording
    info = rerun_replay.read_recording_info(str(path))
    assert info['scenario'] == scenario_from_mapping(PINCH).mapping
    assert info['scenario']['seed'] == 7
    parameters = rerun_replay.read_parameters(str(path))
    assert parameters['config'] == json.loads(json.dumps(dataclasses.asdict(truth['config'])))
    assert rerun_replay.config_from_dict(parameters['config']) == truth['config']
    reader = RrdReader(path)
    assert len(reader.blueprints()) == 1, 'a default blueprint travels with the recording'
    # probe inputs: every frame, bit for bit what the simulator got
    inputs = rerun_replay.read_probe_inputs(str(path))
    assert [item.frame for item in inputs] == list(range(1, truth['frames'] + 1))
    for item, (centers, radii, active) in zip(inputs, truth['inputs']):
        np.testing.assert_array_equal(item.centers[item.active], centers[active])
        np.testing.assert_array_equal(item.radii, radii)
        np.testing.assert_array_equal(item.active, active)


def test_paper_texture_is_static_and_texture_coordinates_follow_the_mesh(pinch_recording):
    path, truth = pinch_recording
    static = [c.to_record_batch() for c in chunks_of(path, 'paper/mesh') if c.is_static]
    assert any('Mesh3D:albedo_texture_buffer' in batch.schema.names for batch in static)
    for static_batch in static:
        assert 'Mesh3D:vertex_positions' not in static_batch.schema.names
    for chunk in chunks_of(path, 'paper/mesh'):
        batch = chunk.to_record_batch()
        if chunk.is_static or 'Mesh3D:triangle_indices' not in batch.schema.names:
            continue
        for row in range(batch.num_rows):
            if batch.column('Mesh3D:triangle_indices')[row].is_valid:
                assert len(batch.column('Mesh3D:vertex_texcoords')[row]) \
                    == len(batch.column('Mesh3D:vertex_positions')[row])


def test_springs_and_probes_are_logged(pinch_recording):
    path, truth = pinch_recording
    for entity in ('paper/springs/hinge', 'paper/springs/aux', 'paper/probes'):
        temporal = [c for c in chunks_of(path, entity) if not c.is_static]
        assert sum(c.num_rows for c in temporal) > 0, entity
    hinge = [c for c in chunks_of(path, 'paper/springs/hinge') if not c.is_static]
    assert sum(c.num_rows for c in hinge) == truth['frames']
    # the last frame's segments: each spring of its kind from end to end, in spring order
    ends, kinds = truth['final_springs']
    for kind, entity in ENTITY_SPRINGS.items():
        logged = last_row_points(path, entity, 'LineStrips3D:strips')
        expected = truth['positions'][-1][ends[kinds == kind]].astype(np.float32)
        assert np.count_nonzero(kinds == kind) > 0, entity
        np.testing.assert_array_equal(logged, expected.reshape(-1, 3), err_msg=entity)


# --------------------------------------------------------------------------- bad output
def test_unwritable_path_or_absent_viewer_is_a_clear_error(tmp_path):
    with pytest.raises(OSError, match='does not exist'):
        RerunRecorder('t', path=str(tmp_path / 'missing' / 'x.rrd'))
    with pytest.raises(ValueError, match='is a directory'):
        RerunRecorder('t', path=str(tmp_path))
    with pytest.raises(ValueError, match='must end in .rrd'):
        RerunRecorder('t', path=str(tmp_path / 'x.txt'))
    with pytest.raises(OSError, match='cannot write Rerun recording'):
        RerunRecorder('t', path='/proc/paper_sim_test.rrd')  # unwritable, even for root
    with pytest.raises(ValueError, match='rerun_connect'):
        RerunRecorder('t', connect_url='http://localhost:9876')
    with pytest.raises(ConnectionError, match='no Rerun viewer or server'):
        RerunRecorder('t', connect_url=f'rerun+http://127.0.0.1:{_free_port()}/proxy')


def test_headless_refuses_an_unwritable_rrd_before_running(tmp_path, capsys):
    target = tmp_path / 'missing' / 'run.rrd'
    code = headless_main(['--scenario', 'press', '--grid', '17', '--duration', '0.1',
                          '--rrd', str(target)])
    assert code == 2
    error = capsys.readouterr().err
    assert 'cannot write Rerun recording' in error and str(target) in error
    assert '"final_positions_sha256"' not in capsys.readouterr().out


def test_recorder_off_is_a_no_op_and_close_is_idempotent(tmp_path):
    scenario = scenario_from_mapping({**PINCH, 'duration': 0.05})
    simulator = build_simulator(scenario)
    simulator.step_frame()
    off = RerunRecorder('t')
    assert not off.enabled
    off.log_frame(simulator.time, simulator)
    off.close()
    off.close()
    path = tmp_path / 'twice.rrd'
    on = RerunRecorder('t', path=str(path), recording_info={'scenario': scenario.mapping})
    on.log_frame(simulator.time, simulator)
    on.close()
    on.close()
    on.log_frame(simulator.time, simulator)  # after close: ignored, file stays complete
    assert rerun_replay.summary(str(path))['mesh_rows'] == 1
    assert rerun_replay.is_complete(str(path))


# ------------------------------------------------------------------------------- replay
def test_replay_reproduces_the_recorded_run_with_damage(pinch_recording, tmp_path):
    path, truth = pinch_recording
    metrics = rerun_replay.replay(str(path), rrd=str(tmp_path / 'again.rrd'))
    assert metrics['replay_exact']
    assert metrics['replay_frames'] == truth['frames']
    assert metrics['breaks'] == truth['breaks'] > 0
    assert metrics['final_positions_sha256'] == truth['final_sha256']
    again = rerun_replay.summary(str(tmp_path / 'again.rrd'))
    assert again['mesh_rows'] == truth['frames']
    assert again['recording_info']['replay_of'] == str(path)


@pytest.mark.slow
def test_replay_uses_the_recorded_inputs_not_the_scenario_tracks(tmp_path):
    """A session whose probes wandered off the scenario's keyframes (a person or a robot
    driving them): the replay follows what was recorded."""
    scenario = scenario_from_mapping(PINCH)
    rng = np.random.default_rng(3)

    def wobbly(time: float):
        centers, radii, active = scenario.probe_inputs(time)
        return centers + rng.normal(0.0, 0.002, centers.shape), radii, active

    path = tmp_path / 'wobbly.rrd'
    truth = record(PINCH, path, probe_inputs=wobbly)
    plain = run_scenario(scenario)
    assert plain['final_positions_sha256'] != truth['final_sha256']
    metrics = rerun_replay.replay(str(path))
    assert metrics['final_positions_sha256'] == truth['final_sha256']


def test_headless_replay_command(pinch_recording, tmp_path, capsys):
    path, truth = pinch_recording
    out = tmp_path / 'metrics.json'
    assert headless_main(['--replay', str(path), '--metrics-json', str(out)]) == 0
    assert json.loads(out.read_text())['final_positions_sha256'] == truth['final_sha256']
    assert headless_main(['--replay', str(path), '--seed', '3']) == 2
    assert 'cannot be combined with --seed' in capsys.readouterr().err


# ------------------------------------------------------------------ interrupted sessions
def _whole_frames(path: Path) -> dict:
    """Rows per entity of an interrupted recording: all equal when it ends on a whole frame."""
    summary = rerun_replay.summary(str(path))
    series = rerun_replay.read_scalars(str(path))
    rows = {'mesh': summary['mesh_rows'], 'inputs': summary['probe_input_rows']}
    rows.update({name: len(series[name][1]) for name in METRICS})
    return rows


def _logged_frames(path: Path) -> int:
    """Mesh rows readable so far from a recording that is still being written (0 while the
    file is not decodable yet)."""
    try:
        return sum(chunk.num_rows for chunk in RrdReader(path).stream()
                   if chunk.entity_path == '/paper/mesh' and not chunk.is_static)
    except (RuntimeError, ValueError, OSError):
        return 0


def _wait_for_frames(path: Path, process: subprocess.Popen, frames: int,
                     timeout: float = 180.0) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if process.poll() is not None:
            raise AssertionError(f'process exited early ({process.returncode}): '
                                 f'{process.stderr.read().decode()[-2000:]}')
        if path.exists() and _logged_frames(path) >= frames:
            return
        time.sleep(0.3)
    raise AssertionError(f'{path} did not reach {frames} frames in {timeout} s')


def _headless(*arguments: str, timeout: float = 300.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, '-m', 'paper_sim_ros.headless', *arguments],
                          cwd=REPO, capture_output=True, text=True, timeout=timeout)


@pytest.mark.slow
@pytest.mark.parametrize('signal_number', [signal.SIGINT, signal.SIGTERM],
                         ids=['SIGINT', 'SIGTERM'])
def test_headless_interrupted_recording_is_complete_and_replayable(tmp_path, signal_number):
    scenario_file = tmp_path / 'long_pinch.yaml'
    scenario_file.write_text(yaml.safe_dump({**PINCH, 'duration': 600.0}))
    path = tmp_path / 'interrupted.rrd'
    # SIGINT as a terminal sends it, even where the tests run in a background job (which
    # ignores it, and a child Python started so would never see it)
    process = subprocess.Popen(
        [sys.executable, '-m', 'paper_sim_ros.headless', '--scenario', str(scenario_file),
         '--rrd', str(path)], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        _wait_for_frames(path, process, 20)
        process.send_signal(signal_number)
        _, stderr = process.communicate(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 130, stderr.decode()
    assert b'interrupted' in stderr
    assert rerun_replay.is_complete(str(path)), 'the footer was written on the way out'
    rows = _whole_frames(path)
    frames = rows['mesh']
    assert 20 <= frames < 36000, rows
    assert set(rows.values()) == {frames}, f'the recording ends on a whole frame: {rows}'
    meshes = rerun_replay.read_mesh_frames(str(path))
    assert [m.frame for m in meshes] == list(range(1, frames + 1))
    assert all(np.all(np.isfinite(m.positions)) for m in meshes)

    # re-run it from the file alone, recording the replay: every frame comes out the same
    again = tmp_path / 'replayed.rrd'
    result = _headless('--replay', str(path), '--rrd', str(again))
    assert result.returncode == 0, result.stderr[-3000:]
    metrics = json.loads(result.stdout)
    assert metrics['replay_frames'] == frames and metrics['replay_exact']
    replayed = rerun_replay.read_mesh_frames(str(again))
    assert len(replayed) == frames
    for original, copy in zip(meshes, replayed):
        np.testing.assert_array_equal(copy.positions, original.positions,
                                      err_msg=f'frame {original.frame} of the replay')


# A long recording: a 65 x 65 sheet logged for 1 200 frames and a camera's images every
# third; the process's RSS [MB] after the first ten frames and at the end
RECORDING_MEMORY_SCRIPT = """
import sys, time
import numpy as np
from paper_sim_ros.core import build_simulator, load_scenario
from paper_sim_ros.core.camera import CameraConfig, render_simulator
from paper_sim_ros.rerun_logger import RerunRecorder

def rss():
    with open('/proc/self/status') as status:
        return next(int(line.split()[1]) for line in status
                    if line.startswith('VmRSS')) / 1024

simulator = build_simulator(load_scenario({'name': 'long', 'sheet': {'nx': 65, 'ny': 65}}))
camera = CameraConfig()
frame = render_simulator(camera, simulator,
                         np.full((simulator.sheet.vertex_count, 3), 200, dtype=np.uint8))
recorder = RerunRecorder('memory', sys.argv[1], cameras=(camera.name,))
for index in range(1200):
    simulator.sheet.positions[:, 2] += 1e-6
    recorder.log_frame(index / 60, simulator)
    if index % 3 == 0:
        recorder.log_camera(index / 60, simulator, camera, frame)
    if index == 10:
        time.sleep(0.5)
        early = rss()
    time.sleep(0.005)
time.sleep(0.5)
print(early, rss())
recorder.close()
"""


@pytest.mark.slow
def test_a_long_recording_keeps_the_memory_flat(tmp_path):
    """The Rerun SDK's allocator kept what its writer freed (``import_rerun``): measured
    25-35 MB more over these frames that way, 3-5 MB now."""
    environment = {name: value for name, value in os.environ.items()
                   if name != 'MIMALLOC_PURGE_DELAY'}
    path = tmp_path / 'long.rrd'
    result = subprocess.run([sys.executable, '-c', RECORDING_MEMORY_SCRIPT, str(path)],
                            cwd=REPO, env=environment, capture_output=True, text=True,
                            timeout=300)
    assert result.returncode == 0, result.stderr[-3000:]
    early, late = (float(value) for value in result.stdout.split())
    assert late - early < 15.0, f'RSS {early:.1f} -> {late:.1f} MB'
    assert rerun_replay.is_complete(str(path))
    assert rerun_replay.summary(str(path))['mesh_rows'] == 1200


# ---------------------------------------------------------------------------- streaming
def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(('127.0.0.1', 0))
        return probe.getsockname()[1]


def _accepts_connections(port: int) -> bool:
    try:
        with socket.create_connection(('127.0.0.1', port), timeout=1.0):
            return True
    except OSError:
        return False


def test_streams_to_a_running_rerun_server(tmp_path):
    """``connect_url``: the frames reach a real Rerun gRPC server (the ``rerun`` binary of this
    SDK, saving what it receives), which stands in for a viewer."""
    rerun_binary = Path(sys.executable).with_name('rerun')
    port = _free_port()
    received = tmp_path / 'received.rrd'
    # its own session: the `rerun` wrapper starts the real binary as a child, and the
    # whole group must go at the end, not only the wrapper (an orphan kept serving)
    server = subprocess.Popen([str(rerun_binary), '--port', str(port), '--save', str(received)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                              start_new_session=True)
    try:
        # listening: on a loaded machine the server takes more than the 2 s it usually does
        deadline = time.monotonic() + 60
        while not _accepts_connections(port) and time.monotonic() < deadline:
            assert server.poll() is None, server.stderr.read().decode()[-2000:]
            time.sleep(0.2)
        assert server.poll() is None, server.stderr.read().decode()[-2000:]
        scenario = scenario_from_mapping({**PINCH, 'duration': 0.2})
        simulator = build_simulator(scenario)
        recorder = RerunRecorder('paper_sim_test',
                                 connect_url=f'rerun+http://127.0.0.1:{port}/proxy',
                                 recording_info={'scenario': scenario.mapping})
        for frame in range(1, scenario.frame_count + 1):
            simulator.set_probes(*scenario.probe_inputs(frame * scenario.config.solver.dt))
            simulator.step_frame()
            recorder.log_frame(simulator.time, simulator)
        recorder.close()
        # read a copy that decodes whole: the server writes on, and a SIGTERM can cut its
        # last message short
        snapshot = tmp_path / 'snapshot.rrd'
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            if received.exists():
                shutil.copyfile(received, snapshot)
            if _logged_frames(snapshot) >= scenario.frame_count:
                break
            time.sleep(0.2)
    finally:
        os.killpg(server.pid, signal.SIGTERM)
        server.wait(10)
    meshes = rerun_replay.read_mesh_frames(str(snapshot))
    assert len(meshes) == scenario.frame_count
    assert rerun_replay.read_recording_info(str(snapshot))['scenario']['name'] == 'pinch'
    np.testing.assert_allclose(meshes[-1].positions, simulator.sheet.positions, atol=1e-6)


@pytest.mark.parametrize('ground, expected_low', [(False, 0.5 - 0.297), (True, 0.3)])
def test_the_view_frames_where_a_pinned_sheet_will_hang(ground, expected_low):
    """The 3-D view is set from the first frame: a sheet pinned along its short edge,
    released flat 0.5 m up, swings down by its length (0.297 m), so the view reaches that
    far below the pins, or down to the table where there is one (0.3 m here); a sheet
    nothing pins is framed as it lies."""
    mapping = {'name': 'view', 'pin': 'short_edge',
               'sheet': {'nx': 9, 'ny': 9, 'elevation': 0.5},
               'contact': {'ground_enabled': ground, 'ground_height': 0.3}}
    low, high = view_bounds(build_simulator(scenario_from_mapping(mapping)))
    np.testing.assert_allclose(low[2], expected_low, atol=1e-9)
    np.testing.assert_allclose(high[2], 0.5, atol=1e-9)
    np.testing.assert_allclose([low[1], high[1]], [-0.1485, 0.1485], atol=1e-9)
    free = build_simulator(scenario_from_mapping({**mapping, 'pin': 'none'}))
    np.testing.assert_allclose(view_bounds(free)[0][2], 0.5, atol=1e-9)
