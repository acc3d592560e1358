"""The node's parameter table, its validation and its scheduling, without a node."""
from __future__ import annotations

from dataclasses import fields

import numpy as np
import pytest
import yaml

from paper_sim_ros.core.appearance import AppearanceConfig
from paper_sim_ros.core.config import DamageConfig, SheetConfig, SimulationConfig
from paper_sim_ros.core.materials import MATERIAL_PRESETS
from paper_sim_ros.core.scenarios import pin_mask
from paper_sim_ros.core.sheet import build_flat_sheet
from paper_sim_ros.node import Schedule
from paper_sim_ros.node_parameters import (PARAMETER_SPECS, PARAMETERS, declared_defaults,
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
    assert len(PARAMETER_SPECS) == len(PARAMETERS)
    for spec in PARAMETERS:
        assert spec.description.strip(), spec.name
        numeric = isinstance(spec.default, (int, float)) and not isinstance(spec.default, bool)
        if numeric:
            assert spec.bounds is not None, f'{spec.name} has no range'
            low, high = spec.bounds
            assert low <= spec.default <= high, spec.name
    for name in ('sheet.nx', 'sheet.ny', 'solver.method', 'physics_rate', 'frame_id',
                 'probe_topics', 'rerun_path', 'seed', 'material', 'damage.fragility',
                 'appearance.texture_path', 'appearance.light_direction'):
        assert PARAMETER_SPECS[name].read_only, f'{name} cannot change at run time'
    for name in ('publish_rate', 'markers_rate', 'probe_radii', 'probe_timeout', 'pin_mode',
                 'crumple_count', 'solver.substeps', 'contact.ground_height'):
        assert not PARAMETER_SPECS[name].read_only, f'{name} can change at run time'


def test_the_shipped_parameter_file_names_only_declared_parameters():
    document = yaml.safe_load(CONFIG.read_text())
    assert list(document) == ['/paper_sim']
    values = flatten(document['/paper_sim']['ros__parameters'])
    unknown = sorted(set(values) - set(PARAMETER_SPECS))
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
    ({'contact.grip_give': float('inf')}, 'grip_give'),
    ({'solver.give_substeps': 0}, 'give_substeps'),
    ({'solver.squeeze_step_ratio': -1.0}, 'squeeze_step_ratio'),
    ({'publish_rate': float('nan')}, 'publish_rate'),
    ({'material': 'papyrus'}, "unknown material 'papyrus'"),
    ({'appearance.light_direction': [0.0, 0.0, 0.0]}, 'light_direction'),
    ({'appearance.normal_level': 0}, 'normal_level'),
    ({'appearance.texture_blend': 1.5}, 'texture_blend'),
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
    """The node pins with the core's pin_mask: short_edge is the edge at y = -height/2."""
    sheet = build_flat_sheet(SheetConfig(nx=5, ny=7))
    assert not pin_mask(sheet, 'none').any()
    mask = pin_mask(sheet, 'short_edge')
    assert mask.sum() == 5
    np.testing.assert_allclose(sheet.positions[mask, 1], -sheet.height / 2, atol=1e-12,
                               err_msg='short_edge must clamp the edge at y = -height/2')
    with pytest.raises(ValueError):
        pin_mask(sheet, 'corner')


# -------------------------------------------------------------------------------- material
def test_without_a_material_the_defaults_are_the_core_s():
    assert declared_defaults('') == {**defaults(), 'material': ''}
    settings = settings_from_values(declared_defaults(''))
    assert settings.material == ''
    assert settings.simulation.sheet == SheetConfig()
    assert settings.simulation.damage == DamageConfig()


@pytest.mark.parametrize('material', sorted(MATERIAL_PRESETS))
def test_a_material_preset_gives_the_defaults_of_the_parameters_it_names(material):
    declared = declared_defaults(material)
    settings = settings_from_values(declared)
    assert settings.material == material
    for section, values in MATERIAL_PRESETS[material].items():
        config = getattr(settings.simulation, section)
        for field, value in values.items():
            name = f'{section}.{field}'
            spec = PARAMETER_SPECS[name]  # every preset value is a node parameter...
            assert spec.read_only, f'{name} is set by the read-only material'
            assert type(declared[name]) is type(spec.default), f'{name}: declared type'
            low, high = spec.bounds  # ... and inside the range rclpy enforces
            assert low <= declared[name] <= high, f'{material}: {name} = {value}'
            assert getattr(config, field) == pytest.approx(value), name
    named = {f'{section}.{field}' for section, values in MATERIAL_PRESETS[material].items()
             for field in values}
    others = {name: value for name, value in declared.items()
              if name not in named and name != 'material'}
    assert others == {name: value for name, value in defaults().items() if name in others}, \
        'a preset changed a parameter it does not name'


def test_a_parameter_given_explicitly_wins_over_the_material():
    """rclpy declares a parameter with the value given in the parameter file or with -p when
    there is one, else with the declared default: the preset's. Same here."""
    explicit = {'damage.fragility': 3.0, 'sheet.grammage': 0.1}
    settings = settings_from_values({**declared_defaults('cardboard'), **explicit})
    assert settings.simulation.damage.fragility == 3.0
    assert settings.simulation.sheet.grammage == 0.1
    cardboard = MATERIAL_PRESETS['cardboard']
    assert settings.simulation.sheet.bending_rigidity == cardboard['sheet']['bending_rigidity']
    assert settings.simulation.damage.area_conservation == \
        cardboard['damage']['area_conservation']


def test_an_unknown_material_is_refused_with_the_known_ones():
    with pytest.raises(ValueError, match='known: printer_paper'):
        declared_defaults('papyrus')


# ------------------------------------------------------------------------------ appearance
def test_every_appearance_field_is_a_parameter():
    names = {spec.name for spec in PARAMETERS if spec.name.startswith('appearance.')}
    assert names == {f'appearance.{field.name}' for field in fields(AppearanceConfig)}
    assert settings_from_values(defaults()).appearance == AppearanceConfig()


def test_appearance_parameters_reach_the_appearance_config():
    settings = settings_from_values({
        **defaults(), 'appearance.normal_level': 4, 'appearance.light_direction': [0.0, 0.0, 2.0],
        'appearance.ambient': 0.5, 'appearance.texture_blend': 0.0,
        'appearance.texture_seed': 7, 'appearance.texture_size': 64,
        'appearance.texture_path': '/tmp/page.png'})
    assert settings.appearance == AppearanceConfig(
        texture_path='/tmp/page.png', normal_level=4, light_direction=(0.0, 0.0, 2.0),
        ambient=0.5, texture_blend=0.0, texture_seed=7, texture_size=64)
