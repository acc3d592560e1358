"""The node's rosbag2 output (issue 16): a session stopped by a signal leaves a complete MCAP
bag that two independent readers (rosbags, and mcap with its ROS 2 decoder) read alike:
every topic the node published, what a subscriber received, stamps in order, the camera on
/tf_static. A bag path that exists is refused before anything runs."""
from __future__ import annotations

import signal
from pathlib import Path

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
import numpy as np
import pytest
from rosbags.rosbag2 import Reader
from sensor_msgs.msg import CameraInfo, PointCloud2

from paper_sim_ros.bag_recorder import TYPESTORE
from paper_sim_ros.headless import main as headless_main
from ros_harness import RosClient, new_domain_id, start_node

TOPICS = {'/paper/points': 'sensor_msgs/msg/PointCloud2',
          '/paper/markers': 'visualization_msgs/msg/MarkerArray',
          '/paper/eye/depth/image_raw': 'sensor_msgs/msg/Image',
          '/paper/eye/color/image_raw': 'sensor_msgs/msg/Image',
          '/paper/eye/camera_info': 'sensor_msgs/msg/CameraInfo',
          '/paper/eye/points': 'sensor_msgs/msg/PointCloud2',
          '/diagnostics': 'diagnostic_msgs/msg/DiagnosticArray',
          '/tf_static': 'tf2_msgs/msg/TFMessage'}
EYE = [0.1, -0.2, 0.4]


def stamp_ns(header) -> int:
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


@pytest.mark.parametrize('signal_number', [signal.SIGINT, signal.SIGTERM],
                         ids=['SIGINT', 'SIGTERM'])
def test_a_session_stopped_by_a_signal_leaves_a_complete_bag(tmp_path, signal_number):
    bag = tmp_path / 'session'
    domain = new_domain_id()
    process = start_node(tmp_path, {
        'sheet.nx': 17, 'sheet.ny': 17, 'publish_rate': 10.0, 'markers_rate': 2.0,
        'diagnostics_rate': 2.0, 'cameras': ['eye'], 'eye.rate': 5.0,
        'eye.width': 64, 'eye.height': 48, 'eye.position': EYE,
        'bag_path': str(bag)}, domain_id=domain)
    client = RosClient(domain)
    try:
        client.subscribe(PointCloud2, 'paper/points')
        client.subscribe(CameraInfo, 'paper/eye/camera_info')
        client.spin_until(lambda: len(client.messages('paper/eye/camera_info')) >= 4, 90,
                          'four camera frames', process)
        received = {stamp_ns(m.header) for m in client.messages('paper/points')}
    finally:
        client.close()
    assert process.stop(signal_number) == 0, process.output()[-3000:]

    # both readers: every topic, decodable, alike, stamps in order
    with Reader(bag) as reader:
        assert {c.topic: c.msgtype for c in reader.connections} == TOPICS
    by_topic = read_with_both_readers(bag)
    # what the subscriber got is there
    points = {stamp_ns(m.header) for _, m in by_topic['/paper/points']}
    assert received and received <= points, (len(received), len(points))
    assert len(by_topic['/paper/eye/camera_info']) >= 4
    for topic in ('/paper/eye/depth/image_raw', '/paper/eye/color/image_raw',
                  '/paper/eye/points'):  # one of each per camera frame, same stamps
        assert [t for t, _ in by_topic[topic]] == [t for t, _ in by_topic[
            '/paper/eye/camera_info']], topic
    (_, tf), = by_topic['/tf_static']
    transform, = tf.transforms
    assert transform.child_frame_id == 'eye_optical_frame'
    assert transform.header.frame_id == 'world'
    np.testing.assert_allclose([transform.transform.translation.x,
                                transform.transform.translation.y,
                                transform.transform.translation.z], EYE)
    depth = by_topic['/paper/eye/depth/image_raw'][-1][1]
    assert (depth.encoding, depth.width, depth.height) == ('32FC1', 64, 48)


def test_an_existing_bag_path_is_refused_before_anything_runs(tmp_path):
    bag = tmp_path / 'taken'
    bag.mkdir()
    process = start_node(tmp_path, {'sheet.nx': 9, 'sheet.ny': 9, 'bag_path': str(bag)},
                         domain_id=new_domain_id())
    process.process.wait(60)  # it exits by itself
    code = process.stop()
    assert code == 1 and 'cannot write the bag' in process.output() \
        and 'exists' in process.output(), process.output()[-2000:]


def read_with_both_readers(bag: Path) -> dict[str, list]:
    """Messages per topic as rosbags decodes them, checked against the mcap decoder's
    counts and against the stamps in order."""
    by_topic: dict[str, list] = {}
    with Reader(bag) as reader:
        for connection, timestamp, raw in reader.messages():
            by_topic.setdefault(connection.topic, []).append(
                (timestamp, TYPESTORE.deserialize_cdr(raw, connection.msgtype)))
    (mcap_file,) = Path(bag).glob('*.mcap')
    counts: dict[str, int] = {}
    with open(mcap_file, 'rb') as stream:
        for _, channel, _, _ in make_reader(
                stream, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
    assert counts == {topic: len(items) for topic, items in by_topic.items()}
    for topic, items in by_topic.items():
        times = [timestamp for timestamp, _ in items]
        assert times == sorted(times), topic
    return by_topic


def test_headless_bag_holds_the_run_with_the_default_camera(tmp_path, capsys):
    bag = tmp_path / 'press'
    assert headless_main(['--scenario', 'press', '--grid', '17', '--duration', '0.5',
                          '--bag', str(bag), '--camera-rate', '10']) == 0
    by_topic = read_with_both_readers(bag)
    assert len(by_topic['/paper/points']) == 30  # every frame of 0.5 s at 60 Hz
    # camera slots k / 10 s reached from 1/60 s to 0.5 s: k = 0..5
    for suffix in ('depth/image_raw', 'color/image_raw', 'camera_info', 'points'):
        assert len(by_topic[f'/paper/camera/{suffix}']) == 6, suffix
    cloud = by_topic['/paper/points'][-1][1]
    assert cloud.width == 17 * 17 and cloud.header.frame_id == 'world'
    depth = by_topic['/paper/camera/depth/image_raw'][-1][1]
    assert (depth.width, depth.height, depth.header.frame_id) == (640, 480,
                                                                  'camera_optical_frame')
    pixels = np.frombuffer(bytes(depth.data), '<f4')
    assert np.isfinite(pixels).mean() > 0.5, 'the camera sees the sheet and the table'
    (_, tf), = by_topic['/tf_static']
    assert tf.transforms[0].child_frame_id == 'camera_optical_frame'


def test_headless_refuses_an_existing_bag_directory(tmp_path, capsys):
    (tmp_path / 'taken').mkdir()
    assert headless_main(['--scenario', 'press', '--grid', '9', '--duration', '0.1',
                          '--bag', str(tmp_path / 'taken')]) == 2
    assert 'exists' in capsys.readouterr().err


def test_headless_camera_rate_needs_a_bag_or_a_recording(tmp_path, capsys):
    assert headless_main(['--scenario', 'press', '--grid', '9', '--duration', '0.1',
                          '--camera-rate', '5']) == 2
    assert '--bag or --rrd' in capsys.readouterr().err


def test_a_scenario_file_sets_any_number_of_cameras(tmp_path, capsys):
    scenario = tmp_path / 'two_cameras.yaml'
    scenario.write_text(
        'duration: 0.3\n'
        'contact: {ground_enabled: true}\n'
        'cameras:\n'
        '  - {name: top, position: [0.0, 0.0, 0.5], width: 80, height: 60, rate: 10}\n'
        '  - {name: side, position: [0.4, 0.0, 0.1], width: 64, height: 48, rate: 20,\n'
        '     depth_noise_stddev: 0.001, fx: 50.0, fy: 55.0, cx: 30.0, cy: 20.0}\n')
    bag = tmp_path / 'two'
    assert headless_main(['--scenario', str(scenario), '--grid', '9', '--bag', str(bag)]) == 0
    by_topic = read_with_both_readers(bag)
    # 0.3 s: slots k / 10 s for k = 0..3, k / 20 s for k = 0..6
    assert len(by_topic['/paper/top/camera_info']) == 4
    assert len(by_topic['/paper/side/camera_info']) == 7
    assert by_topic['/paper/side/depth/image_raw'][0][1].width == 64
    np.testing.assert_allclose(by_topic['/paper/side/camera_info'][0][1].k,
                               [50.0, 0, 30.0, 0, 55.0, 20.0, 0, 0, 1])
    top = by_topic['/paper/top/depth/image_raw'][-1][1]
    depth = np.frombuffer(bytes(top.data), '<f4').reshape(60, 80)
    assert depth[30, 40] == pytest.approx(0.5, abs=1e-3), 'straight down onto the sheet'
    frames = {m.transforms[0].child_frame_id for _, m in by_topic['/tf_static']}
    assert frames == {'top_optical_frame', 'side_optical_frame'}


@pytest.mark.parametrize('cameras, reason', [
    ('[{name: a, colour: red}]', 'unknown camera keys'),
    ('[{name: a}, {name: a}]', 'distinct'),
    ('[{name: a, rate: 0}]', 'rate'),
    ('[{name: "no spaces"}]', 'letter'),
    ('[{name: a, fx: -1.0}]', 'fx must be > 0'),
    ('[{name: a, position: [0, 0, 0], target: [0, 0, 0]}]', 'differ'),
])
def test_bad_scenario_cameras_are_refused_with_a_reason(tmp_path, capsys, cameras, reason):
    scenario = tmp_path / 'bad.yaml'
    scenario.write_text(f'duration: 0.1\ncameras: {cameras}\n')
    assert headless_main(['--scenario', str(scenario), '--grid', '9']) == 2
    assert reason in capsys.readouterr().err
