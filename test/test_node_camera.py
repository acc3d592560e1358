"""The node's virtual cameras over real DDS (issue 16): depth, colour, camera info and the
organised cloud arrive at each camera's rate, one header per frame, and show the sheet where
it is; a second camera has its own topics, frame and intrinsics; bad camera parameters are
refused with a reason."""
from __future__ import annotations

import math
import time

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo, Image, PointCloud2
from std_srvs.srv import Trigger

from paper_sim_ros.core.camera import HIT_PAPER
from paper_sim_ros.msg_adapters.camera import PIXEL_DTYPE
from paper_sim_ros.node_parameters import declared_defaults, settings_from_values
from paper_sim_ros.rerun_replay import read_chunks
from ros_harness import RosClient, new_domain_id, start_node, stop_cleanly

WIDTH, HEIGHT, FOV, RATE = 160, 120, 1.0, 10.0
HEIGHT_ABOVE = 0.5
TOPICS = {'depth': ('paper/top/depth/image_raw', Image),
          'color': ('paper/top/color/image_raw', Image),
          'info': ('paper/top/camera_info', CameraInfo),
          'points': ('paper/top/points', PointCloud2)}
# a second camera, with its intrinsics given in pixels rather than by a field of view
SIDE_INFO = 'paper/side/camera_info'
SIDE_WIDTH, SIDE_HEIGHT, SIDE_FX, SIDE_FY, SIDE_CX, SIDE_CY = 64, 48, 50.0, 55.0, 30.0, 20.0


@pytest.fixture(scope='module')
def camera_node(tmp_path_factory):
    domain = new_domain_id()
    process = start_node(tmp_path_factory.mktemp('camera'), {
        'sheet.nx': 17, 'sheet.ny': 17, 'publish_rate': 5.0, 'markers_rate': 0.0,
        'cameras': ['top', 'side'],
        'top.rate': RATE, 'top.width': WIDTH, 'top.height': HEIGHT, 'top.horizontal_fov': FOV,
        'top.position': [0.0, 0.0, HEIGHT_ABOVE], 'top.target': [0.0, 0.0, 0.0],
        'side.rate': 5.0, 'side.width': SIDE_WIDTH, 'side.height': SIDE_HEIGHT,
        'side.fx': SIDE_FX, 'side.fy': SIDE_FY, 'side.cx': SIDE_CX, 'side.cy': SIDE_CY,
        'side.position': [0.5, 0.0, 0.2]},
        domain_id=domain)
    client = RosClient(domain)
    for topic, kind in TOPICS.values():
        client.subscribe(kind, topic)
    client.subscribe(CameraInfo, SIDE_INFO)
    try:
        # the four subscriptions are matched at different moments, so the first frames
        # may reach only some of them: wait for six frames seen on all four
        client.spin_until(lambda: len(frames_on_every_topic(client)) >= 6
                          and len(client.messages(SIDE_INFO)) >= 4, 90,
                          'six frames on all four camera topics, four of the side camera',
                          process)
        yield client
    finally:
        client.close()
        stop_cleanly(process)


def stamps_of(messages: list) -> list[float]:
    return [m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec for m in messages]


def frames_on_every_topic(client: RosClient) -> set[float]:
    return set.intersection(*(set(stamps_of(client.messages(topic)))
                              for topic, _ in TOPICS.values()))


def test_every_frame_has_its_four_messages_under_one_header_at_the_rate(camera_node):
    stamps = {}
    for key, (topic, _) in TOPICS.items():
        messages = camera_node.messages(topic)
        assert {m.header.frame_id for m in messages} == {'top_optical_frame'}, key
        stamps[key] = stamps_of(messages)
    common = frames_on_every_topic(camera_node)
    assert len(common) >= 6, stamps
    ordered = sorted(common)
    # simulated time between frames: 1 / rate (a dropped slot would be a multiple); the
    # first frame is the first physics frame, the next on the slot grid t = k / rate
    gaps = np.diff(ordered)[1:]
    assert np.allclose(gaps / (1.0 / RATE), np.rint(gaps / (1.0 / RATE)), atol=0.02), gaps
    assert np.min(gaps) == pytest.approx(1.0 / RATE, abs=1e-3)


@pytest.mark.slow
def test_a_tick_of_several_frames_keeps_the_camera_on_its_slot_grid(tmp_path):
    """/clock advances seven frames at a time (a node behind its clock catches up so): the
    camera renders the frames its 10 Hz slots fall on, not the tick's last frame. (Ticks
    may merge on a busy machine; with no cap on catching up none slips, and the slots are
    the same however the frames are shared out.)"""
    domain = new_domain_id()
    process = start_node(tmp_path, {
        'sheet.nx': 9, 'sheet.ny': 9, 'publish_rate': 0.0, 'markers_rate': 0.0,
        'use_sim_time': True, 'max_catchup_frames': 1000, 'physics_rate': 60.0,
        'cameras': ['top'], 'top.rate': RATE, 'top.width': 32, 'top.height': 24},
        domain_id=domain)
    client = RosClient(domain)
    start, frame, stride, ticks = 100.0, 1.0 / 60.0, 7, 14
    try:
        client.subscribe(CameraInfo, TOPICS['info'][0])
        clock = client.node.create_publisher(Clock, '/clock', 10)

        def publish_clock(seconds: float) -> None:
            message = Clock()
            message.clock.sec = int(seconds)
            message.clock.nanosec = int(round((seconds - int(seconds)) * 1e9))
            clock.publish(message)
            client.spin_for(0.15)
        client.spin_until(lambda: client.node.count_subscribers('/clock') >= 1
                          and client.node.count_publishers(TOPICS['info'][0]) >= 1, 60,
                          'the node to subscribe to /clock and publish camera info', process)
        # the first tick on /clock the node sees sets the simulation's clock origin (on a
        # busy machine it may be a later one: the stamps are read relative to the first
        # frame's below)
        for _ in range(3):
            publish_clock(start)
        for tick in range(1, ticks + 1):
            publish_clock(start + tick * stride * frame)
        client.spin_until(lambda: len(client.messages(TOPICS['info'][0])) >= 16, 30,
                          f'the camera frames of {ticks * stride} simulated frames: got '
                          f'{stamps_of(client.messages(TOPICS["info"][0]))}', process)
    finally:
        client.close()
        stop_cleanly(process)
    # the first physics frame, then every slot k / rate after it
    stamps = np.array(stamps_of(client.messages(TOPICS['info'][0])))[:16]
    expected = np.concatenate([[frame], np.arange(1, 16) / RATE])
    np.testing.assert_allclose(stamps - stamps[0] + frame, expected, atol=1e-6)


def test_images_and_info_describe_the_camera_above_the_sheet(camera_node):
    depth = camera_node.latest(TOPICS['depth'][0])
    color = camera_node.latest(TOPICS['color'][0])
    info = camera_node.latest(TOPICS['info'][0])
    assert (depth.encoding, depth.width, depth.height, depth.step) == ('32FC1', WIDTH, HEIGHT,
                                                                       4 * WIDTH)
    assert (color.encoding, color.width, color.height, color.step) == ('rgb8', WIDTH, HEIGHT,
                                                                       3 * WIDTH)
    focal = 0.5 * WIDTH / math.tan(0.5 * FOV)
    np.testing.assert_allclose(info.k, [focal, 0, (WIDTH - 1) / 2, 0, focal,
                                        (HEIGHT - 1) / 2, 0, 0, 1])
    assert (info.width, info.height, info.distortion_model) == (WIDTH, HEIGHT, 'plumb_bob')
    pixels = np.frombuffer(bytes(depth.data), '<f4').reshape(HEIGHT, WIDTH)
    # the A4 sheet (0.21 x 0.297 m) fills the middle of the view, flat at z = 0: 0.5 m away
    middle = pixels[HEIGHT // 2 - 10:HEIGHT // 2 + 10, WIDTH // 2 - 10:WIDTH // 2 + 10]
    np.testing.assert_allclose(middle, HEIGHT_ABOVE, atol=2e-3)
    rgb = np.frombuffer(bytes(color.data), np.uint8).reshape(HEIGHT, WIDTH, 3)
    assert rgb[HEIGHT // 2, WIDTH // 2].min() > 100, 'the sheet looks like paper, not black'


def test_a_second_camera_has_its_own_topics_frame_rate_and_intrinsics(camera_node):
    top = stamps_of(camera_node.messages(TOPICS['info'][0]))
    side = camera_node.messages(SIDE_INFO)
    info = side[-1]
    assert {m.header.frame_id for m in side} == {'side_optical_frame'}
    assert (info.width, info.height) == (SIDE_WIDTH, SIDE_HEIGHT)
    np.testing.assert_allclose(info.k, [SIDE_FX, 0, SIDE_CX, 0, SIDE_FY, SIDE_CY, 0, 0, 1])
    np.testing.assert_allclose(info.p, [SIDE_FX, 0, SIDE_CX, 0, 0, SIDE_FY, SIDE_CY, 0,
                                        0, 0, 1, 0])
    # 5 Hz of simulated time beside the top camera's 10 Hz (after the first frame, which is
    # the first physics frame, both on their slot grids t = k / rate)
    assert np.min(np.diff(stamps_of(side))[1:]) == pytest.approx(0.2, abs=1e-3)
    assert np.min(np.diff(top)[1:]) == pytest.approx(0.1, abs=1e-3)


def test_organised_cloud_shows_the_sheet_with_its_material_coordinates(camera_node):
    cloud = camera_node.latest(TOPICS['points'][0])
    assert (cloud.height, cloud.width, cloud.point_step) == (HEIGHT, WIDTH, 24)
    points = np.frombuffer(bytes(cloud.data), PIXEL_DTYPE).reshape(HEIGHT, WIDTH)
    paper = points['hit'] == HIT_PAPER
    # the sheet's footprint in the image: 0.21 m of 2 * 0.5 tan(0.5) = 0.546 m across
    expected = (0.21 * 0.297) / (2 * HEIGHT_ABOVE * math.tan(0.5 * FOV)) ** 2 * WIDTH ** 2
    assert paper.sum() == pytest.approx(expected, rel=0.1), (paper.sum(), expected)
    # looking straight down with image up = +y: optical x = world x, optical y = -world y
    np.testing.assert_allclose(points['u'][paper], points['x'][paper], atol=2e-3)
    np.testing.assert_allclose(points['v'][paper], -points['y'][paper], atol=2e-3)
    np.testing.assert_allclose(points['z'][paper], HEIGHT_ABOVE, atol=2e-3)


def test_a_probe_above_a_sleeping_sheet_shows_in_the_image_and_leaves_the_sheet_asleep(
        camera_node):
    """The sheet on the table sleeps, and the node keeps its colours and images while it
    does (node._at_rest); a probe passing 25 cm above it, far out of its reach, does not wake
    it, but the camera above sees it, and sees the sheet again once the probe has gone."""
    client = camera_node
    client.subscribe(DiagnosticArray, '/diagnostics')
    poses = client.node.create_publisher(PoseStamped, 'probe/pose', 10)
    depth_topic = TOPICS['depth'][0]

    def asleep() -> bool:
        latest = client.latest('/diagnostics')
        return latest is not None and \
            {pair.key: pair.value for pair in latest.status[0].values}['asleep'] == 'true'

    def middle_depth(since: float) -> float:
        client.spin_until(lambda: client.messages(depth_topic, since), 10, 'a depth image')
        image = client.messages(depth_topic, since)[-1]
        pixels = np.frombuffer(bytes(image.data), '<f4').reshape(HEIGHT, WIDTH)
        return float(pixels[HEIGHT // 2, WIDTH // 2])

    def hover() -> None:
        message = PoseStamped()
        message.header.frame_id = 'world'
        message.header.stamp = client.node.get_clock().now().to_msg()
        message.pose.position.z = 0.25
        message.pose.orientation.w = 1.0
        poses.publish(message)

    client.spin_until(asleep, 20, 'the sheet asleep')
    assert middle_depth(time.monotonic()) == pytest.approx(HEIGHT_ABOVE, abs=2e-3)
    client.spin_for(1.0, hover)
    since = time.monotonic()
    client.spin_for(1.0, hover)
    # the probe (radius 0.02 m) between the camera and the sheet
    assert middle_depth(since) == pytest.approx(HEIGHT_ABOVE - 0.25 - 0.02, abs=2e-3)
    client.spin_until(lambda: client.messages('/diagnostics', since), 10, 'diagnostics')
    assert asleep(), 'a probe 25 cm above the sheet woke it'
    client.spin_for(1.5)  # probe_timeout 0.5 s: the probe has gone
    assert middle_depth(time.monotonic()) == pytest.approx(HEIGHT_ABOVE, abs=2e-3)


def test_cameras_go_on_at_their_rate_after_a_reset(camera_node):
    """A reset restarts simulated time at zero: the cameras start their slot grid again
    rather than wait for the time they had reached. Runs last on the shared node."""
    info = TOPICS['info'][0]
    camera_node.spin_until(lambda: len(camera_node.messages(info)) >= 20, 30,
                           'two seconds of camera frames')
    before = len(camera_node.messages(info))
    response = camera_node.call(Trigger, 'paper/reset', Trigger.Request())
    assert response.success
    camera_node.spin_until(lambda: len(camera_node.messages(info)) >= before + 10, 30,
                           'ten camera frames after the reset')
    # the stamps go on across the reset (clock time of the reset plus simulated time), with
    # no gap of the two seconds simulated before it
    gaps = np.diff(stamps_of(camera_node.messages(info)[before - 5:]))
    assert gaps.max() < 1.0, gaps


@pytest.mark.parametrize('name, value, reason', [
    ('cameras', ['two words'], 'letter then letters'),
    ('cameras', ['sheet'], 'taken by the parameters sheet'),
    ('cameras', ['camera', 'camera'], 'distinct'),
    ('camera.fx', -5.0, 'fx'),
    ('camera.target', [0.0, 0.0, 0.5], 'must differ'),
    ('camera.position', [0.0, float('nan'), 0.5], 'finite'),
    ('camera.rate', -1.0, 'camera.rate'),
    ('camera.depth_noise_stddev', float('nan'), 'depth noise'),
])
def test_bad_camera_parameters_are_refused_with_a_reason(name, value, reason):
    values = declared_defaults()
    values['camera.position'] = [0.0, 0.0, 0.5]
    values[name] = value
    with pytest.raises(ValueError, match=reason):
        settings_from_values(values)


@pytest.mark.slow
def test_an_output_no_one_reads_is_skipped_and_a_recorded_camera_still_renders(tmp_path):
    """With a reader on the camera's info only: the info arrives at the camera's rate, the
    outputs nobody reads (cloud, markers, the camera's images and organised cloud) are
    skipped and counted in diagnostics, and the Rerun recording still holds every camera
    frame. A reader that comes later gets the cloud from then on."""
    path = tmp_path / 'unread.rrd'
    domain = new_domain_id()
    process = start_node(tmp_path, {
        'sheet.nx': 9, 'sheet.ny': 9, 'publish_rate': 10.0, 'markers_rate': 5.0,
        'cameras': ['top'], 'top.rate': RATE, 'top.width': 32, 'top.height': 24,
        'rerun_path': str(path), 'diagnostics_rate': 5.0}, domain_id=domain)
    client = RosClient(domain)
    try:
        client.subscribe(CameraInfo, TOPICS['info'][0])
        client.subscribe(DiagnosticArray, '/diagnostics')

        def unread() -> int:
            latest = client.latest('/diagnostics')
            values = {pair.key: pair.value for pair in latest.status[0].values} \
                if latest is not None else {}
            return int(values.get('unread_outputs', 0))
        client.spin_until(lambda: len(client.messages(TOPICS['info'][0])) >= 10
                          and unread() >= 20, 90,
                          'ten camera infos and twenty outputs skipped', process)
        assert not client.messages('paper/points')
        client.subscribe(PointCloud2, 'paper/points')
        client.spin_until(lambda: len(client.messages('paper/points')) >= 3, 30,
                          'the cloud, once it has a reader', process)
    finally:
        client.close()
        stop_cleanly(process)
    depth_frames = sum(len(chunk.to_record_batch().column('DepthImage:buffer'))
                       for chunk in read_chunks(str(path))
                       if chunk.entity_path == '/paper/cameras/top/depth')
    # every camera frame recorded, read or not: at least those whose info arrived
    assert depth_frames >= len(client.messages(TOPICS['info'][0])) >= 10
