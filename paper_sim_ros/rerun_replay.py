"""Read a recorded session back with Rerun's own API, and re-run it (SPEC §8).

Reading goes through ``rerun.chunk.RrdReader(path).stream()``: it reads a finished recording
and also one whose writer died before writing the footer (``RrdReader.store()``, the lazy
manifest-based store, needs the footer; ``is_complete`` says whether it is there).

Re-running: the recording holds the scenario mapping (``recording_info['scenario']``), every
parameter of the simulation (``parameters_json``: the ``SimulationConfig``, the pinned
vertices, the hash of the initial sheet) and the exact probe inputs of every frame
(``paper/inputs/probes``, float64). ``replay(path)`` rebuilds the scenario, checks that the
rebuilt simulation has the recorded configuration and initial sheet, and steps it with the
recorded probe inputs in place of the scenario's keyframe tracks; with the same seed the final
positions hash equals the original run's (``final_positions_sha256`` in the metrics).

A session without a scenario (the node's) is rebuilt from its recorded ``SimulationConfig`` and
pinned vertices instead. Not replayable, and refused with the reason: a session that was reset
part-way (the frame counter restarts), and one whose initial sheet cannot be rebuilt from the
recorded parameters (checked by hash). Inputs that do not pass through the probes (a crumple
service call in the middle of a node session) are not recorded, so such a replay diverges.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
import json
from typing import Any, Callable

import numpy as np

from .core import Scenario, SimulationConfig, Simulator, build_simulator, run_scenario
from .core.scenarios import scenario_from_mapping
from .rerun_logger import (ENTITY_INFO, ENTITY_MESH, ENTITY_METRICS, ENTITY_PROBE_INPUTS,
                           FRAME_TIMELINE, INFO_COMPONENT, PARAMETERS_COMPONENT, TIMELINE,
                           RerunRecorder, jsonable)

POSITIONS = 'Mesh3D:vertex_positions'
TRIANGLES = 'Mesh3D:triangle_indices'
SCALARS = 'Scalars:scalars'


@dataclass(frozen=True)
class ProbeInput:
    """The probe inputs of one recorded frame: what ``Simulator.set_probes`` received."""

    frame: int
    sim_time: float
    centers: np.ndarray
    """(P, 3) float64 [m]."""
    radii: np.ndarray
    """(P,) float64 [m]."""
    active: np.ndarray
    """(P,) bool."""


@dataclass(frozen=True)
class MeshFrame:
    frame: int
    sim_time: float
    positions: np.ndarray
    """(V, 3) float32 [m] as logged."""
    triangle_count: int | None
    """Triangles logged on this frame (None: the topology did not change)."""


# ------------------------------------------------------------------------------ reading
def read_chunks(path: str) -> list:
    """Every chunk of the first recording store in ``path`` (footer or not)."""
    from rerun.chunk import RrdReader

    return RrdReader(path).stream().to_chunks()


def is_complete(path: str) -> bool:
    """True when the recording was finished properly (it has its footer/manifest, so the
    lazy ``RrdReader(path).store()`` opens it)."""
    from rerun.chunk import RrdReader

    try:
        RrdReader(path).store()
    except Exception:  # the bindings raise their own error type for a missing footer
        return False
    return True


def _entity(chunk) -> str:
    return chunk.entity_path.lstrip('/')


def _column(batch, name: str) -> list | None:
    return batch.column(name).to_pylist() if name in batch.schema.names else None


def _time_seconds(batch) -> list[float]:
    values = batch.column(TIMELINE).cast('int64').to_pylist()
    return [value / 1e9 for value in values]


def _rows(chunks: list, entity: str, components: tuple[str, ...]):
    """(frame, sim_time [s], values) of every temporal row of ``entity`` whose first component
    is set; ``values`` are the components' arrow scalars (None where a row lacks one)."""
    for chunk in chunks:
        if _entity(chunk) != entity or chunk.is_static:
            continue
        batch = chunk.to_record_batch()
        names = batch.schema.names
        if components[0] not in names or TIMELINE not in names:
            continue
        frames = batch.column(FRAME_TIMELINE).to_pylist() if FRAME_TIMELINE in names \
            else [0] * batch.num_rows
        times = _time_seconds(batch)
        columns = [batch.column(name) if name in names else None for name in components]
        for row in range(batch.num_rows):
            if not columns[0][row].is_valid:
                continue
            values = [column[row] if column is not None and column[row].is_valid else None
                      for column in columns]
            yield frames[row], times[row], values


def _numbers(scalar, dtype) -> np.ndarray:
    """An arrow list scalar (of numbers, or of fixed-size lists of numbers) as a flat array."""
    values = scalar.values
    if hasattr(values, 'flatten'):
        values = values.flatten()
    return values.to_numpy(zero_copy_only=False).astype(dtype, copy=False)


def _static_text(chunks: list, component: str) -> str | None:
    """The last logged value of a static text component of ``paper/info`` (static chunks may
    hold several rows, each with some of the components)."""
    found = None
    for chunk in chunks:
        if _entity(chunk) == ENTITY_INFO and chunk.is_static:
            for value in _column(chunk.to_record_batch(), component) or []:
                if value:
                    found = value[0]
    return found


def read_recording_info(path: str, chunks: list | None = None) -> dict:
    """The recording info logged at start (scenario, parameters, seed, recorder)."""
    text = _static_text(chunks if chunks is not None else read_chunks(path), INFO_COMPONENT)
    if text is None:
        raise ValueError(f'{path}: no {ENTITY_INFO}:{INFO_COMPONENT}; not a paper_sim_ros '
                         f'recording')
    return json.loads(text)


def read_parameters(path: str, chunks: list | None = None) -> dict:
    """The simulation parameters logged with the first frame: ``config`` (every field of the
    SimulationConfig), ``pinned_vertices``, ``initial_vertex_count``,
    ``initial_positions_sha256``."""
    text = _static_text(chunks if chunks is not None else read_chunks(path),
                        PARAMETERS_COMPONENT)
    if text is None:
        raise ValueError(f'{path}: no {ENTITY_INFO}:{PARAMETERS_COMPONENT}; no frame was '
                         f'recorded')
    return json.loads(text)


def read_probe_inputs(path: str, chunks: list | None = None,
                      check_resets: bool = True) -> list[ProbeInput]:
    """The probe inputs of every recorded frame, in sim_time order. Raises ``ValueError`` when
    the frame counter went back (the session was reset): such a session is several runs."""
    chunks = chunks if chunks is not None else read_chunks(path)
    inputs = [ProbeInput(frame=frame, sim_time=time,
                         centers=_numbers(centers, np.float64).reshape(-1, 3),
                         radii=_numbers(radii, np.float64), active=_numbers(active, bool))
              for frame, time, (centers, radii, active)
              in _rows(chunks, ENTITY_PROBE_INPUTS, ('centers', 'radii', 'active'))]
    inputs.sort(key=lambda item: (item.sim_time, item.frame))
    if check_resets:
        _refuse_resets(path, inputs)
    return inputs


def _refuse_resets(path: str, inputs: list[ProbeInput]) -> None:
    for before, after in zip(inputs, inputs[1:]):
        if after.frame <= before.frame:
            raise ValueError(f'{path}: the frame counter restarts at sim_time '
                             f'{after.sim_time:.3f} s (the session was reset there); a replay '
                             f'covers one run from its start')


def read_mesh_frames(path: str, chunks: list | None = None) -> list[MeshFrame]:
    """Every logged frame of ``paper/mesh`` (sim_time order) with its vertex positions."""
    chunks = chunks if chunks is not None else read_chunks(path)
    frames = [MeshFrame(frame=frame, sim_time=time,
                        positions=_numbers(positions, np.float32).reshape(-1, 3),
                        triangle_count=None if triangles is None else len(triangles))
              for frame, time, (positions, triangles)
              in _rows(chunks, ENTITY_MESH, (POSITIONS, TRIANGLES))]
    frames.sort(key=lambda mesh: (mesh.sim_time, mesh.frame))
    return frames


Series = tuple[np.ndarray, np.ndarray]


def read_scalars(path: str, chunks: list | None = None) -> dict[str, Series]:
    """Every scalar series under ``paper/metrics``: name -> (sim_time [s], values)."""
    chunks = chunks if chunks is not None else read_chunks(path)
    series: dict[str, list[tuple[float, float]]] = {}
    names = {_entity(chunk) for chunk in chunks if not chunk.is_static}
    for entity in sorted(names):
        if entity.startswith(ENTITY_METRICS + '/'):
            series[entity[len(ENTITY_METRICS) + 1:]] = [
                (time, value.values[0].as_py())
                for _, time, (value,) in _rows(chunks, entity, (SCALARS,)) if len(value)]
    result = {}
    for name, points in series.items():
        points.sort()
        result[name] = (np.array([p[0] for p in points]), np.array([p[1] for p in points]))
    return result


def summary(path: str) -> dict:
    """A compact description of a recording: what a test or a user checks first."""
    chunks = read_chunks(path)
    meshes = read_mesh_frames(path, chunks)
    inputs = read_probe_inputs(path, chunks, check_resets=False)
    return {
        'complete': is_complete(path),
        'recording_info': read_recording_info(path, chunks),
        'mesh_rows': len(meshes),
        'vertex_counts': sorted({mesh.positions.shape[0] for mesh in meshes}),
        'topology_rows': sum(mesh.triangle_count is not None for mesh in meshes),
        'first_frame': meshes[0].frame if meshes else None,
        'last_frame': meshes[-1].frame if meshes else None,
        'last_sim_time': meshes[-1].sim_time if meshes else None,
        'probe_input_rows': len(inputs),
        'scalars': sorted(read_scalars(path, chunks)),
    }


# ----------------------------------------------------------------------------- re-running
class RecordedScenario:
    """A scenario whose probe inputs are the recorded ones, frame by frame.

    Stands in for ``core.scenarios.Scenario`` in the headless runner: ``frame_count`` and
    ``probe_inputs(time)`` come from the recording, everything else from the scenario.
    ``time`` is the end of frame k = round(time / dt) (the runner's convention). A frame with
    no recorded input keeps the latest earlier one (Rerun's latest-at); ``exact`` is False then.
    """

    def __init__(self, scenario: Scenario, inputs: list[ProbeInput]) -> None:
        if not inputs:
            raise ValueError('the recording has no probe inputs: no frame was recorded')
        self.scenario = scenario
        self.name = f'{scenario.name} (replay)'
        self.duration = inputs[-1].frame * scenario.config.solver.dt
        self.frame_count = int(inputs[-1].frame)
        self._by_frame = {item.frame: item for item in inputs}
        frames = sorted(self._by_frame)
        self.exact = frames == list(range(1, self.frame_count + 1))
        self._frames = np.array(frames)

    def __getattr__(self, name: str):
        # everything else (config, pin, crumple, ...) is the recorded scenario's own
        if name == 'scenario':
            raise AttributeError(name)
        return getattr(self.scenario, name)

    def probe_inputs_at_frame(self, frame: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Centres, radii and active flags recorded for ``frame`` (1-based: the state after
        the k-th step), or the latest earlier recorded frame's."""
        item = self._by_frame.get(frame)
        if item is None:
            earlier = self._frames[self._frames <= frame]
            source = int(earlier[-1]) if earlier.size else int(self._frames[0])
            item = self._by_frame[source]
        return item.centers.copy(), item.radii.copy(), item.active.copy()

    def probe_inputs(self, time: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self.probe_inputs_at_frame(int(round(time / self.config.solver.dt)))


def config_from_dict(values: dict) -> SimulationConfig:
    """A ``SimulationConfig`` from ``dataclasses.asdict`` output (as recorded), every nested
    config dataclass included (lists back to tuples where the default is a tuple)."""
    def build(cls, mapping: dict):
        kwargs = {}
        for spec in dataclasses.fields(cls):
            if spec.name not in mapping:
                continue
            value = mapping[spec.name]
            default = spec.default_factory() if spec.default_factory is not dataclasses.MISSING \
                else spec.default
            if dataclasses.is_dataclass(default) and isinstance(value, dict):
                value = build(type(default), value)
            elif isinstance(default, tuple) and isinstance(value, list):
                value = tuple(value)
            kwargs[spec.name] = value
        unknown = sorted(set(mapping) - {spec.name for spec in dataclasses.fields(cls)})
        if unknown:
            raise ValueError(f'the recording has {cls.__name__} parameters this version does '
                             f'not know: {", ".join(unknown)}')
        return cls(**kwargs)

    return build(SimulationConfig, values)


def _differences(rebuilt: Any, recorded: Any, prefix: str = 'config') -> list[str]:
    """Readable differences between two JSON-like values, by dotted key."""
    if isinstance(rebuilt, dict) and isinstance(recorded, dict):
        found = []
        for key in sorted(set(rebuilt) | set(recorded)):
            if key not in recorded:
                found.append(f'{prefix}.{key} not recorded')
            elif key not in rebuilt:
                found.append(f'{prefix}.{key} unknown now')
            else:
                found += _differences(rebuilt[key], recorded[key], f'{prefix}.{key}')
        return found
    return [] if rebuilt == recorded else [f'{prefix}: {recorded!r} recorded, {rebuilt!r} now']


def _mapping_from_config(config: SimulationConfig) -> dict:
    """A scenario mapping holding exactly ``config`` (every config section, and the seed)."""
    mapping: dict[str, Any] = {'name': 'recorded session', 'seed': config.seed}
    for spec in dataclasses.fields(config):
        value = getattr(config, spec.name)
        if dataclasses.is_dataclass(value):
            mapping[spec.name] = dataclasses.asdict(value)
    return mapping


def recorded_scenario(path: str, chunks: list | None = None) -> RecordedScenario:
    """Rebuild the recorded scenario and check it against the recorded parameters."""
    chunks = chunks if chunks is not None else read_chunks(path)
    info = read_recording_info(path, chunks)
    parameters = read_parameters(path, chunks)
    mapping = info.get('scenario')
    if not isinstance(mapping, dict):
        # a session without a scenario (the node's): the scenario is its recorded parameters,
        # with no probe tracks of its own; the pins come from the recording (see replay)
        if 'config' not in parameters:
            raise ValueError(f'{path}: the recording has neither a scenario nor its '
                             f'parameters, so it cannot be re-run')
        mapping = _mapping_from_config(config_from_dict(parameters['config']))
    scenario = scenario_from_mapping(mapping)
    recorded = parameters.get('config')
    if recorded is not None:
        differences = _differences(jsonable(scenario.config), recorded)
        if differences:
            raise ValueError(f'{path}: the scenario rebuilt from the recording does not have '
                             f'the recorded parameters ({"; ".join(differences[:5])}): the code '
                             f'changed since it was recorded')
    return RecordedScenario(scenario, read_probe_inputs(path, chunks))


def replay(path: str, rrd: str | None = None,
           on_frame: Callable[[Simulator, float], None] | None = None) -> dict:
    """Re-run a recorded session with its recorded probe inputs; the headless metrics of the
    new run, plus ``replay_of`` (the recording), ``replay_frames`` and ``replay_exact``
    (every frame's input was recorded). ``rrd``: record the new run too."""
    chunks = read_chunks(path)
    scenario = recorded_scenario(path, chunks)
    parameters = read_parameters(path, chunks)
    simulator = build_simulator(scenario)
    pinned = parameters.get('pinned_vertices')
    if pinned is not None and 'scenario' not in read_recording_info(path, chunks):
        mask = np.zeros(simulator.sheet.vertex_count, dtype=bool)
        mask[np.asarray(pinned, dtype=np.int64)] = True
        simulator.set_pinned(mask)
    if pinned is not None and np.flatnonzero(simulator.sheet.pinned).tolist() != pinned:
        raise ValueError(f'{path}: the rebuilt sheet pins other vertices than the recording')
    initial = parameters.get('initial_positions_sha256')
    if initial is not None and simulator.initial_sheet.positions_sha256() != initial:
        raise ValueError(f'{path}: the rebuilt initial sheet differs from the recorded one')
    recorder = None
    if not rrd:
        callback = on_frame
    else:
        info = dict(read_recording_info(path, chunks))
        info['replay_of'] = str(path)
        info.pop('recorder', None)
        recorder = RerunRecorder('paper_sim_replay', path=rrd, recording_info=info,
                                 appearance=scenario.appearance)
        dt = scenario.config.solver.dt

        def callback(sim, step_seconds: float) -> None:
            recorder.log_frame(sim.time, sim, scalars={
                'step_time': step_seconds,
                'real_time_factor': dt / step_seconds if step_seconds > 0 else 0.0})
            if on_frame is not None:
                on_frame(sim, step_seconds)
    try:
        metrics = run_scenario(scenario, on_frame=callback, simulator=simulator)
    finally:
        if recorder is not None:
            recorder.close()
    metrics['replay_of'] = str(path)
    metrics['replay_frames'] = scenario.frame_count
    metrics['replay_exact'] = scenario.exact
    return metrics
