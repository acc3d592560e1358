"""The node as its own process, over real DDS: rates, clouds, probes, bad input, services.

One node (17 x 17 grid, sheet flat on the table) serves the whole module; the tests run in
file order and each leaves it running. The sheet lies on the table at z = 0, so a probe
"pressing into the sheet" from below the table surface lifts the vertices above it.
"""
from __future__ import annotations

import math
import re
import time

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseStamped
from rcl_interfaces.msg import ParameterType
from rcl_interfaces.srv import DescribeParameters, GetParameters, ListParameters
from sensor_msgs.msg import PointCloud2
from std_srvs.srv import Trigger
from visualization_msgs.msg import Marker, MarkerArray

from paper_sim_ros.core.materials import MATERIAL_PRESETS
from ros_harness import (RosClient, cloud_positions, new_domain_id, parse_cloud, set_parameters,
                         start_node, stop_cleanly)

GRID = 17
VERTICES = GRID * GRID
RATES = {'publish_rate': 20.0, 'markers_rate': 5.0, 'diagnostics_rate': 2.0}
PROBE_RADIUS = 0.03
PRESS = (0.0, 0.0, -0.01)
"""A probe centre under the table top: its cap lifts the sheet up to z = 0.02 over (0, 0)."""


@pytest.fixture(scope='module')
def sim(tmp_path_factory):
    log_dir = tmp_path_factory.mktemp('node')
    domain = new_domain_id()
    process = start_node(log_dir, {'sheet.nx': GRID, 'sheet.ny': GRID,
                                   'probe_radii': [PROBE_RADIUS], 'probe_timeout': 0.3,
                                   **RATES}, domain_id=domain)
    client = RosClient(domain)
    client.subscribe(PointCloud2, 'paper/points')
    client.subscribe(MarkerArray, 'paper/markers')
    client.subscribe(DiagnosticArray, '/diagnostics')
    client.pose_publisher = client.node.create_publisher(PoseStamped, 'probe/pose', 10)
    client.process = process
    try:
        client.spin_until(lambda: client.latest('paper/points') is not None, 60,
                          'the first point cloud', process)
        client.spin_for(0.5)
        client.assert_alone()
        yield client
    finally:
        client.close()
        stop_cleanly(process)


def pose(client, position, frame='world', orientation=(0.0, 0.0, 0.0, 1.0)) -> PoseStamped:
    msg = PoseStamped()
    msg.header.frame_id = frame
    msg.header.stamp = client.node.get_clock().now().to_msg()
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = map(float, position)
    (msg.pose.orientation.x, msg.pose.orientation.y, msg.pose.orientation.z,
     msg.pose.orientation.w) = map(float, orientation)
    return msg


def press_for(client, seconds: float, position=PRESS, rate: float = 30.0, **kwargs) -> None:
    last = [0.0]

    def publish():
        if time.monotonic() - last[0] >= 1.0 / rate:
            client.pose_publisher.publish(pose(client, position, **kwargs))
            last[0] = time.monotonic()
    client.spin_for(seconds, publish)


def _seconds(stamp) -> float:
    return stamp.sec + 1e-9 * stamp.nanosec


def diagnostics(client) -> dict:
    latest = client.latest('/diagnostics')
    assert latest is not None, 'no diagnostics received'
    status = latest.status[0]
    return {pair.key: pair.value for pair in status.values}


def fresh_cloud(client, timeout: float = 5.0) -> PointCloud2:
    since = time.monotonic()
    client.spin_until(lambda: client.messages('paper/points', since), timeout,
                      'a new point cloud', client.process)
    return client.messages('paper/points', since)[-1]


def assert_finite_outputs(client, since: float) -> None:
    clouds = client.messages('paper/points', since)
    assert clouds, 'no clouds in the interval'
    for cloud in clouds:
        points = parse_cloud(cloud)
        for name in points.dtype.names:
            assert np.isfinite(points[name].astype(np.float64)).all(), f'{name} not finite'
    for array in client.messages('paper/markers', since):
        for marker in array.markers:
            values = [v for p in marker.points for v in (p.x, p.y, p.z)]
            assert np.isfinite(values).all(), f'non-finite marker {marker.ns}'


def reset(client) -> None:
    response = client.call(Trigger, 'paper/reset', Trigger.Request())
    assert response.success, response.message


def get_parameter(client, name: str):
    response = client.call(GetParameters, '/paper_sim/get_parameters',
                           GetParameters.Request(names=[name]))
    value = response.values[0]
    return {ParameterType.PARAMETER_DOUBLE: value.double_value,
            ParameterType.PARAMETER_INTEGER: value.integer_value,
            ParameterType.PARAMETER_STRING: value.string_value,
            ParameterType.PARAMETER_DOUBLE_ARRAY: list(value.double_array_value)}[value.type]


# ------------------------------------------------------------------------------- outputs
@pytest.mark.slow
def test_outputs_arrive_at_the_configured_rates(sim):
    window = 4.0
    since = time.monotonic()
    sim.spin_for(window)
    for topic, rate in (('paper/points', RATES['publish_rate']),
                        ('paper/markers', RATES['markers_rate']),
                        ('/diagnostics', RATES['diagnostics_rate'])):
        measured = len(sim.messages(topic, since)) / window
        assert 0.6 * rate <= measured <= 1.25 * rate, f'{topic}: {measured:.2f} Hz, want {rate}'
    clouds = sim.messages('paper/points', since)
    stamps = [_seconds(c.header.stamp) for c in clouds]
    assert all(b > a for a, b in zip(stamps, stamps[1:])), 'stamps must increase'
    gaps = np.diff(stamps)
    np.testing.assert_allclose(np.median(gaps), 1.0 / RATES['publish_rate'], rtol=0.25,
                               err_msg='stamps are not spaced by the publish period')
    assert abs(stamps[-1] - time.time()) < 2.0, 'stamps are not near the clock'
    for cloud in clouds:
        assert cloud.header.frame_id == 'world'
    for array in sim.messages('paper/markers', since):
        assert {m.header.frame_id for m in array.markers} == {'world'}
    values = diagnostics(sim)
    for key in ('step_time_ms', 'real_time_factor', 'vertices', 'springs', 'breaks', 'folds',
                'dropped_frames'):
        assert key in values, f'diagnostics lack {key}'
    assert float(values['real_time_factor']) > 0.5


def test_cloud_parses_back_to_the_vertices(sim):
    cloud = fresh_cloud(sim)
    assert [(f.name, f.offset, f.datatype) for f in cloud.fields] == [
        ('x', 0, 7), ('y', 4, 7), ('z', 8, 7), ('normal_x', 12, 7), ('normal_y', 16, 7),
        ('normal_z', 20, 7), ('label', 24, 4), ('u', 28, 7), ('v', 32, 7)]
    points = parse_cloud(cloud)
    assert cloud.width == VERTICES and cloud.height == 1 and points.shape == (VERTICES,)
    assert int(diagnostics(sim)['vertices']) == VERTICES
    for name in points.dtype.names:
        assert np.isfinite(points[name].astype(np.float64)).all(), name
    normals = np.stack([points['normal_x'], points['normal_y'], points['normal_z']], 1)
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-5,
                               err_msg='normals are not of unit length')
    positions = cloud_positions(cloud)
    np.testing.assert_allclose(positions[:, 2], 0.0, atol=1e-3, err_msg='sheet not on table')
    assert np.ptp(positions[:, 0]) == pytest.approx(0.210, rel=0.01)
    assert np.ptp(positions[:, 1]) == pytest.approx(0.297, rel=0.01)
    np.testing.assert_array_equal(points['label'], 0, err_msg='an untouched sheet is undamaged')
    # material coordinates: a flat sheet at rest is where its material is
    np.testing.assert_allclose(points['u'], positions[:, 0], atol=1e-3)
    np.testing.assert_allclose(points['v'], positions[:, 1], atol=1e-3)


def test_markers_are_valid_for_rviz(sim):
    since = time.monotonic()
    sim.spin_until(lambda: sim.messages('paper/markers', since), 5, 'markers', sim.process)
    array = sim.messages('paper/markers', since)[-1]
    kinds = {(m.ns, m.id): m for m in array.markers if m.action == Marker.ADD}
    surface = kinds[('paper/surface', 0)]
    assert surface.type == Marker.TRIANGLE_LIST
    assert len(surface.points) % 3 == 0 and len(surface.points) == len(surface.colors)
    assert len(surface.points) == 3 * 2 * (GRID - 1) ** 2
    hinge = kinds[('paper/springs/hinge', 0)]
    assert hinge.type == Marker.LINE_LIST and len(hinge.points) % 2 == 0
    for marker in array.markers:
        q = marker.pose.orientation
        assert math.isclose(q.x ** 2 + q.y ** 2 + q.z ** 2 + q.w ** 2, 1.0, abs_tol=1e-9)
        if marker.action == Marker.ADD:
            assert marker.scale.x > 0


# -------------------------------------------------------------------------------- probes
@pytest.mark.slow
def test_a_sheet_left_alone_sleeps_and_a_probe_moving_near_it_wakes_it(sim):
    """solver.sleep_speed: the sheet lying untouched on the table sleeps (its frames cost
    nothing); a probe moving 3 mm above it, within its reach but touching nothing (so the
    sheet stays where the next tests expect it), wakes it at once, and once the probe has
    gone it sleeps again. The diagnostics say which."""
    started = time.monotonic()

    def asleep(value: str, hovering: bool):
        def reported() -> bool:
            if hovering:
                x = 0.02 * math.sin(2.0 * (time.monotonic() - started))
                sim.pose_publisher.publish(pose(sim, (x, 0.0, PROBE_RADIUS + 0.003)))
            latest = sim.latest('/diagnostics')
            return latest is not None and \
                {pair.key: pair.value for pair in latest.status[0].values}['asleep'] == value
        return reported
    sim.spin_until(asleep('true', False), 10, 'the untouched sheet asleep', sim.process)
    sim.spin_until(asleep('false', True), 10, 'the sheet awake under the probe', sim.process)
    sim.spin_until(asleep('true', False), 30, 'the sheet asleep again after the probe left',
                   sim.process)


@pytest.mark.slow
def test_a_probe_moves_the_points_under_it_and_letting_go_stops_it(sim):
    reset(sim)
    before = fresh_cloud(sim)
    flat = cloud_positions(before)[:VERTICES]
    under = np.hypot(flat[:, 0] - PRESS[0], flat[:, 1] - PRESS[1]) < 0.015
    away = np.hypot(flat[:, 0], flat[:, 1]) > 0.08
    assert under.sum() >= 1 and away.sum() > 100
    # the node steps in real time beside the test: on a loaded machine its cloud can trail
    # the poses, so the press goes on (up to 11 s) until the cloud shows the sheet lifted
    # and settled, a simulated second after the press began (the sheet the cap lifts at
    # once is flung: 41 mm far out 0.07 s in; 48 mm seen once in a run beside other work)
    press_for(sim, 1.0)
    deadline = time.monotonic() + 10.0
    while True:
        press_for(sim, 0.5)
        cloud = fresh_cloud(sim)
        pressed = cloud_positions(cloud)[:VERTICES]
        lift = pressed[under, 2].max()
        settled = _seconds(cloud.header.stamp) - _seconds(before.header.stamp) > 1.5
        if (lift > 0.01 and settled) or time.monotonic() > deadline:
            break
    assert lift > 0.01, f'the probe lifted the sheet above it only by {lift:.4f} m ' \
        f'(diagnostics: {diagnostics(sim)})'
    # the longer the press (a loaded machine), the more of the sheet drapes over the
    # probe: the far sheet rises, but less than the pressed part (13 mm against 20 mm
    # after 4 s of pressing, once in a run beside other work)
    far = pressed[away, 2].max()
    assert far < 0.75 * lift, \
        f'the far sheet rose {far:.4f} m, as much as the pressed part ({lift:.4f} m)'
    assert int(diagnostics(sim)['active_probes']) == 1
    sim.spin_for(2.5)  # no more poses: after probe_timeout the probe lets go
    released = cloud_positions(fresh_cloud(sim))[:VERTICES]
    assert released[under, 2].max() < 0.004, 'the sheet did not fall back without the probe'
    assert int(diagnostics(sim)['active_probes']) == 0


# ---------------------------------------------------------------------------- bad input
@pytest.mark.parametrize('case, position, frame, orientation, reason', [
    ('nan', (math.nan, 0.0, -0.01), 'world', (0, 0, 0, 1), 'not finite'),
    ('inf', (0.0, math.inf, -0.01), 'world', (0, 0, 0, 1), 'not finite'),
    ('nan orientation', PRESS, 'world', (0, 0, math.nan, 1), 'not finite'),
    ('far', (1.0e6, 0.0, 0.0), 'world', (0, 0, 0, 1), 'farther than'),
    ('wrong frame', PRESS, 'camera', (0, 0, 0, 1), "frame 'camera'"),
    ('empty frame', PRESS, '', (0, 0, 0, 1), "frame ''"),
])
def test_bad_poses_are_refused_and_logged(sim, case, position, frame, orientation, reason):
    reset(sim)
    refused_before = int(diagnostics(sim)['poses_refused'])
    since = time.monotonic()
    press_for(sim, 1.2, position=position, frame=frame, orientation=orientation)
    sim.spin_for(0.6)
    assert sim.process.alive(), sim.process.output()[-2000:]
    assert_finite_outputs(sim, since)
    cloud = cloud_positions(fresh_cloud(sim))
    assert np.abs(cloud[:, 2]).max() < 2e-3, f'a refused {case} pose acted on the sheet'
    assert re.search(rf'refused pose on probe/pose: [^\n]*{re.escape(reason)}',
                     sim.process.output()), f'no log of why the {case} pose was refused'
    assert int(diagnostics(sim)['poses_refused']) > refused_before


def test_a_flood_of_poses_does_not_stall_the_node(sim):
    reset(sim)
    hover = pose(sim, (0.0, 0.0, 0.3))
    since = time.monotonic()
    flood_started = time.time()  # the node stamps /diagnostics with the system clock
    sent = 0
    end = since + 2.5
    while time.monotonic() < end:
        for _ in range(50):
            sim.pose_publisher.publish(hover)
        sent += 50
        sim.executor.spin_once(timeout_sec=0)
    flood_seconds = time.monotonic() - since
    assert sent / flood_seconds > 1000, f'only {sent / flood_seconds:.0f} poses/s sent'
    clouds = sim.messages('paper/points', since)
    rate = len(clouds) / flood_seconds
    assert rate > 0.5 * RATES['publish_rate'], f'clouds at {rate:.1f} Hz under the flood'
    assert_finite_outputs(sim, since)
    # by when the node published them, not when this harness, spinning one callback per 50
    # poses, got round to them (once in 32 runs a report said no probe was active; one
    # from before the flood took hold, read late, is the likely cause)
    reports = [{pair.key: pair.value for pair in array.status[0].values}
               for array in sim.messages('/diagnostics', since)
               if _seconds(array.header.stamp) >= flood_started + 0.6]
    assert reports, 'no diagnostics during the flood'
    assert all(int(values['active_probes']) == 1 for values in reports), \
        'the latest pose of the flood is not in use'
    assert min(float(values['real_time_factor']) for values in reports) > 0.5


def test_parameters_are_declared_with_descriptions_and_ranges(sim):
    names = sim.call(ListParameters, '/paper_sim/list_parameters',
                     ListParameters.Request()).result.names
    for name in ('frame_id', 'sheet.nx', 'physics_rate', 'publish_rate', 'markers_rate',
                 'solver.method', 'solver.jacobi_iterations', 'probe_topics', 'probe_radii',
                 'probe_timeout', 'contact.ground_enabled', 'seed', 'crumple_count',
                 'crumple_seed', 'points.dense_samples', 'points.noise_stddev', 'pin_mode',
                 'use_sim_time', 'rerun_path', 'rerun_connect'):
        assert name in names, f'{name} is not declared'
    described = sim.call(DescribeParameters, '/paper_sim/describe_parameters',
                         DescribeParameters.Request(names=['sheet.nx', 'publish_rate',
                                                           'probe_radii'])).descriptors
    nx, publish_rate, radii = described
    assert nx.read_only and nx.integer_range and nx.integer_range[0].from_value == 3
    assert not publish_rate.read_only and publish_rate.floating_point_range
    assert all(d.description for d in described)
    assert not radii.read_only


def test_invalid_parameter_values_are_refused_with_a_reason(sim):
    before = {name: get_parameter(sim, name) for name in
              ('publish_rate', 'solver.jacobi_iterations', 'pin_mode', 'probe_radii',
               'sheet.nx')}
    cases = [
        ({'publish_rate': -5.0}, ''),
        ({'solver__jacobi_iterations': -1}, ''),
        ({'pin_mode': 'sideways'}, 'pin_mode must be one of'),
        ({'probe_radii': [0.0]}, 'probe radii'),
        ({'probe_radii': [0.01, 0.02, 0.03]}, 'one radius per probe topic'),
        ({'sheet__nx': 33}, ''),
        ({'publish_rate': 'fast'}, ''),
    ]
    for values, reason in cases:
        results = set_parameters(sim, **values)
        assert len(results) == 1 and not results[0].successful, f'{values} was accepted'
        assert results[0].reason, f'{values} refused without a reason'
        assert reason in results[0].reason, results[0].reason
    after = {name: get_parameter(sim, name) for name in before}
    assert after == before, 'a refused change altered a parameter'
    assert "refused parameter change: pin_mode must be one of none, short_edge, got 'sideways'" \
        in sim.process.output()
    since = time.monotonic()
    sim.spin_for(1.0)
    assert_finite_outputs(sim, since)
    # and a valid run-time change is applied
    assert set_parameters(sim, solver__jacobi_iterations=12)[0].successful
    assert get_parameter(sim, 'solver.jacobi_iterations') == 12


@pytest.mark.slow
def test_run_time_changes_take_effect(sim):
    """Dense, noisy cloud sampling, pinning, sub-steps and the table, changed while
    running."""
    reset(sim)
    assert all(result.successful for result in set_parameters(
        sim, points__dense_samples=3, points__noise_stddev=0.001))
    sim.spin_for(0.5)
    cloud = fresh_cloud(sim)
    triangles = 2 * (GRID - 1) ** 2
    assert cloud.width >= 3 * triangles, 'the cloud is not the dense sampling'
    points = parse_cloud(cloud)
    for name in points.dtype.names:
        assert np.isfinite(points[name].astype(np.float64)).all(), name
    assert 0.0005 < float(np.std(points['z'])) < 0.002, 'no sensor-like noise on z'
    assert all(result.successful for result in set_parameters(
        sim, points__dense_samples=0, points__noise_stddev=0.0))
    assert set_parameters(sim, pin_mode='short_edge')[0].successful
    sim.spin_for(1.2)
    assert int(diagnostics(sim)['pinned_vertices']) == GRID
    assert set_parameters(sim, pin_mode='none')[0].successful
    sim.spin_for(1.2)
    assert int(diagnostics(sim)['pinned_vertices']) == 0
    assert fresh_cloud(sim).width == VERTICES
    # the solver's sub-steps and the table height, while running
    assert all(result.successful for result in set_parameters(
        sim, solver__substeps=2, contact__ground_height=0.01))
    sim.spin_for(1.5)
    raised = cloud_positions(fresh_cloud(sim))
    assert raised[:, 2].min() > 0.0095, 'the sheet did not follow the raised table'
    assert get_parameter(sim, 'solver.substeps') == 2
    assert all(result.successful for result in set_parameters(
        sim, solver__substeps=1, contact__ground_height=0.0))
    sim.spin_for(1.0)
    assert np.isfinite(cloud_positions(fresh_cloud(sim))).all()


@pytest.mark.slow
def test_reset_during_contact(sim):
    reset(sim)
    press_for(sim, 1.0)
    since = time.monotonic()
    response = sim.call(Trigger, 'paper/reset', Trigger.Request())
    assert response.success and 'reset' in response.message
    press_for(sim, 1.5)
    assert sim.process.alive()
    assert_finite_outputs(sim, since)
    arrays = sim.messages('paper/markers', since)
    assert any(a.markers and a.markers[0].action == Marker.DELETEALL for a in arrays), \
        'no DELETEALL after the reset'
    lifted = cloud_positions(fresh_cloud(sim))[:VERTICES, 2].max()
    assert lifted > 0.01, 'the probe does not act on the sheet after the reset'
    sim.spin_for(1.0)
    assert int(diagnostics(sim)['resets']) >= 1


def test_crumple_service_answers(sim):
    reset(sim)
    response = sim.call(Trigger, 'paper/crumple', Trigger.Request())
    assert response.success, response.message
    sim.spin_for(1.5)
    values = diagnostics(sim)
    assert int(values['aux_springs']) > 0 or int(values['vertices']) > VERTICES
    labels = parse_cloud(fresh_cloud(sim))['label']
    assert labels.max() > 0, 'crumpled sheet has no damage labels'
    since = time.monotonic()
    sim.spin_for(1.0)
    assert_finite_outputs(sim, since)


def _report_since(client, since: float, timeout: float = 5.0):
    """The first /diagnostics status that came after ``since`` (a whole window later)."""
    client.spin_until(lambda: len(client.messages('/diagnostics', since)) >= 2, timeout,
                      'two diagnostics reports', client.process)
    status = client.messages('/diagnostics', since)[1].status[0]
    return status, {pair.key: pair.value for pair in status.values}


def test_diagnostics_report_the_strain_and_warn_beyond_strain_warning(sim):
    """The diagnostics carry the largest HINGE strain of their window and of the run, and
    warn while the window's exceeds ``strain_warning``: a user sees when the sheet is no
    longer paper. A crumpled sheet's creases strain it; at a threshold below that, WARN
    with the figure; switched off (0), no warning for it."""
    reset(sim)
    assert set_parameters(sim, strain_warning=1e-9)[0].successful
    try:
        assert sim.call(Trigger, 'paper/crumple', Trigger.Request()).success
        status, values = _report_since(sim, time.monotonic())
        window, run = float(values['max_strain']), float(values['max_strain_run'])
        assert 1e-9 < window <= run < 10.0, values
        assert status.level == DiagnosticStatus.WARN, (status.level, status.message)
        assert re.search(r'sheet strained \d+\.\d% \(beyond strain_warning 0\.0%\)',
                         status.message), status.message
        assert set_parameters(sim, strain_warning=0.0)[0].successful
        status, values = _report_since(sim, time.monotonic())
        assert 'strained' not in status.message, status.message
        assert float(values['max_strain_run']) >= run
    finally:
        assert set_parameters(sim, strain_warning=0.02)[0].successful


# ----------------------------------------------------------------------- material, looks
@pytest.mark.slow
def test_a_material_sets_the_defaults_and_explicit_values_win(tmp_path):
    """A node of its own: material cardboard with damage.fragility given on the command
    line. The preset's values are the sheet's, the explicit one wins, and the material and
    the appearance are read-only parameters with ranges."""
    domain = new_domain_id()
    process = start_node(tmp_path, {'sheet.nx': 9, 'sheet.ny': 9, 'material': 'cardboard',
                                    'damage.fragility': 3.0, 'appearance.texture_blend': 0.5},
                         domain_id=domain)
    client = RosClient(domain)
    client.process = process
    try:
        client.subscribe(PointCloud2, 'paper/points')
        client.spin_until(lambda: client.latest('paper/points') is not None, 60,
                          'the first point cloud', process)
        cardboard = MATERIAL_PRESETS['cardboard']
        assert get_parameter(client, 'material') == 'cardboard'
        for name in ('grammage', 'stretch_stiffness', 'bending_rigidity'):
            assert get_parameter(client, f'sheet.{name}') == cardboard['sheet'][name], name
        assert get_parameter(client, 'damage.area_conservation') == \
            cardboard['damage']['area_conservation']
        assert get_parameter(client, 'damage.fragility') == 3.0, 'the explicit value lost'
        assert get_parameter(client, 'appearance.texture_blend') == 0.5
        material, ambient = client.call(
            DescribeParameters, '/paper_sim/describe_parameters',
            DescribeParameters.Request(names=['material', 'appearance.ambient'])).descriptors
        assert material.read_only and 'cardboard' in material.description
        assert ambient.read_only and ambient.floating_point_range[0].to_value == 1.0
        refused = set_parameters(client, material='banknote')[0]
        assert not refused.successful and get_parameter(client, 'material') == 'cardboard'
    finally:
        client.close()
        stop_cleanly(process)
