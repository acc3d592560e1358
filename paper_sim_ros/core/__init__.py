"""The simulation core: pure Python, numpy and numba; no ROS, no Rerun.

The names below are the stable Python API for scripts and tests without ROS (README,
"Python API (no ROS)"); everything else in the submodules may change.
"""
from .appearance import AppearanceConfig
from .config import ContactConfig, DamageConfig, SheetConfig, SimulationConfig, SolverConfig
from .materials import MATERIAL_PRESETS, material_preset
from .metrics import damage_metrics, mesh_problems, plane_deviation, relaxed_deviation
from .runner import (build_simulator, check_metrics_path, load_scenario, run_scenario,
                     write_metrics)
from .scenarios import BUILTIN_SCENARIOS, PIN_MODES, Scenario, pin_mask
from .sheet import AUX, BEND, CREASED, HINGE, INSERTED, UNDAMAGED, Sheet, damage_labels
from .simulator import Simulator
from .topology import vertex_normals

__all__ = [
    'AUX', 'AppearanceConfig', 'BEND', 'BUILTIN_SCENARIOS', 'CREASED', 'ContactConfig',
    'DamageConfig', 'HINGE', 'INSERTED', 'MATERIAL_PRESETS', 'PIN_MODES', 'Scenario', 'Sheet',
    'SheetConfig', 'SimulationConfig', 'Simulator', 'SolverConfig', 'UNDAMAGED',
    'build_simulator', 'check_metrics_path', 'damage_labels', 'damage_metrics',
    'load_scenario', 'material_preset', 'mesh_problems', 'pin_mask', 'plane_deviation',
    'relaxed_deviation', 'run_scenario', 'vertex_normals', 'write_metrics',
]
