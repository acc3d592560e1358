"""The Python API (no ROS): README's "Python API (no ROS)" example runs as written, and what it
reads is what it says."""
from __future__ import annotations

from pathlib import Path
import re

import numpy as np
import pytest

import paper_sim_ros.core as core

README = Path(__file__).resolve().parents[1] / 'README.md'


def readme_example() -> str:
    """The first python code block of README's "Python API (no ROS)" section."""
    text = README.read_text(encoding='utf-8')
    section = text.split('\n## Python API (no ROS)\n', 1)
    assert len(section) == 2, 'README has no "## Python API (no ROS)" section'
    block = re.search(r'```python\n(.*?)```', section[1].split('\n## ', 1)[0], re.DOTALL)
    assert block is not None, 'the "Python API (no ROS)" section has no python code block'
    return block.group(1)


@pytest.fixture(scope='module')
def example() -> dict:
    """The README example's variables after it ran."""
    namespace: dict = {'__name__': 'readme_example'}
    exec(compile(readme_example(), str(README), 'exec'), namespace)
    return namespace


def test_readme_example_reads_positions_normals_labels_and_metrics(example):
    simulator = example['simulator']
    vertex_count = simulator.sheet.vertex_count
    assert example['scenario'].material == 'cardboard'
    assert simulator.config.sheet.grammage == core.material_preset('cardboard')['sheet'][
        'grammage']
    np.testing.assert_allclose(simulator.time, 0.5, atol=1e-9, err_msg='30 frames of 1/60 s')
    positions, normals, labels = example['positions'], example['normals'], example['labels']
    assert positions.shape == normals.shape == (vertex_count, 3)
    assert np.all(np.isfinite(positions))
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-12,
                               err_msg='vertex normals are not unit')
    assert labels.shape == (vertex_count,)
    assert set(np.unique(labels).tolist()) <= {core.UNDAMAGED, core.CREASED, core.INSERTED}
    # the crumple broke springs: each break inserted a vertex, past the initial grid
    damage = example['damage']
    assert damage['breaks'] > 0 and damage['mesh_valid'], damage
    inserted = np.flatnonzero(labels == core.INSERTED)
    assert inserted.size == damage['breaks']
    assert inserted.min() == simulator.initial_sheet.vertex_count
    assert np.any(labels == core.CREASED)
    # the fingertip came down to 1 cm, its 1 cm radius on the table: the sheet under it is
    # on the table, not pushed through
    assert positions[:, 2].min() > -0.002


def test_readme_example_runs_a_scenario_to_its_metrics(example):
    metrics = example['metrics']
    assert metrics['scenario'] == 'squeeze'
    assert metrics['grid'] == [17, 17]
    assert metrics['steps'] == 60
    assert not metrics['nan'] and metrics['mesh_valid']
    assert len(metrics['final_positions_sha256']) == 64


def test_the_api_names_are_exported():
    for name in ('load_scenario', 'build_simulator', 'run_scenario', 'Scenario', 'Simulator',
                 'SimulationConfig', 'SheetConfig', 'SolverConfig', 'ContactConfig',
                 'DamageConfig', 'AppearanceConfig', 'material_preset', 'BUILTIN_SCENARIOS',
                 'damage_labels', 'vertex_normals', 'damage_metrics', 'PIN_MODES', 'pin_mask'):
        assert name in core.__all__ and hasattr(core, name), name


def test_load_scenario_takes_a_name_a_file_or_a_mapping(tmp_path):
    by_name = core.load_scenario('press', grid=9, duration=0.5)
    path = tmp_path / 'my_press.yaml'
    path.write_text('duration: 0.5\nsheet: {nx: 9, ny: 9}\ncontact: {ground_enabled: true}\n'
                    'probes:\n  - {name: finger, radius: 0.01, keyframes: '
                    '[[0.0, 0, 0, 0.05], [1.0, 0, 0, 0.009]]}\n')
    by_file = core.load_scenario(str(path))
    by_mapping = core.load_scenario({'duration': 0.5, 'sheet': {'nx': 9, 'ny': 9}})
    assert (by_name.name, by_file.name, by_mapping.name) == ('press', 'my_press', 'custom')
    assert by_name.config.sheet.nx == by_file.config.sheet.nx == by_mapping.config.sheet.nx == 9
    assert by_file.probes[0].radius == 0.01
    with pytest.raises(ValueError, match='neither a built-in'):
        core.load_scenario('no_such_scenario')


def test_material_and_appearance_reach_the_scenario_and_explicit_keys_win():
    preset = core.material_preset('banknote')
    scenario = core.load_scenario({'material': 'banknote', 'sheet': {'grammage': 0.1},
                                   'appearance': {'normal_level': 4, 'texture_blend': 0.5}})
    assert scenario.config.sheet.grammage == 0.1
    assert scenario.config.sheet.bending_rigidity == preset['sheet']['bending_rigidity']
    assert scenario.config.damage.fragility == preset['damage']['fragility']
    assert scenario.appearance == core.AppearanceConfig(normal_level=4, texture_blend=0.5)
    assert core.load_scenario('press').appearance == core.AppearanceConfig()


@pytest.mark.parametrize('mapping, message', [
    ({'material': 'papyrus'}, "unknown material 'papyrus'"),
    ({'material': 3}, 'material must be a name'),
    ({'appearance': {'shine': 1}}, 'unknown AppearanceConfig keys: shine'),
    ({'appearance': {'ambient': 2.0}}, 'ambient must be in'),
    ({'appearance': [1, 2]}, 'appearance must be a mapping'),
    ({'colour': 'blue'}, 'unknown scenario keys: colour'),
])
def test_bad_material_or_appearance_is_refused_with_the_reason(mapping, message):
    with pytest.raises(ValueError, match=message):
        core.load_scenario(mapping)


def test_pin_mask_clamps_the_short_edge_at_minus_half_the_height():
    scenario = core.load_scenario('hanging', grid=9)
    simulator = core.build_simulator(scenario)
    sheet = simulator.sheet
    mask = core.pin_mask(sheet, 'short_edge')
    np.testing.assert_allclose(sheet.material[mask, 1], -sheet.height / 2, atol=1e-12)
    assert mask.sum() == 9
    np.testing.assert_array_equal(simulator.sheet.pinned, mask)
    assert not core.pin_mask(sheet, 'none').any()
    with pytest.raises(ValueError, match='pin mode must be one of none, short_edge'):
        core.pin_mask(sheet, 'corner')
