"""The node's Rerun recording (SPEC §7–8, issue 6): stopped by SIGINT or SIGTERM mid-session,
it is complete, ends on whole frames, and re-runs to the same sheet from nothing but the file.

The node runs as its own process on real DDS; a probe pose is published to press the sheet so
that the recording has something to reproduce. Read back with ``rerun.chunk.RrdReader``."""
from __future__ import annotations

import signal
import time

from geometry_msgs.msg import PoseStamped
import numpy as np
import pytest
from sensor_msgs.msg import PointCloud2

from paper_sim_ros import rerun_replay
from ros_harness import RosClient, new_domain_id, start_node

NODE = {'sheet.nx': 17, 'sheet.ny': 17, 'publish_rate': 20.0, 'markers_rate': 2.0,
        'probe_radii': [0.02]}


def press(client: RosClient, process, seconds: float) -> None:
    """Bring a probe down onto the sheet near its centre, pressing it on the table, then
    drag it 2 cm along x."""
    publisher = client.node.create_publisher(PoseStamped, 'probe/pose', 10)
    started = time.monotonic()

    def publish() -> None:
        elapsed = time.monotonic() - started
        progress = min(1.0, elapsed / (0.6 * seconds))
        dragged = min(1.0, max(0.0, elapsed - 0.6 * seconds) / (0.3 * seconds))
        pose = PoseStamped()
        pose.header.frame_id = 'world'
        pose.header.stamp = client.node.get_clock().now().to_msg()
        pose.pose.position.x = 0.01 + 0.02 * dragged
        pose.pose.position.y = -0.02
        pose.pose.position.z = 0.05 - progress * (0.05 - 0.017)
        pose.pose.orientation.w = 1.0
        publisher.publish(pose)
        if not process.alive():
            raise AssertionError(f'node exited while pressing:\n{process.output()[-3000:]}')

    client.spin_for(seconds, every=publish)


@pytest.mark.slow
@pytest.mark.parametrize('signal_number', [signal.SIGINT, signal.SIGTERM],
                         ids=['SIGINT', 'SIGTERM'])
def test_node_recording_stopped_by_a_signal_is_complete_and_replays(tmp_path, signal_number):
    path = tmp_path / 'node_session.rrd'
    domain = new_domain_id()
    process = start_node(tmp_path, {**NODE, 'rerun_path': str(path)}, domain_id=domain)
    client = RosClient(domain)
    try:
        client.subscribe(PointCloud2, 'paper/points')
        client.spin_until(lambda: client.latest('paper/points') is not None, 90.0,
                          'a point cloud', process)
        press(client, process, 2.5)
    finally:
        client.close()
    code = process.stop(signal_number)
    output = process.output()
    assert code == 0, f'exit status {code}:\n{output[-3000:]}'
    assert 'Traceback' not in output, output[-3000:]

    assert rerun_replay.is_complete(str(path)), 'the footer was written on the way out'
    summary = rerun_replay.summary(str(path))
    info = summary['recording_info']
    assert info['parameters']['sheet.nx'] == 17 and 'seed' in info['parameters']
    meshes = rerun_replay.read_mesh_frames(str(path))
    inputs = rerun_replay.read_probe_inputs(str(path))
    series = rerun_replay.read_scalars(str(path))
    assert len(meshes) >= 10, summary
    assert all(np.isfinite(mesh.positions).all() for mesh in meshes)
    # every stepped frame has its inputs; every logged frame is whole
    assert [item.frame for item in inputs] == list(range(1, len(inputs) + 1))
    assert meshes[-1].frame <= inputs[-1].frame
    for name in ('step_time', 'real_time_factor', 'energy', 'max_strain', 'breaks', 'folds'):
        assert len(series[name][1]) == len(meshes), name
    assert any(item.active.any() for item in inputs), 'the probe reached the node'
    moved = max(float(np.abs(mesh.positions - meshes[0].positions).max()) for mesh in meshes
                if mesh.positions.shape == meshes[0].positions.shape)
    assert moved > 1e-3, 'the probe moved the sheet'

    # re-run from the file alone: every logged mesh is reproduced
    replayed = {}

    def keep(simulator, step_seconds):
        replayed[simulator.frame] = simulator.sheet.positions.copy()
    metrics = rerun_replay.replay(str(path), on_frame=keep)
    assert metrics['replay_exact'] and metrics['replay_frames'] == inputs[-1].frame
    for mesh in meshes:
        np.testing.assert_allclose(mesh.positions, replayed[mesh.frame], atol=1e-6,
                                   err_msg=f'frame {mesh.frame} of the replay')
