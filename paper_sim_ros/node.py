"""The ROS 2 node: probe poses in; markers, point clouds and diagnostics out (SPEC §7).

    ros2 run paper_sim_ros paper_sim_node --ros-args --params-file config/paper_sim.yaml
    python -m paper_sim_ros.node --ros-args --params-file config/paper_sim.yaml

Timing. The simulation steps frames of exactly dt = 1 / ``physics_rate`` on a timer of the
node's clock (wall clock, or ``/clock`` with ``use_sim_time``). Each tick steps as many frames
as the clock has advanced, at most ``max_catchup_frames``; if it is further behind, the
simulation slips (its clock origin moves forward, the real-time factor drops below 1) instead
of taking bigger steps. With ``publish_clock`` the simulation is the clock instead: it steps
as fast as it can, up to ``max_real_time_factor``, never slips, and publishes its time on
/clock after every frame for nodes run with ``use_sim_time``. Outputs are scheduled in
simulated time at their own rates. The point
cloud and the markers are published at most once per tick: when frames are stepped faster
than they can follow, publications are dropped, never physics frames. Both are counted in
``/diagnostics``. A virtual camera renders the frame its slot falls on, also in a tick of
several frames, so that its images keep to the grid t = k / rate of simulated time.

Stamps. Every header carries ``frame_id`` and the time of the state it shows: the clock time
at which the simulation started (or was reset) plus the simulated time.

Probes. One ``geometry_msgs/PoseStamped`` topic per probe (``probe_topics``); only the latest
poses of each are kept (queue depth POSE_HISTORY), and each tick takes every one waiting
before it steps, so a flood of poses costs a few callbacks a tick and nothing else. Poses
in another frame, with NaN / inf, or absurdly far away are refused with a throttled warning
naming the reason, and counted.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from collections import deque
import math
import sys
import time

import numpy as np
from rclpy.clock import Clock, ClockType
from rclpy.exceptions import ParameterException
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy, HistoryPolicy, DurabilityPolicy
from builtin_interfaces.msg import Time as TimeMessage
from rclpy.time import Time
from rosgraph_msgs.msg import Clock as ClockMessage
from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                SetParametersResult)
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import CameraInfo, Image, PointCloud2
from std_msgs.msg import Header
from std_srvs.srv import Trigger
from visualization_msgs.msg import MarkerArray

from .bag_recorder import BagRecorder, message_type_name
from .core.appearance import PaperAppearance
from .core.camera import render_simulator, with_depth_noise
from .core.scenarios import pin_mask
from .core.sheet import AUX, BEND, HINGE, Sheet
from .core.simulator import Simulator
from .core.topology import vertex_normals
from .msg_adapters.camera import camera_messages
from .msg_adapters.diagnostics import diagnostic_array, diagnostic_status
from .msg_adapters.markers import MarkerStyle, sheet_markers_cdr
from .msg_adapters.point_cloud import create_cloud, dense_surface_points, sheet_points
from .node_runner import run_node
from .pose_track import POSE_HISTORY, PoseTrack
from .node_parameters import (PARAMETER_SPECS, NodeSettings, declared_defaults,
                              parameter_table, settings_from_values)
from .rerun_logger import RerunRecorder

NODE_NAME = 'paper_sim'
DIAGNOSTIC_NAME = 'paper_sim: simulation'
OUTPUT_QOS = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST,
                        reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.VOLATILE)
"""Reliable, latest only: RViz subscribes reliable by default; best-effort readers connect."""
POSE_QOS = QoSProfile(depth=POSE_HISTORY, history=HistoryPolicy.KEEP_LAST,
                      reliability=ReliabilityPolicy.RELIABLE)
"""As deep as the track: the poses that came while a tick ran (one tick behind the clock
at 65² takes 0.1-0.2 s) reach the track (``_take_waiting_poses``), which places each by its
stamp. With depth 1 only the last of them did, the track's poses lay too far apart to
extrapolate from, and the probe stood still for the last frames of every tick, then went on
at once (the demo, 65²: 13-15 % strain). Under a flood the same few poses wait, never
more."""
CLOCK_QOS = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST,
                       reliability=ReliabilityPolicy.RELIABLE)
"""/clock with ``publish_clock``: latest only (rclpy's time source reads it best-effort)."""
CLOCK_TICK_SECONDS = 0.001
"""With ``publish_clock``, the wall-clock period of the tick timer; each tick steps at most
one frame (so at most 1 000 frames a wall-clock second)."""
WARN_EVERY = 2.0
"""Seconds between two warnings of one kind (refused poses, failed ticks)."""


class StartupError(Exception):
    """A configuration the node cannot start with; the message says why."""


@dataclass
class ProbeInput:
    """The accepted poses of one probe topic: when the latest arrived, and the recent ones
    by their stamps (where the probe is at each frame's time: pose_track.py)."""

    topic: str
    received: Time | None = None
    track: PoseTrack = field(default_factory=PoseTrack)
    unstamped: np.ndarray | None = None
    """The latest pose without a usable stamp, not yet on the track: the next tick puts it at
    its end (where the probe is once the tick's frames are stepped)."""


@dataclass
class Schedule:
    """When an output is next due, in simulated seconds, and how many were dropped."""

    next_time: float = 0.0
    dropped: int = 0

    def take(self, sim_time: float, rate: float) -> bool:
        """True if the output is due at ``sim_time``; skipped slots count as dropped. While
        the output is off (rate 0) nothing is due and nothing is dropped."""
        if rate <= 0:
            self.next_time = sim_time
            return False
        if sim_time + 1e-9 < self.next_time:
            return False
        period = 1.0 / rate
        missed = int((sim_time + 1e-9 - self.next_time) // period)
        self.dropped += missed
        self.next_time += (missed + 1) * period
        return True


@dataclass
class Statistics:
    """Counters for /diagnostics; the ``window_*`` ones restart at every report."""

    frames_stepped: int = 0
    slipped_frames: int = 0
    poses_received: int = 0
    poses_refused: int = 0
    tick_errors: int = 0
    nonfinite_skipped: int = 0
    unread_outputs: int = 0
    """Output messages that fell due but were not built: no reader was matched to their
    topic (PaperSimNode._read)."""
    resets: int = 0
    window_step_seconds: float = 0.0
    window_step_max: float = 0.0
    window_steps: int = 0
    window_publish_seconds: float = 0.0
    window_publishes: int = 0
    window_started: float = 0.0
    window_frames: int = 0
    window_dropped: int = 0
    window_slipped: int = 0
    window_refused: int = 0
    window_max_strain: float = 0.0
    """Largest HINGE strain of a frame since the last report."""
    last_real_time_factor: float = 0.0
    last_step_seconds: float = 0.0
    max_strain: float = 0.0
    """Largest HINGE strain |l/l0 - 1| of any frame since start."""
    recent_strains: deque = field(default_factory=deque)
    """HINGE max strain of each of the last second's frames (a deque of one second's length)."""


def _descriptor(spec) -> ParameterDescriptor:
    descriptor = ParameterDescriptor(description=spec.description, read_only=spec.read_only)
    if spec.bounds is not None:
        low, high = spec.bounds
        if isinstance(spec.default, bool):
            pass
        elif isinstance(spec.default, int):
            descriptor.integer_range = [IntegerRange(from_value=int(low), to_value=int(high),
                                                     step=1)]
        else:
            descriptor.floating_point_range = [FloatingPointRange(
                from_value=float(low), to_value=float(high), step=0.0)]
    return descriptor


class PaperSimNode(Node):
    """Steps the sheet on a timer and serves it; see the module docstring."""

    def __init__(self, **node_kwargs) -> None:
        super().__init__(NODE_NAME, **node_kwargs)
        self._recorder = None
        self._bag = None
        # the material first: its preset gives the other parameters their defaults
        # and the camera names: each has its own parameters
        material = self.declare_parameter('material', PARAMETER_SPECS['material'].default,
                                          _descriptor(PARAMETER_SPECS['material'])).value
        cameras = self.declare_parameter('cameras', PARAMETER_SPECS['cameras'].default,
                                         _descriptor(PARAMETER_SPECS['cameras'])).value
        try:
            defaults = declared_defaults(material, cameras)
        except ValueError as error:
            raise StartupError(f'invalid parameters: {error}') from None
        self._specs = {spec.name: spec for spec in parameter_table(cameras)}
        for spec in self._specs.values():
            if spec.name not in ('material', 'cameras'):
                self.declare_parameter(spec.name, defaults[spec.name], _descriptor(spec))
        self._values = {name: self.get_parameter(name).value for name in self._specs}
        try:
            self._settings = settings_from_values(self._values)
        except ValueError as error:
            raise StartupError(f'invalid parameters: {error}') from None
        settings = self._settings
        if settings.publish_clock and self.get_parameter('use_sim_time').value:
            raise StartupError('publish_clock and use_sim_time exclude each other: the '
                               'simulation would follow the clock it publishes')

        self.simulator = Simulator(settings.simulation)
        self._apply_pins()
        try:
            self._appearance = PaperAppearance(settings.appearance, self.simulator.sheet)
        except OSError as error:  # the texture image: missing or not an image
            raise StartupError(f'cannot load appearance.texture_path: {error}') from None
        self._warm_up()

        self._recorder = self._open_recorder(settings)
        if settings.bag_path:
            try:
                self._bag = BagRecorder(settings.bag_path)
            except (OSError, ValueError) as error:
                raise StartupError(f'cannot write the bag: {error}') from None
        self._stats = Statistics(
            window_started=time.monotonic(),
            recent_strains=deque(maxlen=int(round(self._settings.physics_rate))))
        self._points_schedule = Schedule()
        self._markers_schedule = Schedule()
        self._camera_schedules = [Schedule() for _ in settings.cameras]
        self._cameras_on_tf_static: set[str] = set()
        self._origin_ns: int | None = 0 if settings.publish_clock else None
        """Clock time [ns] of frame 0: set by the first tick (publish_clock: 0, the start)."""
        self._wall_origin_ns: int | None = None
        """publish_clock: the steady clock [ns] at which frame 0 was due (the cap's base)."""
        self._delete_all_pending = True
        self._crumple_calls = 0
        self._rest_outputs: dict = {}
        """What was computed from a sleeping sheet, kept while it sleeps (_at_rest)."""

        self._points_pub = self.create_publisher(PointCloud2, 'paper/points', OUTPUT_QOS)
        self._markers_pub = self.create_publisher(MarkerArray, 'paper/markers', OUTPUT_QOS)
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self._clock_pub = (self.create_publisher(ClockMessage, '/clock', CLOCK_QOS)
                           if settings.publish_clock else None)
        self._camera_pubs = [
            (self.create_publisher(Image, f'{prefix}/depth/image_raw', OUTPUT_QOS),
             self.create_publisher(Image, f'{prefix}/color/image_raw', OUTPUT_QOS),
             self.create_publisher(CameraInfo, f'{prefix}/camera_info', OUTPUT_QOS),
             self.create_publisher(PointCloud2, f'{prefix}/points', OUTPUT_QOS))
            for prefix in (f'paper/{camera.config.name}' for camera in settings.cameras)]
        self._probes = [ProbeInput(topic) for topic in settings.probe_topics]
        self._pose_subscriptions = [
            self.create_subscription(PoseStamped, topic,
                                     lambda msg, index=index: self._on_pose(index, msg),
                                     POSE_QOS)
            for index, topic in enumerate(settings.probe_topics)]
        self.create_service(Trigger, 'paper/reset', self._on_reset)
        self.create_service(Trigger, 'paper/crumple', self._on_crumple)
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)

        if settings.publish_clock:
            self._tick_timer = self.create_timer(CLOCK_TICK_SECONDS, self._on_tick,
                                                 clock=Clock(clock_type=ClockType.STEADY_TIME))
        else:
            self._tick_timer = self.create_timer(1.0 / settings.physics_rate, self._on_tick)
        self._diagnostics_timer = None
        self._start_diagnostics_timer()
        sheet = self.simulator.sheet
        self.get_logger().info(
            f'{sheet.vertex_count} vertices, {len(sheet.triangles)} triangles, '
            f'{sheet.spring_count} springs; solver {settings.simulation.solver.method} at '
            f'{settings.physics_rate:g} Hz; probes on {", ".join(settings.probe_topics) or "-"}'
            f' in frame {settings.frame_id!r}; recording: '
            f'{self._recorder.path if self._recorder is not None else "off"}')

    # ------------------------------------------------------------------------- set-up
    def _warm_up(self) -> None:
        """Compile the numba kernels before the first tick: a tiny sheet of the same
        configuration steps with a probe touching it and the table on."""
        config = self._settings.simulation
        tiny = replace(config, sheet=replace(config.sheet, nx=5, ny=5),
                       contact=replace(config.contact, ground_enabled=True))
        simulator = Simulator(tiny)
        center = simulator.sheet.positions.mean(axis=0)
        simulator.set_probes(center[None, :], np.array([0.01]), np.array([True]))
        simulator.step_frame()
        simulator.step_frame()
        colors = self._appearance.vertex_colors(self.simulator.sheet)
        for camera in self._settings.cameras[:1]:  # the organised cloud's kernel too
            tiny_camera = replace(camera.config, width=4, height=3)
            camera_messages(Header(), tiny_camera,
                            render_simulator(tiny_camera, self.simulator, colors))

    def _open_recorder(self, settings: NodeSettings):
        if not (settings.rerun_path or settings.rerun_connect):
            return None
        try:
            return RerunRecorder('paper_sim_ros', settings.rerun_path or None,
                                 settings.rerun_connect or None,
                                 {'node': self.get_fully_qualified_name(),
                                  'parameters': dict(self._values)},
                                 cameras=tuple(camera.config.name
                                               for camera in settings.cameras
                                               if camera.rate > 0))
        except (OSError, ValueError, RuntimeError) as error:
            raise StartupError(f'cannot record to Rerun: {error}') from None

    def _start_diagnostics_timer(self) -> None:
        if self._diagnostics_timer is not None:
            self.destroy_timer(self._diagnostics_timer)
        self._diagnostics_timer = self.create_timer(
            1.0 / self._settings.diagnostics_rate, self._on_diagnostics,
            clock=Clock(clock_type=ClockType.STEADY_TIME))

    def _apply_pins(self) -> None:
        self.simulator.set_pinned(pin_mask(self.simulator.sheet, self._settings.pin_mode))

    # ----------------------------------------------------------------------- parameters
    def _validate_parameters(self, parameters) -> SetParametersResult:
        """Refuse a change that would make the settings invalid; nothing is applied here."""
        values = dict(self._values)
        for parameter in parameters:
            if parameter.name in self._specs:
                values[parameter.name] = parameter.value
        try:
            settings_from_values(values)
        except (ValueError, TypeError) as error:
            self.get_logger().warn(f'refused parameter change: {error}')
            return SetParametersResult(successful=False, reason=str(error))
        return SetParametersResult(successful=True)

    def _apply_parameters(self, parameters) -> None:
        """Apply accepted changes (only run-time ones get here: the rest are read-only)."""
        changed = {parameter.name for parameter in parameters
                   if parameter.name in self._specs}
        if not changed:
            return
        for parameter in parameters:
            if parameter.name in self._specs:
                self._values[parameter.name] = parameter.value
        previous = self._settings
        self._settings = settings_from_values(self._values)
        if self._settings.simulation != previous.simulation:
            self.simulator.reconfigure(self._settings.simulation)
        if self._settings.pin_mode != previous.pin_mode:
            self._apply_pins()
        if self._settings.publish_rate != previous.publish_rate:
            self._points_schedule.next_time = min(self._points_schedule.next_time,
                                                  self.simulator.time)
        if self._settings.markers_rate != previous.markers_rate:
            self._markers_schedule.next_time = min(self._markers_schedule.next_time,
                                                   self.simulator.time)
        for schedule, camera, before in zip(self._camera_schedules, self._settings.cameras,
                                            previous.cameras):
            if camera.rate != before.rate:
                schedule.next_time = min(schedule.next_time, self.simulator.time)
        if self._settings.diagnostics_rate != previous.diagnostics_rate:
            self._start_diagnostics_timer()
        if self._settings.max_real_time_factor != previous.max_real_time_factor:
            self._wall_origin_ns = None  # the cap counts from now, at its new rate
        self.get_logger().info(f'parameters changed: {", ".join(sorted(changed))}')

    # --------------------------------------------------------------------------- probes
    def _on_pose(self, index: int, msg: PoseStamped) -> None:
        stats = self._stats
        stats.poses_received += 1
        probe = self._probes[index]
        logger = self.get_logger()
        position = msg.pose.position
        orientation = msg.pose.orientation
        center = np.array([position.x, position.y, position.z])
        quaternion = (orientation.x, orientation.y, orientation.z, orientation.w)
        limit = self._settings.simulation.contact.max_probe_distance
        if msg.header.frame_id != self._settings.frame_id:
            logger.warn(f'refused pose on {probe.topic}: frame {msg.header.frame_id!r} is not '
                        f'the sheet frame {self._settings.frame_id!r}',
                        throttle_duration_sec=WARN_EVERY)
        elif not (np.isfinite(center).all() and all(map(math.isfinite, quaternion))):
            logger.warn(f'refused pose on {probe.topic}: not finite (position '
                        f'{center.tolist()}, orientation {list(quaternion)})',
                        throttle_duration_sec=WARN_EVERY)
        elif float(np.linalg.norm(center)) > limit:
            logger.warn(f'refused pose on {probe.topic}: {np.linalg.norm(center):.3g} m from '
                        f'the origin, farther than contact.max_probe_distance = {limit:g} m',
                        throttle_duration_sec=WARN_EVERY)
        else:
            now = self._now()
            # a pose stamped on this clock is placed by its stamp, any other at a tick's end
            stamp_ns = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            if stamp_ns == 0 or abs(stamp_ns - now.nanoseconds) > \
                    self._settings.probe_timeout * 1e9:
                probe.unstamped = center
            else:
                probe.track.add(stamp_ns, center)
                probe.unstamped = None
            probe.received = now
            return
        stats.poses_refused += 1
        stats.window_refused += 1

    def _active_probes(self, now: Time) -> np.ndarray:
        """(P,) bool: the probes whose latest pose is within ``probe_timeout`` of ``now``."""
        active = np.zeros(len(self._probes), dtype=bool)
        timeout_ns = self._settings.probe_timeout * 1e9
        for index, probe in enumerate(self._probes):
            if probe.received is None:
                continue
            age_ns = (now - probe.received).nanoseconds if \
                now.nanoseconds >= probe.received.nanoseconds else -1
            active[index] = 0 <= age_ns <= timeout_ns
        return active

    # ------------------------------------------------------------------------- stepping
    def _on_tick(self) -> None:
        try:
            self._tick()
        except Exception as error:  # noqa: BLE001 - a failing frame must not end the node
            if not self.context.ok():
                return  # Ctrl-C or SIGTERM shut the context down mid-tick: nothing failed
            self._stats.tick_errors += 1
            self.get_logger().error(f'simulation tick failed: {error!r}',
                                    throttle_duration_sec=WARN_EVERY)

    def _now(self) -> Time:
        """The time the simulation lives in: the node's clock, or with ``publish_clock`` its
        own (the simulated time it publishes)."""
        if self._clock_pub is None:
            return self.get_clock().now()
        return Time(nanoseconds=self._simulated_ns(), clock_type=self.get_clock().clock_type)

    def _simulated_ns(self) -> int:
        """The clock time [ns] of the simulator's current frame."""
        return self._origin_ns + int(round(self.simulator.frame
                                           * self.simulator.config.solver.dt * 1e9))

    def _frames_due(self, now: Time) -> int:
        """Frames to step to catch up with the node's clock (``_tick`` steps at most
        ``max_catchup_frames`` of them and slips the rest)."""
        simulator = self.simulator
        dt_ns = simulator.config.solver.dt * 1e9
        if self._origin_ns is None:
            self._origin_ns = now.nanoseconds - int(round(simulator.frame * dt_ns))
            return 0
        due = int(math.floor((now.nanoseconds - self._origin_ns) / dt_ns + 0.25)) \
            - simulator.frame
        if due < -self._settings.physics_rate:
            # the clock jumped back by more than a second (a replayed /clock): follow it
            self.get_logger().warn('clock jumped back; re-basing the simulation clock')
            self._origin_ns = now.nanoseconds - int(round(simulator.frame * dt_ns))
            return 0
        return due

    def _frames_free_running(self) -> int:
        """With ``publish_clock``: one frame if ``max_real_time_factor`` allows it by now on
        the steady clock (0: no cap), else none. One a tick, so that nodes on /clock answer
        each frame before the next (a probe's pose for it); a simulation behind its cap
        owes nothing: it is the clock, and runs as fast as it can."""
        settings = self._settings
        if settings.max_real_time_factor <= 0:
            return 1
        frame = self.simulator.frame
        wall_ns = time.monotonic_ns()
        frame_wall_ns = self.simulator.config.solver.dt * 1e9 / settings.max_real_time_factor
        if self._wall_origin_ns is None \
                or wall_ns - self._wall_origin_ns > (frame + 1) * frame_wall_ns:
            self._wall_origin_ns = wall_ns - int(frame * frame_wall_ns)  # behind: rebase
        return int(wall_ns - self._wall_origin_ns >= frame * frame_wall_ns)

    def _take_waiting_poses(self) -> None:
        """Every pose waiting in the probe subscriptions' queues, onto the tracks, before a
        tick steps. The executor takes one message a subscription each time it waits, and a
        node behind the clock finds its tick due every time it waits: it took one pose a
        tick, and the rest waited in the queue, the oldest dropped (the demo at 65², 0.9×
        real time: poses 0.53 s old when taken, 689 of some 1 000 taken in 20 s). At most
        a queue's depth a tick, so that a flood cannot hold the tick up."""
        for index, subscription in enumerate(self._pose_subscriptions):
            for _ in range(POSE_HISTORY):
                with subscription.handle:
                    taken = subscription.handle.take_message(subscription.msg_type,
                                                             subscription.raw)
                if taken is None:
                    break
                self._on_pose(index, taken[0])

    def _tick(self) -> None:
        simulator = self.simulator
        self._take_waiting_poses()
        dt = simulator.config.solver.dt
        dt_ns = dt * 1e9
        now = self._now()
        due = self._frames_due(now) if self._clock_pub is None else self._frames_free_running()
        if due <= 0:
            return
        # where the last frame ended: the probes' path from there to this tick's last
        # frame is shared out over its frames, also when frames slipped
        last_end_ns = self._origin_ns + simulator.frame * dt_ns
        limit = self._settings.max_catchup_frames
        if due > limit:
            slipped = due - limit
            self._origin_ns += int(round(slipped * dt_ns))
            self._stats.slipped_frames += slipped
            self._stats.window_slipped += slipped
            due = limit
        active = self._active_probes(now)
        centers = np.zeros((active.size, 3))
        radii = np.asarray(self._settings.probe_radii, dtype=np.float64)
        stats = self._stats
        tick_end_ns = self._origin_ns + (simulator.frame + due) * dt_ns
        for probe, is_active in zip(self._probes, active):
            if not is_active:
                probe.track.forget_placement()  # when it returns, it comes from away
            if probe.unstamped is not None:
                # it moved there over this tick, from where it stood at the last frame
                newest = probe.track.newest_stamp
                if newest is not None and newest < last_end_ns:
                    probe.track.add(int(last_end_ns), probe.track.at(int(last_end_ns)))
                probe.track.add(int(round(tick_end_ns)), probe.unstamped)
                probe.unstamped = None
        for frame in range(due):
            # each probe where its poses put it at the end of this frame, not at its latest
            # pose: poses arrive in bursts (pose_track.py); a tick behind the clock steps
            # the path it lost in fewer, longer strides rather than one jump, and closes
            # any gap to poses that came after its frames over a few frames (place)
            frame_end_ns = int(round(last_end_ns + (frame + 1) / due
                                     * (tick_end_ns - last_end_ns)))
            for index in np.flatnonzero(active):
                centers[index] = self._probes[index].track.place(frame_end_ns, dt)
            self._set_probes(centers, radii, active)
            started = time.perf_counter()
            simulator.step_frame()
            seconds = time.perf_counter() - started
            stats.frames_stepped += 1
            stats.window_frames += 1
            stats.window_steps += 1
            stats.window_step_seconds += seconds
            stats.window_step_max = max(stats.window_step_max, seconds)
            stats.last_step_seconds = seconds
            strain = simulator.max_strain()
            stats.max_strain = max(stats.max_strain, strain)
            stats.window_max_strain = max(stats.window_max_strain, strain)
            stats.recent_strains.append(strain)
            # a camera renders the frame its slot falls on, also inside a tick of several
            # frames: its images keep to the grid t = k / rate of simulated time
            colors = self._publish_cameras()
            if self._recorder is not None and frame < due - 1:
                self._recorder.log_inputs(self._recording_time(), simulator)
        if self._clock_pub is not None:
            self._clock_pub.publish(ClockMessage(clock=self._stamp()))
        self._publish(colors)

    def _set_probes(self, centers: np.ndarray, radii: np.ndarray, active: np.ndarray) -> None:
        try:
            self.simulator.set_probes(centers, radii, active)
        except ValueError as error:  # poses are checked on arrival: a core limit changed
            self.get_logger().warn(f'probes ignored this frame: {error}',
                                   throttle_duration_sec=WARN_EVERY)
            self.simulator.set_probes(centers, radii, np.zeros_like(active))

    def _recording_time(self) -> float:
        """Seconds simulated since the node started, across resets (Rerun timeline)."""
        return self._stats.frames_stepped * self.simulator.config.solver.dt

    def _stamp(self):
        return Time(nanoseconds=max(0, self._simulated_ns()),
                    clock_type=self.get_clock().clock_type).to_msg()

    # ------------------------------------------------------------------------ publishing
    def _publish(self, colors: np.ndarray | None) -> None:
        """The point cloud, the markers and the recording when due; ``colors``: the sheet's
        vertex colours if a camera already computed them this frame."""
        settings = self._settings
        simulator = self.simulator
        sim_time = simulator.time
        want_points = self._points_schedule.take(sim_time, settings.publish_rate)
        want_markers = self._markers_schedule.take(sim_time, settings.markers_rate)
        recorder = self._recorder
        if not (want_points or want_markers):
            if recorder is not None:
                recorder.log_inputs(self._recording_time(), simulator)
            return
        # an output no one reads is not built (_read)
        want_points = want_points and self._read(self._points_pub)
        want_markers = want_markers and self._read(self._markers_pub)
        if not (want_points or want_markers or recorder is not None):
            return
        started = time.perf_counter()
        if not self._sheet_is_finite():
            return
        sheet = simulator.sheet
        header = Header(frame_id=settings.frame_id, stamp=self._stamp())
        if want_points:
            normals = vertex_normals(sheet.positions, sheet.triangles)
            self._send(self._points_pub, create_cloud(header, self._cloud_points(
                sheet, normals, simulator.damage_labels())), header.stamp)
        if colors is None and (want_markers or recorder is not None):
            colors = self._vertex_colors()
        if want_markers:
            centers, radii, active = (simulator.probes.end, simulator.probes.radius,
                                      simulator.probes.active)
            style = MarkerStyle(hinge_springs=settings.hinge_springs,
                                aux_springs=settings.aux_springs,
                                bend_springs=settings.bend_springs)
            # serialised by numpy: the same bytes as the MarkerArray object, 30x cheaper
            self._send(self._markers_pub, sheet_markers_cdr(
                header, sheet.positions, sheet.triangles, colors, sheet.spring_vertices,
                sheet.spring_kind, centers, radii, active, style,
                delete_all=self._delete_all_pending), header.stamp)
            self._delete_all_pending = False
        if recorder is not None:
            stats = self._stats
            recorder.log_frame(self._recording_time(), simulator, vertex_colors=colors,
                               scalars={'step_time': stats.last_step_seconds,
                                        'real_time_factor': stats.last_real_time_factor})
        self._stats.window_publish_seconds += time.perf_counter() - started
        self._stats.window_publishes += 1

    def _read(self, publisher) -> bool:
        """Whether a message on ``publisher``'s topic reaches anyone: a reader matched to it,
        or the bag. The outputs are volatile, so a message published with no reader matched
        is lost anyway: it is not built (the demo's 65² sheet without RViz: the markers, the
        cloud and the camera's images and organised cloud)."""
        if self._bag is not None or publisher.get_subscription_count() > 0:
            return True
        self._stats.unread_outputs += 1
        return False

    def _sheet_is_finite(self) -> bool:
        """False, counted and logged, if the sheet holds a NaN or infinity: never published."""
        if np.isfinite(self.simulator.sheet.positions).all():
            return True
        self._stats.nonfinite_skipped += 1
        self.get_logger().error('non-finite sheet state: frame not published',
                                throttle_duration_sec=WARN_EVERY)
        return False

    def _publish_cameras(self) -> np.ndarray | None:
        """The virtual cameras whose slot has come at this frame; the vertex colours they
        were rendered with, if any (the frame's other outputs use them too)."""
        sim_time = self.simulator.time
        due_cameras = [index for index, (camera, schedule)
                       in enumerate(zip(self._settings.cameras, self._camera_schedules))
                       if schedule.take(sim_time, camera.rate)]
        # rendered for the recording or for the topics someone reads (_read)
        read = {index: tuple(self._read(publisher) for publisher in self._camera_pubs[index])
                for index in due_cameras}
        due_cameras = [index for index in due_cameras
                       if self._recorder is not None or any(read[index])]
        if not due_cameras:
            return None
        started = time.perf_counter()
        if not self._sheet_is_finite():
            return None
        stamp = self._stamp()
        colors = self._vertex_colors()
        for index in due_cameras:
            self._publish_camera(index, stamp, colors, read[index])
        self._stats.window_publish_seconds += time.perf_counter() - started
        return colors

    def _vertex_colors(self) -> np.ndarray:
        return self._at_rest('colors', lambda: self._appearance.vertex_colors(
            self.simulator.sheet))

    def _at_rest(self, key, compute, inputs=()):
        """``compute()``, kept under ``key`` while the sheet sleeps in one rest (its state
        stands: Simulator.rest_id) and ``inputs`` stay equal (only the latest is kept, so a
        probe moving about a sleeping sheet does not pile up images); computed afresh while
        it is awake."""
        rest_id = self.simulator.rest_id
        if rest_id is None:
            self._rest_outputs.clear()
            return compute()
        if self._rest_outputs.get('rest_id') != rest_id:
            self._rest_outputs = {'rest_id': rest_id}
        kept = self._rest_outputs.get(key)
        if kept is None or kept[0] != inputs:
            kept = self._rest_outputs[key] = (inputs, compute())
        return kept[1]

    def _publish_camera(self, index: int, stamp: TimeMessage, colors: np.ndarray,
                        read: tuple[bool, bool, bool, bool]) -> None:
        """What the ``index``-th virtual camera sees, its four messages under one header in
        its optical frame (those of its topics that are ``read``)."""
        settings = self._settings
        camera = settings.cameras[index]
        config = camera.config
        rng = np.random.default_rng([settings.noise_seed, self.simulator.frame, 1, index])
        probes = self.simulator.probes
        # the image of a sleeping sheet stands while the camera and the probes do
        seen = (config, probes.end.tobytes(), probes.radius.tobytes(), probes.active.tobytes())
        image = self._at_rest(('camera', index),
                              lambda: render_simulator(config, self.simulator, colors), seen)
        frame = with_depth_noise(image, camera.depth_noise_stddev, rng)
        header = Header(frame_id=config.optical_frame, stamp=stamp)
        if self._bag is not None and config.name not in self._cameras_on_tf_static:
            self._bag.write_camera_transform(settings.frame_id, config,
                                             Time.from_msg(header.stamp).nanoseconds)
            self._cameras_on_tf_static.add(config.name)
        for publisher, message in zip(self._camera_pubs[index],
                                      camera_messages(header, config, frame, read)):
            if message is not None:
                self._send(publisher, message, header.stamp)
        if self._recorder is not None:
            self._recorder.log_camera(self._recording_time(), self.simulator, config, frame)

    def _cloud_points(self, sheet: Sheet, normals: np.ndarray, labels: np.ndarray):
        settings = self._settings
        rng = np.random.default_rng([settings.noise_seed, self.simulator.frame])
        if settings.dense_samples > 0:
            return dense_surface_points(sheet.positions, normals, labels, sheet.material,
                                        sheet.triangles,
                                        settings.dense_samples, settings.noise_stddev, rng)
        positions = sheet.positions
        if settings.noise_stddev > 0:
            positions = positions + rng.normal(0.0, settings.noise_stddev, positions.shape)
        return sheet_points(positions, normals, labels, sheet.material)

    # -------------------------------------------------------------------------- services
    def _on_reset(self, request, response):
        # a published clock goes on from where it was (time never runs back); a followed
        # one sets the origin again at the next tick
        origin = self._simulated_ns() if self._clock_pub is not None else None
        self.simulator.reset()
        self._apply_pins()
        self._origin_ns = origin
        self._wall_origin_ns = None
        for probe in self._probes:
            probe.track.forget_placement()
        self._points_schedule = Schedule(dropped=self._points_schedule.dropped)
        self._markers_schedule = Schedule(dropped=self._markers_schedule.dropped)
        self._camera_schedules = [Schedule(dropped=schedule.dropped)
                                  for schedule in self._camera_schedules]
        self._delete_all_pending = True
        self._crumple_calls = 0
        self._stats.resets += 1
        response.success = True
        response.message = (f'reset to the initial sheet ({self.simulator.sheet.vertex_count} '
                            'vertices)')
        self.get_logger().info(response.message)
        return response

    def _on_crumple(self, request, response):
        count = self._settings.crumple_count
        seed = self._settings.crumple_seed + self._crumple_calls
        try:
            self.simulator.crumple(count, seed)
        except ValueError as error:
            response.success = False
            response.message = f'crumple refused: {error}'
            self.get_logger().warn(response.message)
            return response
        self._crumple_calls += 1
        sheet = self.simulator.sheet
        response.success = True
        response.message = (f'crumpled: {count} events, seed {seed}; now '
                            f'{self.simulator.breaks} breaks, {self.simulator.folds} folds, '
                            f'{sheet.vertex_count} vertices')
        self.get_logger().info(response.message)
        return response

    # ----------------------------------------------------------------------- diagnostics
    def counters(self) -> dict[str, int]:
        """Totals since start: frames stepped and slipped, publications dropped, outputs not
        built for want of a reader, poses."""
        stats = self._stats
        return {
            'frames_stepped': stats.frames_stepped,
            'slipped_frames': stats.slipped_frames,
            'dropped_frames': self._points_schedule.dropped + self._markers_schedule.dropped,
            'dropped_points': self._points_schedule.dropped,
            'dropped_markers': self._markers_schedule.dropped,
            'poses_received': stats.poses_received,
            'poses_refused': stats.poses_refused,
            'unread_outputs': stats.unread_outputs,
            'resets': stats.resets,
            'tick_errors': stats.tick_errors,
        }

    def strain_summary(self) -> tuple[float, float]:
        """Largest HINGE strain over the last second of frames, and since start."""
        stats = self._stats
        return max(stats.recent_strains, default=0.0), stats.max_strain

    def _on_diagnostics(self) -> None:
        stats = self._stats
        simulator = self.simulator
        sheet = simulator.sheet
        wall = time.monotonic()
        elapsed = max(wall - stats.window_started, 1e-9)
        dt = simulator.config.solver.dt
        real_time_factor = stats.window_frames * dt / elapsed
        stats.last_real_time_factor = real_time_factor
        dropped = self._points_schedule.dropped + self._markers_schedule.dropped
        kind = sheet.spring_kind
        step_mean = stats.window_step_seconds / stats.window_steps if stats.window_steps else 0.0
        publish_mean = (stats.window_publish_seconds / stats.window_publishes
                        if stats.window_publishes else 0.0)
        window_dropped = dropped - stats.window_dropped
        level = DiagnosticStatus.OK
        problems = []
        if stats.window_slipped:
            problems.append(f'behind real time by {stats.window_slipped} frames')
        if window_dropped:
            problems.append(f'{window_dropped} publications dropped')
        if stats.window_refused:
            problems.append(f'{stats.window_refused} probe poses refused')
        if simulator.nan_seen or stats.nonfinite_skipped:
            problems.append('non-finite state was rolled back')
        strain_warning = self._settings.strain_warning
        if strain_warning > 0 and stats.window_max_strain > strain_warning:
            # paper stretches well under 1 %: beyond this the sheet is no longer paper
            # (fingertips pushing it together on the table: docs/contact.md)
            problems.append(f'sheet strained {stats.window_max_strain:.1%} '
                            f'(beyond strain_warning {strain_warning:.1%})')
        if problems:
            level = DiagnosticStatus.WARN
        if stats.tick_errors:
            level = DiagnosticStatus.ERROR
            problems.append(f'{stats.tick_errors} failed ticks (see log)')
        message = '; '.join(problems) if problems else 'running'
        values = {
            'sim_time': simulator.time,
            'frame': simulator.frame,
            'step_time_ms': 1e3 * step_mean,
            'step_time_max_ms': 1e3 * stats.window_step_max,
            'publish_time_ms': 1e3 * publish_mean,
            'real_time_factor': real_time_factor,
            'vertices': sheet.vertex_count,
            'triangles': int(sheet.triangles.shape[0]),
            'springs': sheet.spring_count,
            'hinge_springs': int(np.count_nonzero(kind == HINGE)),
            'bend_springs': int(np.count_nonzero(kind == BEND)),
            'aux_springs': int(np.count_nonzero(kind == AUX)),
            'breaks': int(simulator.breaks),
            'folds': int(simulator.folds),
            'max_strain': stats.window_max_strain,
            'max_strain_run': stats.max_strain,
            **self.counters(),
            'active_probes': int(np.count_nonzero(simulator.probes.active)),
            'pinned_vertices': int(np.count_nonzero(sheet.pinned)),
            'nan_rolled_back': bool(simulator.nan_seen),
            'asleep': bool(simulator.asleep),
            'recording': self._recorder.path if self._recorder is not None else '',
        }
        status = diagnostic_status(DIAGNOSTIC_NAME, self.get_fully_qualified_name(), level,
                                   message, values)
        now = self._now().to_msg()  # with publish_clock, the simulated time as everywhere
        self._send(self._diagnostics_pub, diagnostic_array(now, [status]), now)
        stats.window_started = wall
        stats.window_frames = stats.window_steps = stats.window_publishes = 0
        stats.window_step_seconds = stats.window_step_max = stats.window_publish_seconds = 0.0
        stats.window_slipped = stats.window_refused = 0
        stats.window_max_strain = 0.0
        stats.window_dropped = dropped

    # -------------------------------------------------------------------------- shutdown
    def _send(self, publisher, message, stamp) -> None:
        """Publish, and record in the bag at ``stamp`` (the message's header stamp). The
        markers come serialised already (bytes): recorded as MarkerArray."""
        publisher.publish(message)
        if self._bag is not None:
            self._bag.write(publisher.topic_name, message, Time.from_msg(stamp).nanoseconds,
                            message_type_name(publisher.msg_type))

    def destroy_node(self) -> None:
        """Close the Rerun recording and the bag (so both are complete), then the node."""
        if self._recorder is not None:
            recorder, self._recorder = self._recorder, None
            recorder.close()
        if self._bag is not None:
            bag, self._bag = self._bag, None
            bag.close()
        super().destroy_node()


def main(args=None) -> int:
    return run_node(PaperSimNode, args, NODE_NAME, (StartupError, ParameterException))


if __name__ == '__main__':
    sys.exit(main())
