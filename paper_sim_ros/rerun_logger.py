"""Record a simulation session to Rerun (SPEC §8): one explicit recording stream per session.

Entity hierarchy (everything under ``/paper``):

    paper/info                 static: the recording info (scenario, every parameter, seed) as
                               JSON (``recording_info_json``, ``parameters_json``) and as a
                               readable TextDocument
    paper/mesh                 Mesh3D: positions + normals every frame; triangle indices and
                               texture coordinates only on frames where the mesh changed (damage);
                               the paper texture once, static
    paper/springs/hinge        LineStrips3D of HINGE springs (every ``hinge_every`` frames)
    paper/springs/aux          LineStrips3D of AUX springs (damage memory), every frame
    paper/probes               Points3D of the active probes, with their radii
    paper/inputs/probes        the probe inputs of each frame, exactly (float64 centres, radii,
                               active flags) — what ``rerun_replay`` drives a new run with
    paper/metrics/<name>       Scalars: step_time, real_time_factor, energy, max_strain, breaks,
                               folds, vertices (and any other scalar the caller passes)

Timelines: ``sim_time`` (duration, seconds of simulated time) and ``frame`` (the simulator's
frame counter). Imports go one way: this module reads the core, the core never imports rerun.

rerun-sdk is imported only by a recorder that records (``import_rerun``): it has no rosdep
key, so a ROS installation may lack it, and the node must still run with recording off.
"""
from __future__ import annotations

import array
import atexit
import contextlib
import dataclasses
import datetime
import functools
import json
import logging
import math
import os
import signal
import socket
import sys
import threading
import urllib.parse
import uuid
import weakref
from typing import Any

import numpy as np

from .core.appearance import AppearanceConfig, PaperAppearance
from .core.camera import intrinsics
from .core.sheet import AUX, HINGE
from .core.topology import spring_end_points, vertex_normals

ENTITY_INFO = 'paper/info'
ENTITY_MESH = 'paper/mesh'
ENTITY_SPRINGS = {HINGE: 'paper/springs/hinge', AUX: 'paper/springs/aux'}
ENTITY_PROBES = 'paper/probes'
ENTITY_PROBE_INPUTS = 'paper/inputs/probes'
ENTITY_METRICS = 'paper/metrics'
ENTITY_CAMERAS = 'paper/cameras'
TIMELINE = 'sim_time'
FRAME_TIMELINE = 'frame'
INFO_COMPONENT = 'recording_info_json'
PARAMETERS_COMPONENT = 'parameters_json'
SPRING_COLORS = {HINGE: (120, 140, 175), AUX: (220, 40, 40)}
PROBE_COLOR = (40, 160, 255)
RERUN_REQUIREMENT = 'rerun-sdk==0.41.*'
"""The Rerun SDK this package records with (setup.py declares the same)."""
ALLOCATOR_PURGE_DELAY = 'MIMALLOC_PURGE_DELAY'
"""The environment variable of the delay [ms] before the Rerun SDK's allocator returns
freed memory to the system (``import_rerun``)."""


def import_rerun():
    """The ``rerun`` module, or a ``RuntimeError`` saying how to install it.

    The SDK's allocator (mimalloc, inside its library) returns what its writer thread
    frees to the system only when that thread allocates again, and between two frames it
    waits: a recording's memory grew with what it had written (the demo at 65², 300 s:
    329 MB after start, 467 MB at the end; 13 MB a minute). Freed at once, it stays flat
    (372-377 MB over 240 s). mimalloc reads the setting when the library loads; a value
    the user set stands."""
    os.environ.setdefault(ALLOCATOR_PURGE_DELAY, '0')
    try:
        import rerun
    except ModuleNotFoundError as error:
        if error.name not in ('rerun', 'rerun_bindings', 'pyarrow'):
            raise
        raise RuntimeError(f'recording to Rerun needs the Rerun SDK, which is not installed '
                           f"({error}): pip install '{RERUN_REQUIREMENT}'") from None
    return rerun


def jsonable(value: Any) -> Any:
    """Plain JSON types for dataclasses, numpy scalars/arrays, tuples, ``array.array`` (rclpy's
    array parameters) and paths; non-finite floats as their repr."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return jsonable(dataclasses.asdict(value))
    if isinstance(value, dict):
        return {str(key): jsonable(item) for key, item in value.items()}
    if isinstance(value, (list, tuple, array.array)):
        return [jsonable(item) for item in value]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return repr(value)
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    return str(value)


def check_writable_rrd(path: str | os.PathLike) -> str:
    """Absolute path of a ``.rrd`` file that can be created here, or a clear error.

    Raises ``ValueError`` for a path that is not an ``.rrd`` file name or is a directory, and
    ``OSError`` (naming the path and the reason) when the file cannot be created. The file is
    created (truncated) by the check itself, so nothing else can fail later at start-up.
    """
    text = os.fspath(path)
    if not text:
        raise ValueError('Rerun recording path is empty')
    absolute = os.path.abspath(os.path.expanduser(text))
    if os.path.isdir(absolute):
        raise ValueError(f'Rerun recording path {absolute} is a directory, not an .rrd file')
    if not absolute.endswith('.rrd'):
        raise ValueError(f'Rerun recording path {absolute} must end in .rrd')
    directory = os.path.dirname(absolute)
    if not os.path.isdir(directory):
        raise FileNotFoundError(2, f'cannot write Rerun recording {absolute}: '
                                   f'directory {directory} does not exist', absolute)
    try:
        with open(absolute, 'wb'):
            pass
    except OSError as error:
        raise OSError(error.errno, f'cannot write Rerun recording {absolute}: '
                                   f'{error.strerror}', absolute) from error
    return absolute


def check_reachable(url: str, timeout: float = 3.0) -> None:
    """A Rerun gRPC URL (``rerun+http://host:port/proxy``) with a server listening, or a clear
    error: ``ValueError`` for a malformed URL, ``ConnectionError`` when nothing answers (the
    SDK would otherwise buffer the whole session and give up only at the end)."""
    parsed = urllib.parse.urlparse(url)
    if parsed.scheme not in ('rerun', 'rerun+http', 'rerun+https') or not parsed.hostname:
        raise ValueError(f'rerun_connect must be a Rerun gRPC URL such as '
                         f'rerun+http://127.0.0.1:9876/proxy, got {url!r}')
    port = parsed.port or (443 if parsed.scheme == 'rerun+https' else 9876)
    try:
        with socket.create_connection((parsed.hostname, port), timeout=timeout):
            pass
    except OSError as error:
        raise ConnectionError(f'no Rerun viewer or server at {url} ({error}); start one with '
                              f'`rerun` (it listens on port 9876) or record to a file') from None


def _segments(points: np.ndarray, strip_type):
    """Segments given by their ``points`` (2 S, 3) float32, two by two, as S two-point line
    strips, built as one arrow array over ``points``' memory (the SDK's own conversion loops
    over the strips in Python: ~15x slower at 65x65)."""
    import pyarrow as pa  # installed with rerun-sdk (see import_rerun)

    inner = pa.FixedSizeListArray.from_arrays(pa.array(points.reshape(-1)),
                                              type=strip_type.value_type)
    offsets = pa.array(np.arange(0, points.shape[0] + 1, 2, dtype=np.int32))
    return pa.ListArray.from_arrays(offsets, inner, type=strip_type)


def _blob(image: np.ndarray, buffer_type):
    """``image``'s bytes as a Rerun blob, an arrow array over its own memory: the SDK's
    ``Image`` and ``DepthImage`` copy an image twice on the way (0.3 → 1.3 ms at 640 × 480
    once arrow's allocator returns freed memory at once, as import_rerun has it)."""
    import pyarrow as pa  # installed with rerun-sdk (see import_rerun)

    data = np.ascontiguousarray(image).reshape(-1).view(np.uint8)
    return pa.ListArray.from_arrays(pa.array(np.array([0, data.size], dtype=np.int32)),
                                    pa.array(data), type=buffer_type)


def view_bounds(simulator) -> tuple[np.ndarray, np.ndarray]:
    """Corners (low, high) [m] of the box the 3-D view frames: the sheet as it starts, and,
    if it is pinned, as far below its pins as it is long (a pinned sheet swings down and
    hangs there), but not below the table."""
    positions = simulator.sheet.positions
    low, high = positions.min(axis=0), positions.max(axis=0)
    pinned = simulator.sheet.pinned
    if np.any(pinned):
        low[2] = min(low[2], positions[pinned, 2].min() - float(np.max(high - low)))
    contact = simulator.config.contact
    if contact.ground_enabled:
        low[2] = max(low[2], min(contact.ground_height, high[2]))
    return low, high


def default_blueprint(center: np.ndarray | None = None, size: float | None = None,
                      cameras: tuple[str, ...] = ()):
    """A 3D view of the sheet beside the metric plots and the session info. With the sheet's
    ``center`` and ``size`` [m], the camera looks at it obliquely from the front, low side,
    from far enough (1.7 times its size) that it stays in view as it moves.
    Each virtual camera of ``cameras`` (names) gets a 2-D view of what it saw."""
    import rerun.blueprint as rrb

    def plot(name: str, *entities: str):
        return rrb.TimeSeriesView(name=name, origin=f'/{ENTITY_METRICS}',
                                  contents=[f'/{ENTITY_METRICS}/{e}' for e in entities])

    eye = None
    if center is not None and size:
        eye = rrb.EyeControls3D(position=tuple(np.asarray(center) + 1.5 * size * np.array(
            [0.45, -0.85, 0.62])), look_target=tuple(center), eye_up=(0.0, 0.0, 1.0))
    view_3d = rrb.Spatial3DView(
        name='sheet', origin='/paper',
        # cameras as frusta; their depth images, projected into 3-D, would bury the sheet
        contents=['+ /paper/mesh', '+ /paper/springs/**', '+ /paper/probes',
                  f'+ /{ENTITY_CAMERAS}/**'] + [f'- /{ENTITY_CAMERAS}/{name}/depth'
                                                for name in cameras],
        eye_controls=eye)
    plots = rrb.Grid(
        plot('step time [s]', 'step_time'),
        plot('real-time factor', 'real_time_factor'),
        plot('energy [J]', 'energy'),
        plot('max strain', 'max_strain'),
        plot('breaks, folds', 'breaks', 'folds'),
        plot('vertices', 'vertices'),
        grid_columns=2)
    info = rrb.TextDocumentView(name='session', origin=f'/{ENTITY_INFO}')
    # what each camera saw, in colour (its depth is in the recording beside it)
    views = [rrb.Spatial2DView(name=name, origin=f'/{ENTITY_CAMERAS}/{name}',
                               contents=[f'+ /{ENTITY_CAMERAS}/{name}/rgb'])
             for name in cameras]
    right = rrb.Vertical(plots, *views, info, row_shares=[3] + [2] * len(views) + [1])
    return rrb.Blueprint(
        rrb.Horizontal(view_3d, right, column_shares=[3, 2]),
        rrb.BlueprintPanel(state='collapsed'),
        rrb.SelectionPanel(state='collapsed'),
        rrb.TimePanel(timeline=TIMELINE))


def _info_markdown(info: dict, text: str) -> str:
    """The recording info for people: what ran, then every parameter as JSON."""
    scenario = info.get('scenario') if isinstance(info.get('scenario'), dict) else {}
    lines = []
    if scenario:
        lines.append(f"**scenario** `{scenario.get('name', '?')}`, "
                     f"seed {scenario.get('seed', 0)}: {scenario.get('description', '')}")
    if 'node' in info:
        lines.append(f"**node** `{info['node']}`")
    if 'replay_of' in info:
        lines.append(f"**replay of** `{info['replay_of']}`")
    lines.append(f'```json\n{text}\n```')
    return '\n\n'.join(lines)


class RerunRecorder:
    """Logs every frame of a simulator to one Rerun recording (file, viewer, or nothing).

    ``path``: save to this ``.rrd`` file (checked writable here, before anything starts);
    ``connect_url``: stream to a running viewer (``rerun+http://host:9876/proxy``); both: both;
    neither: a cheap no-op recorder (``enabled`` is False).

    ``hinge_every``: log the HINGE springs every n-th frame only (they are the mesh edges, the
    heaviest per-frame data); AUX springs, the mesh, probes and metrics go out every frame.
    ``appearance``: the paper texture (``core.appearance``) mapped on the mesh of frames logged
    without ``vertex_colors``; None: ``AppearanceConfig()``.

    Recording needs rerun-sdk: without it a recorder that is asked to record raises
    ``RuntimeError`` naming the package to install (``import_rerun``).
    """

    def __init__(self, application_id: str, path: str | None = None,
                 connect_url: str | None = None, recording_info: dict | None = None,
                 *, hinge_every: int = 1, appearance: AppearanceConfig | None = None,
                 cameras: tuple[str, ...] = ()) -> None:
        if not isinstance(hinge_every, int) or hinge_every < 0:
            raise ValueError(f'hinge_every must be an integer >= 0 (0: never), '
                             f'got {hinge_every!r}')
        rr = import_rerun() if path or connect_url else None  # before creating the file
        self.path = check_writable_rrd(path) if path else None
        self.connect_url = connect_url or None
        self.hinge_every = hinge_every
        self._cameras = tuple(cameras)
        self._appearance_config = appearance if appearance is not None else AppearanceConfig()
        self._lock = threading.RLock()
        self._stream = None
        self._closed = False
        self._frames_logged = 0
        self._triangles: np.ndarray | None = None
        self._appearance: PaperAppearance | None = None
        self._texture_logged = False
        self._aux_logged = False
        self._parameters_logged = False
        self.close_error: str | None = None
        """Why ``close`` could not deliver everything (a viewer that went away), else None."""
        self.recording_info = jsonable(recording_info or {})
        if rr is None:
            return
        if self.connect_url is not None:
            check_reachable(self.connect_url)
        stream = rr.RecordingStream(application_id, recording_id=uuid.uuid4(),
                                    send_properties=True)
        if not rr.is_enabled(stream):
            raise RuntimeError('Rerun logging is disabled in this environment (RERUN=off); '
                               'unset it or turn recording off explicitly')
        sinks = []
        if self.path is not None:
            sinks.append(rr.FileSink(self.path))
        if self.connect_url is not None:
            try:
                sinks.append(rr.GrpcSink(self.connect_url))
            except Exception as error:  # the bindings raise their own types for a bad URL
                raise ValueError(f'bad rerun_connect URL {self.connect_url!r}: {error}') from None
        # the blueprint goes out with the first frame, when the sheet's size is known
        rr.set_sinks(*sinks, recording=stream)
        self._stream = stream
        self._rr = rr
        self._strip_type = rr.components.LineStrip3D.arrow_type()
        self._buffer_type = rr.components.ImageBuffer.arrow_type()
        info = dict(self.recording_info)
        info.setdefault('recorder', {
            'application_id': application_id,
            'rerun_sdk': rr.__version__,
            'created_utc': datetime.datetime.now(datetime.timezone.utc).isoformat(),
        })
        self.recording_info = info
        text = json.dumps(info, indent=1, sort_keys=True)
        stream.log(ENTITY_INFO, rr.AnyValues(**{INFO_COMPONENT: text}), static=True)
        stream.log(ENTITY_INFO, rr.TextDocument(_info_markdown(info, text),
                                                media_type=rr.MediaType.MARKDOWN), static=True)
        # what never changes: colours and widths of the springs and probes
        for kind, entity in ENTITY_SPRINGS.items():
            stream.log(entity, rr.LineStrips3D.from_fields(
                colors=SPRING_COLORS[kind],
                radii=rr.Radius.ui_points(0.5 if kind == HINGE else 2.5)), static=True)
        stream.log(ENTITY_PROBES, rr.Points3D.from_fields(colors=PROBE_COLOR), static=True)
        for name in ('breaks', 'folds'):
            stream.log(f'{ENTITY_METRICS}/{name}', rr.SeriesLines(names=name), static=True)
        # closed at interpreter exit too (e.g. SIGINT in a script that forgot to close)
        self._atexit_hook = functools.partial(_close_at_exit, weakref.WeakMethod(self.close))
        atexit.register(self._atexit_hook)

    # ------------------------------------------------------------------------------ state
    @property
    def enabled(self) -> bool:
        """True while this recorder writes somewhere."""
        return self._stream is not None and not self._closed

    # ---------------------------------------------------------------------------- logging
    def log_frame(self, sim_time: float, simulator, vertex_colors: np.ndarray | None = None,
                  scalars: dict[str, float] | None = None) -> None:
        """Log the simulator's current frame at ``sim_time`` [s] on the ``sim_time`` timeline.

        ``vertex_colors``: (V, 3) or (V, 4) uint8 shaded colours from the caller (they replace
        the texture); ``scalars``: metrics by name, logged under ``paper/metrics/<name>``
        (energy, max_strain, breaks, folds and vertices are taken from the simulator when
        absent).
        """
        with self._logging_at(sim_time, simulator) as stream:
            if stream is None:
                return
            rr = self._rr
            sheet = simulator.sheet
            if not self._parameters_logged:
                self._log_parameters(simulator)
                low, high = view_bounds(simulator)
                stream.send_blueprint(default_blueprint(
                    0.5 * (low + high), float(max(np.max(high - low), 0.05)), self._cameras))
            self._log_mesh(sheet, vertex_colors)
            self._log_springs(sheet)
            probes = simulator.probes
            active = np.asarray(probes.active, dtype=bool)
            stream.log(ENTITY_PROBES, rr.Points3D.from_fields(
                positions=np.asarray(probes.end, dtype=np.float32)[active].reshape(-1, 3),
                radii=np.asarray(probes.radius, dtype=np.float32)[active]))
            self._log_probe_inputs(probes)
            self._log_scalars(simulator, scalars or {})
            self._frames_logged += 1

    def log_camera(self, sim_time: float, simulator, config, frame) -> None:
        """What a virtual camera (``core.camera.CameraConfig``) saw at ``sim_time``: its pose
        and pinhole under ``paper/cameras/<name>`` (so the 3-D view shows its frustum), its
        depth [m] and colour images."""
        with self._logging_at(sim_time, simulator) as stream:
            if stream is None:
                return
            rr = self._rr
            entity = f'{ENTITY_CAMERAS}/{config.name}'
            stream.log(entity, rr.Transform3D(translation=config.position,
                                              quaternion=config.orientation))
            stream.log(entity, rr.Pinhole(image_from_camera=intrinsics(config),
                                          resolution=[config.width, config.height],
                                          camera_xyz=rr.ViewCoordinates.RDF))
            height, width = frame.depth.shape
            image_format = rr.components.ImageFormat
            stream.log(f'{entity}/depth', rr.DepthImage.from_fields(
                buffer=_blob(frame.depth, self._buffer_type), meter=1.0,
                format=image_format(width=width, height=height, channel_datatype='F32')))
            stream.log(f'{entity}/rgb', rr.Image.from_fields(
                buffer=_blob(frame.rgb, self._buffer_type),
                format=image_format(width=width, height=height, color_model='RGB',
                                    channel_datatype='U8')))

    def log_inputs(self, sim_time: float, simulator) -> None:
        """Log only the probe inputs of a frame (for a caller that steps frames it does not
        publish: the replay then still has every frame's input)."""
        if not self.enabled:
            return
        with self._lock:
            if self.enabled:
                self._set_time(sim_time, simulator)
                self._log_probe_inputs(simulator.probes)

    @contextlib.contextmanager
    def _logging_at(self, sim_time: float, simulator):
        """The stream, its clock at ``sim_time``, held for one frame's logging with signals
        deferred (so a frame is whole in the file); None once closed."""
        if not self.enabled:
            yield None
            return
        with self._lock, _signals_deferred():
            if not self.enabled:
                yield None
                return
            self._set_time(sim_time, simulator)
            yield self._stream

    def _set_time(self, sim_time: float, simulator) -> None:
        self._stream.set_time(TIMELINE, duration=float(sim_time))
        self._stream.set_time(FRAME_TIMELINE, sequence=int(simulator.frame))

    def _log_parameters(self, simulator) -> None:
        rr = self._rr
        # the sheet the run started from (the simulator's reset state), not this frame's
        initial = simulator.initial_sheet
        parameters = {
            'config': jsonable(simulator.config),
            'initial_vertex_count': int(initial.vertex_count),
            'pinned_vertices': np.flatnonzero(initial.pinned).tolist(),
            'initial_positions_sha256': initial.positions_sha256(),
        }
        text = json.dumps(parameters, sort_keys=True)
        self._stream.log(ENTITY_INFO, rr.AnyValues(**{PARAMETERS_COMPONENT: text}), static=True)
        self._parameters_logged = True

    def _log_mesh(self, sheet, vertex_colors: np.ndarray | None) -> None:
        rr = self._rr
        positions = sheet.positions
        triangles = sheet.triangles
        normals = vertex_normals(positions, triangles).astype(np.float32)
        changed = self._triangles is None or self._triangles.shape != triangles.shape \
            or not np.array_equal(self._triangles, triangles)
        fields: dict[str, Any] = {
            'vertex_positions': positions.astype(np.float32),
            'vertex_normals': normals,
        }
        appearance = None
        if vertex_colors is not None:
            fields['vertex_colors'] = np.asarray(vertex_colors, dtype=np.uint8)
        else:
            if self._appearance is None:
                self._appearance = PaperAppearance(self._appearance_config, sheet)
            appearance = self._appearance
        if changed:
            fields['triangle_indices'] = triangles.astype(np.uint32)
            if appearance is not None:
                fields['vertex_texcoords'] = sheet.texture_coordinates()
            self._triangles = triangles.copy()
        if appearance is not None and not self._texture_logged:
            # static, and only the texture components: a static position would hide the
            # per-frame ones
            image = np.ascontiguousarray(appearance.texture_image, dtype=np.uint8)
            self._stream.log(ENTITY_MESH, rr.Mesh3D.from_fields(
                albedo_texture_buffer=image.tobytes(),
                albedo_texture_format=rr.components.ImageFormat(
                    width=image.shape[1], height=image.shape[0],
                    color_model='RGB' if image.shape[2] == 3 else 'RGBA',
                    channel_datatype='U8')), static=True)
            self._texture_logged = True
        self._stream.log(ENTITY_MESH, rr.Mesh3D.from_fields(**fields))

    def _log_springs(self, sheet) -> None:
        rr = self._rr
        kinds = [AUX]
        if self.hinge_every and self._frames_logged % self.hinge_every == 0:
            kinds.insert(0, HINGE)
        for kind in kinds:
            points = spring_end_points(sheet.positions, sheet.spring_vertices,
                                       sheet.spring_kind, kind)
            if kind == AUX:
                if points.shape[0] == 0 and not self._aux_logged:
                    continue  # no damage yet and nothing shown before: keep frames lean
                self._aux_logged = True
            self._stream.log(ENTITY_SPRINGS[kind], rr.LineStrips3D.from_fields(
                strips=_segments(points, self._strip_type)))

    def _log_probe_inputs(self, probes) -> None:
        # explicit arrow arrays: they keep their type when empty (no probes), so every frame
        # has its row of inputs; float64, so a replay gets exactly what the simulator got
        import pyarrow as pa

        self._stream.log(ENTITY_PROBE_INPUTS, self._rr.AnyValues(
            centers=pa.array(np.asarray(probes.end, dtype=np.float64).reshape(-1)),
            radii=pa.array(np.asarray(probes.radius, dtype=np.float64).reshape(-1)),
            active=pa.array(np.asarray(probes.active, dtype=bool).reshape(-1), type=pa.bool_())))

    def _log_scalars(self, simulator, scalars: dict[str, float]) -> None:
        rr = self._rr
        values = dict(scalars)
        if 'energy' not in values:
            values['energy'] = simulator.energy()
        if 'max_strain' not in values:
            values['max_strain'] = simulator.max_strain()
        values.setdefault('breaks', simulator.breaks)
        values.setdefault('folds', simulator.folds)
        values.setdefault('vertices', simulator.sheet.vertex_count)
        for name, value in values.items():
            self._stream.log(f'{ENTITY_METRICS}/{name}', rr.Scalars(float(value)))

    # ---------------------------------------------------------------------------- closing
    def close(self) -> None:
        """Flush and finish the recording (the file gets its footer and is complete).
        Safe to call twice, and from a signal-driven shutdown path."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            stream, self._stream = self._stream, None
            if stream is None:
                return
            try:
                stream.flush(timeout_sec=30.0)
            except RuntimeError as error:  # a viewer that went away: the file is still finished
                self.close_error = str(error)
                logging.getLogger(__name__).warning(f'Rerun recording not fully sent: {error}')
            finally:
                stream.disconnect()
                atexit.unregister(self._atexit_hook)

    def __enter__(self) -> 'RerunRecorder':
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()


@contextlib.contextmanager
def _signals_deferred():
    """Hold a Python-level SIGINT/SIGTERM handler back while one frame is logged, so that a stop
    lands between frames and the recording ends on a whole frame (mesh, springs, probes, inputs
    and metrics). Blocking the signal would not do: the process-directed signal may be taken
    by another thread, and the main thread then runs the handler mid-frame anyway.

    Only in the main thread (where Python runs handlers), only over Python handlers, and never
    while rclpy's own C handlers are installed (Python cannot see or restore those; under rclpy
    a signal stops the executor between callbacks, so a frame is never cut there)."""
    if threading.current_thread() is not threading.main_thread() or _rclpy_handles_signals():
        yield
        return
    caught: list[tuple[int, Any]] = []
    previous = {}
    for number in (signal.SIGINT, signal.SIGTERM):
        handler = signal.getsignal(number)
        if callable(handler):
            previous[number] = handler
            signal.signal(number, lambda signum, frame: caught.append((signum, frame)))
    try:
        yield
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)
        if caught:
            number, frame = caught[0]
            previous[number](number, frame)


def _rclpy_handles_signals() -> bool:
    signals = sys.modules.get('rclpy.signals')  # not imported: rclpy is not in use
    if signals is None:
        return False
    return signals.get_current_signal_handlers_options() != signals.SignalHandlerOptions.NO


def _close_at_exit(method: weakref.WeakMethod) -> None:
    close = method()
    if close is not None:
        close()
