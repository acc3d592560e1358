"""The node's parameter table, its validation and its scheduling, without a node."""
from __future__ import annotations

import numpy as np
import pytest
import yaml

from paper_sim_ros.core.config import SheetConfig, SimulationConfig
from paper_sim_ros.core.sheet import build_flat_sheet
from paper_sim_ros.node import Schedule, pin_mask
from paper_sim_ros.node_parameters import (PARAMETER_NAMES, PARAMETER_SPECS, PARAMETERS,
                                           settings_from_values)
from ros_harness import CONFIG


def defaults() -> dict:
    return {spec.name: spec.default for spec in PARAMETERS}


def flatten(mapping: dict, prefix: str = '') -> dict:
    flat = {}
    for key, value in mapping.items():
        if isinstance(value, dict):
            flat.update(flatten(value, f'{prefix}{key}.'))
        else:
            flat[f'{prefix}{key}'] = value
    return flat


def test_every_parameter_is_described_once_with_a_range_where_numeric():
    assert len(PARAMETER_NAMES) == len(set(PARAMETER_NAMES))
    for spec in PARAMETERS:
        assert spec.description.strip(), spec.name
        numeric = isinstance(spec.default, (int, float)) and not isinstance(spec.default, bool)
        if numeric:
            assert spec.bounds is not None, f'{spec.name} has no range'
            low, high = spec.bounds
            assert low <= spec.default <= high, spec.name
    for name in ('sheet.nx', 'sheet.ny', 'solver.method', 'physics_rate', 'frame_id',
                 'probe_topics', 'rerun_path', 'seed'):
        assert PARAMETER_SPECS[name].read_only, f'{name} cannot change at run time'
    for name in ('publish_rate', 'markers_rate', 'probe_radii', 'probe_timeout', 'pin_mode',
                 'crumple_count', 'solver.substeps', 'contact.ground_height'):
        assert not PARAMETER_SPECS[name].read_only, f'{name} can change at run time'


def test_the_shipped_parameter_file_names_only_declared_parameters():
    document = yaml.safe_load(CONFIG.read_text())
    assert list(document) == ['/paper_sim']
    values = flatten(document['/paper_sim']['ros__parameters'])
    unknown = sorted(set(values) - set(PARAMETER_NAMES))
    assert not unknown, f'parameters in {CONFIG.name} that the node does not declare: {unknown}'
    merged = {**defaults(), **values}
    settings = settings_from_values(merged)
    assert settings.simulation.sheet.nx == values['sheet.nx']
    for name, value in values.items():
        spec = PARAMETER_SPECS[name]
        assert type(value) is type(spec.default) or (
            isinstance(value, list) and isinstance(spec.default, list)), \
            f'{name}: {value!r} is not of the declared type of {spec.default!r}'


def test_defaults_make_valid_settings():
    settings = settings_from_values(defaults())
    assert isinstance(settings.simulation, SimulationConfig)
    assert settings.simulation.solver.dt == pytest.approx(1.0 / settings.physics_rate)
    assert settings.probe_topics == ('probe/pose',)
    assert settings.probe_radii == (0.02,)


def test_one_radius_serves_every_probe():
    settings = settings_from_values({**defaults(), 'probe_topics': ['a', 'b', 'c'],
                                     'probe_radii': [0.01]})
    assert settings.probe_radii == (0.01, 0.01, 0.01)


@pytest.mark.parametrize('changes, reason', [
    ({'pin_mode': 'diagonal'}, 'pin_mode must be one of'),
    ({'probe_radii': [0.01, 0.02]}, 'one radius per probe topic'),
    ({'probe_radii': [-0.01]}, 'probe radii'),
    ({'probe_topics': ['a', 'a']}, 'distinct'),
    ({'frame_id': ' '}, 'frame_id'),
    ({'solver.method': 'magic'}, 'method'),
    ({'sheet.nx': 2}, 'nx'),
    ({'contact.ground_friction': -1.0}, 'ground_friction'),
    ({'publish_rate': float('nan')}, 'publish_rate'),
])
def test_invalid_values_are_refused_with_a_reason(changes, reason):
    with pytest.raises(ValueError, match=reason):
        settings_from_values({**defaults(), **changes})


def test_a_missing_parameter_is_named():
    values = defaults()
    del values['probe_timeout']
    with pytest.raises(ValueError, match='probe_timeout'):
        settings_from_values(values)


def test_schedule_publishes_at_its_rate_and_counts_what_it_skips():
    schedule = Schedule()
    published = sum(schedule.take(frame / 60.0, 10.0) for frame in range(1, 60))
    assert published == 10 and schedule.dropped == 0, 'slots 0.0, 0.1 ... 0.9 s'
    assert schedule.take(2.0, 10.0), 'due after a jump'
    assert schedule.dropped == 10, 'the slots 1.0 ... 1.9 s were dropped'
    off = Schedule()
    assert not any(off.take(frame / 60.0, 0.0) for frame in range(1, 600))
    assert off.take(10.0, 10.0) and off.dropped == 0, 'an output that was off dropped nothing'


def test_pin_mask_clamps_the_short_edge():
    sheet = build_flat_sheet(SheetConfig(nx=5, ny=7))
    assert not pin_mask(sheet, 'none').any()
    mask = pin_mask(sheet, 'short_edge')
    assert mask.sum() == 5
    assert np.allclose(sheet.positions[mask, 1], sheet.height / 2)
    with pytest.raises(ValueError):
        pin_mask(sheet, 'corner')
