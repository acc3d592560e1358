"""A dataset spec: which scenarios, which axes to sweep, which outputs; expanded into runs.

    scenarios: [press, squeeze, my_press.yaml]   # built-in names, files, inline mappings
    sweep:                                       # every combination is a run
      grid: 17
      duration: 0.5
      seed: [0, 1, 2, 3]
      material: [printer_paper, cardboard]
    outputs: {bag: true, rrd: false}             # metrics JSON always

Each run is its resolved scenario: the scenario mapping with the run's axis values applied,
the same shape as a scenario file. Its id is a hash of that mapping, so a run is the same run
whatever the spec that asked for it, and two combinations that resolve to the same scenario
(``probe_speed`` on a scenario without probes) are one run.

The spec is read on the driver, scenario files included, and each run carries its whole
mapping: a worker on another machine of a cluster needs no file of the spec. Whether the
mapping is a valid scenario is the worker's to find out (``core.load_scenario``): a bad
scenario is a failed run with its reason, not a refused spec.
"""
from __future__ import annotations

from dataclasses import dataclass
import hashlib
import itertools
import json
import math
import os
from typing import Any, Callable

import yaml

from ..core.runner import scenario_file_mapping
from ..core.scenarios import with_overrides

SPEC_KEYS = ('scenarios', 'sweep', 'outputs')
OUTPUT_KEYS = ('bag', 'rrd')
ID_LENGTH = 16
"""Hex digits of a run id (64 bits of sha256: no collision in any dataset of this world)."""


@dataclass(frozen=True)
class Outputs:
    """What each run writes besides its metrics JSON and resolved scenario."""

    bag: bool = False
    """A rosbag2 (MCAP) directory, as ``paper_sim_headless --bag``."""
    rrd: bool = False
    """A Rerun recording, as ``paper_sim_headless --rrd``."""


@dataclass(frozen=True)
class RunRequest:
    """One run of a dataset."""

    id: str
    """A hash of ``scenario`` (``run_id``)."""
    source: str
    """The spec's scenario entry: a built-in name, a file as the spec names it, 'inline'."""
    parameters: dict
    """The sweep's value of each axis for this run."""
    scenario: dict
    """The resolved scenario mapping."""

    @property
    def name(self) -> str:
        return str(self.scenario.get('name', 'custom'))

    @property
    def label(self) -> str:
        """'<id> <name> axis=value ...': which run, for people."""
        return describe_run(self.id, self.name, self.parameters)


def describe_run(identifier: str, name: str, parameters: dict) -> str:
    """'<id> <name> axis=value ...'."""
    values = ' '.join(f'{axis}={json.dumps(value)}' for axis, value in parameters.items())
    return f'{identifier} {name} {values}'.rstrip()


@dataclass(frozen=True)
class DatasetSpec:
    scenarios: tuple[tuple[str, dict], ...]
    """(source, mapping) of each scenario entry."""
    sweep: tuple[tuple[str, tuple], ...]
    """(axis, values) in the spec's order: the first axis varies slowest."""
    outputs: Outputs


def _damage_value(key: str) -> Callable[[dict, Any], dict]:
    def apply(mapping: dict, value: Any) -> dict:
        return {**mapping, 'damage': {**(mapping.get('damage') or {}), key: value}}
    return apply


def _override(name: str) -> Callable[[dict, Any], dict]:
    return lambda mapping, value: with_overrides(mapping, **{name: value})


def _with_probe_speed(mapping: dict, factor: Any) -> dict:
    """Every probe moves ``factor`` times as fast along its track: its keyframe times after
    the first shrink by ``factor`` (it starts moving when it did; the scenario's duration is
    unchanged, so a faster probe leaves the sheet longer to settle)."""
    probes = []
    for probe in mapping.get('probes') or []:
        keyframes = [list(keyframe) for keyframe in probe.get('keyframes') or []]
        if keyframes:
            start = keyframes[0][0]
            for keyframe in keyframes:
                keyframe[0] = start + (keyframe[0] - start) / factor
        probes.append({**probe, 'keyframes': keyframes})
    return {**mapping, 'probes': probes} if 'probes' in mapping else mapping


AXES: dict[str, Callable[[dict, Any], dict]] = {
    'seed': _override('seed'),
    'grid': _override('grid'),
    'duration': _override('duration'),
    'dt': _override('dt'),
    'substeps': _override('substeps'),
    'solver': _override('method'),
    'damage': _override('damage_enabled'),
    'material': _override('material'),
    'fragility': _damage_value('fragility'),
    'area_conservation': _damage_value('area_conservation'),
    'probe_speed': _with_probe_speed,
    'cameras': lambda mapping, cameras: {**mapping, 'cameras': cameras},
}
"""What each sweep axis does to a scenario mapping: ``core.scenarios.with_overrides`` for
the headless runner's options, else the scenario key it sets. ``cameras``: a list of camera
sections (each a list of cameras, [] for none; README, scenario files)."""


def run_id(mapping: dict) -> str:
    """The id of a run: a hash of its resolved scenario (keys sorted, floats as Python
    writes them, so a mapping read back from its YAML file hashes the same)."""
    try:
        text = json.dumps(mapping, sort_keys=True, separators=(',', ':'), allow_nan=False)
    except (TypeError, ValueError) as error:
        raise ValueError(f'scenario {mapping.get("name")!r} is not plain data: {error}') \
            from None
    return hashlib.sha256(text.encode()).hexdigest()[:ID_LENGTH]


def load_spec(path: str) -> DatasetSpec:
    """Read and check a dataset spec file; scenario files are read too, relative to the
    spec's folder. Raises ``ValueError`` naming what is wrong."""
    try:
        with open(path, encoding='utf-8') as stream:
            data = yaml.safe_load(stream)
    except OSError as error:
        raise ValueError(f'cannot read the dataset spec: {error}') from None
    except yaml.YAMLError as error:
        raise ValueError(f'{path}: malformed YAML: {error}'.splitlines()[0]) from None
    return spec_from_mapping(data, os.path.dirname(os.path.abspath(path)))


def spec_from_mapping(data: Any, folder: str) -> DatasetSpec:
    """A spec from its parsed YAML; scenario files relative to ``folder``."""
    if not isinstance(data, dict):
        raise ValueError('a dataset spec must be a mapping with scenarios, sweep, outputs')
    unknown = sorted(set(data) - set(SPEC_KEYS))
    if unknown:
        raise ValueError(f'unknown dataset spec keys: {", ".join(unknown)}; '
                         f'known: {", ".join(SPEC_KEYS)}')
    entries = data.get('scenarios')
    if not isinstance(entries, list) or not entries:
        raise ValueError('scenarios must be a non-empty list of built-in names, scenario '
                         'files or scenario mappings')
    scenarios = tuple(_scenario_entry(entry, folder) for entry in entries)
    return DatasetSpec(scenarios, _sweep(data.get('sweep') or {}),
                       _outputs(data.get('outputs') or {}))


def _scenario_entry(entry: Any, folder: str) -> tuple[str, dict]:
    if isinstance(entry, dict):
        return 'inline', dict(entry)
    if not isinstance(entry, str):
        raise ValueError(f'a scenario entry must be a name, a file or a mapping, got {entry!r}')
    return entry, scenario_file_mapping(entry, folder)


def _sweep(sweep: Any) -> tuple[tuple[str, tuple], ...]:
    if not isinstance(sweep, dict):
        raise ValueError(f'sweep must be a mapping of axis: values, got {sweep!r}')
    axes = []
    for axis, values in sweep.items():
        if axis not in AXES:
            raise ValueError(f'unknown sweep axis {axis!r}; known: {", ".join(AXES)}')
        # a single value is a one-value axis; cameras' value is itself a list, so its axis
        # is always a list of camera lists
        if axis == 'cameras':
            if not (isinstance(values, list) and values
                    and all(isinstance(value, list) for value in values)):
                raise ValueError('sweep cameras must be a list of camera lists, e.g. '
                                 '[[], [{name: top, width: 64, height: 48}]]')
        elif not isinstance(values, list):
            values = [values]
        if not values:
            raise ValueError(f'sweep {axis} has no value')
        if axis == 'probe_speed' and not all(
                isinstance(value, (int, float)) and math.isfinite(value) and value > 0
                for value in values):
            raise ValueError(f'sweep probe_speed must be factors > 0, got {values!r}')
        axes.append((axis, tuple(values)))
    return tuple(axes)


def _outputs(outputs: Any) -> Outputs:
    if not isinstance(outputs, dict):
        raise ValueError(f'outputs must be a mapping, e.g. {{bag: true, rrd: false}}, '
                         f'got {outputs!r}')
    unknown = sorted(set(outputs) - set(OUTPUT_KEYS) - {'metrics'})
    if unknown:
        raise ValueError(f'unknown outputs: {", ".join(unknown)}; known: metrics (always), '
                         f'{", ".join(OUTPUT_KEYS)}')
    for key, value in outputs.items():
        if not isinstance(value, bool):
            raise ValueError(f'outputs {key} must be true or false, got {value!r}')
    if outputs.get('metrics') is False:
        raise ValueError('outputs metrics cannot be switched off: every run writes them')
    return Outputs(**{key: outputs.get(key, False) for key in OUTPUT_KEYS})


def expand(spec: DatasetSpec) -> tuple[list[RunRequest], int]:
    """The runs of ``spec`` in a fixed order (scenario entries, then the sweep's axes, the
    first slowest), and how many combinations were dropped as the same run as an earlier
    one."""
    runs: dict[str, RunRequest] = {}
    combinations = 0
    axes = [axis for axis, _ in spec.sweep]
    for source, base in spec.scenarios:
        for values in itertools.product(*(values for _, values in spec.sweep)):
            combinations += 1
            mapping = base
            for axis, value in zip(axes, values):
                try:
                    mapping = AXES[axis](mapping, value)
                except (ValueError, TypeError, AttributeError) as error:
                    # the scenario's shape cannot take the axis (``sheet`` not a mapping,
                    # keyframes not lists): a mistake of the spec, refused before any run
                    raise ValueError(f'scenario {source}: cannot set {axis} = {value!r}: '
                                     f'{error}') from None
            identifier = run_id(mapping)
            runs.setdefault(identifier, RunRequest(identifier, source,
                                                   dict(zip(axes, values)), mapping))
    return list(runs.values()), combinations - len(runs)
