"""Sleeping (``solver.sleep_speed``): a sheet that has held still falls asleep and costs
nothing, holds exactly still, and wakes as soon as a probe near it moves or the settings
change; the run it then makes is the run it would have made awake."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from paper_sim_ros.core import (ContactConfig, DamageConfig, SheetConfig, SimulationConfig,
                                Simulator, SolverConfig, build_simulator, load_scenario,
                                run_scenario)
from paper_sim_ros.core.scenarios import builtin_mapping, with_overrides

GRID = 17
RADIUS = 0.01


def on_table(**solver) -> Simulator:
    """A flat 17² A4 sheet lying on the table, no damage."""
    return Simulator(SimulationConfig(sheet=SheetConfig(nx=GRID, ny=GRID),
                                      solver=SolverConfig(**solver),
                                      contact=ContactConfig(ground_enabled=True),
                                      damage=DamageConfig(enabled=False)))


def step(simulator: Simulator, frames: int, center=None) -> None:
    """``frames`` frames with one probe of RADIUS at ``center`` (None: no probe)."""
    active = np.array([center is not None])
    at = np.zeros((1, 3)) if center is None else np.asarray(center, dtype=float)[None]
    for _ in range(frames):
        simulator.set_probes(at, np.array([RADIUS]), active)
        simulator.step_frame()


def frames_for(simulator: Simulator, seconds: float) -> int:
    return int(round(seconds / simulator.config.solver.dt))


def test_a_still_sheet_falls_asleep_and_then_holds_exactly_still_at_no_cost():
    simulator = on_table()
    step(simulator, frames_for(simulator, 0.45))
    assert not simulator.asleep, 'asleep before sleep_time (0.5 s) of stillness'
    step(simulator, frames_for(simulator, 0.1))
    assert simulator.asleep
    positions = simulator.sheet.positions.copy()
    iterations = simulator.spring_iterations
    asleep_before = simulator.frames_asleep
    # a probe far above the sheet moving about does not wake it
    for height in np.linspace(0.3, 0.1, 30):
        step(simulator, 1, center=(0.02, -0.03, height))
    assert simulator.asleep
    assert simulator.frames_asleep == asleep_before + 30
    assert simulator.spring_iterations == iterations, 'a sleeping sheet was solved for'
    assert np.array_equal(simulator.sheet.positions, positions)
    assert not np.any(simulator.sheet.velocities)
    assert simulator.time == pytest.approx(0.55 + 0.5, abs=1e-9)


def test_a_probe_coming_down_wakes_the_sheet_and_presses_it_as_if_it_never_slept():
    """The built-in press at 33²: the sheet sleeps while the probe is far above it and after
    it has lifted off, and ends where a sheet that never sleeps ends."""
    ends = {}
    for sleep_speed in (1e-4, 0.0):
        mapping = with_overrides(builtin_mapping('press'), grid=33)
        mapping['solver'] = {'sleep_speed': sleep_speed}
        scenario = load_scenario(mapping)
        simulator = build_simulator(scenario)
        metrics = run_scenario(scenario, simulator=simulator)
        ends[sleep_speed] = simulator.sheet.positions.copy(), metrics
    (slept, metrics), (awake, reference) = ends[1e-4], ends[0.0]
    assert reference['frames_asleep'] == 0
    # 0.5-0.9 s before the probe comes near, 2.2-3 s after it has gone
    assert 60 <= metrics['frames_asleep'] <= 90, metrics['frames_asleep']
    assert np.abs(slept - awake).max() < 1e-9
    for key in ('max_probe_penetration_m', 'max_table_penetration_m'):
        assert metrics[key] == pytest.approx(reference[key], abs=1e-9)
    assert metrics['max_strain'] < 1e-6 and metrics['final_max_speed_mps'] == 0.0


def test_a_probe_holding_still_on_the_sheet_keeps_it_asleep_and_wakes_it_when_it_moves():
    simulator = on_table()
    pressing = (0.0, 0.0, RADIUS - 0.001)  # 1 mm into the table, pinching the sheet
    step(simulator, frames_for(simulator, 0.6), center=pressing)
    assert simulator.asleep
    positions = simulator.sheet.positions.copy()
    rest_id, energy = simulator.rest_id, simulator.energy()
    step(simulator, 10, center=pressing)
    assert simulator.asleep and np.array_equal(simulator.sheet.positions, positions)
    assert simulator.rest_id == rest_id is not None and simulator.energy() == energy
    # it drags the paper 1 mm a frame: awake at once, the gripped paper carried along
    iterations = simulator.spring_iterations
    for frame in range(1, 11):
        step(simulator, 1, center=(0.001 * frame, 0.0, RADIUS - 0.001))
        assert not simulator.asleep
    assert simulator.spring_iterations > iterations and simulator.rest_id is None
    under = np.linalg.norm(positions[:, :2], axis=1) < 0.5 * RADIUS
    moved = simulator.sheet.positions[under, 0] - positions[under, 0]
    assert np.all(moved > 0.008), moved


def test_a_probe_that_leaves_or_changes_size_beside_the_sheet_wakes_it():
    beside = (0.0, 0.0, RADIUS + 0.002)  # 2 mm above the paper, touching nothing
    for change in ('leaves', 'grows'):
        simulator = on_table()
        step(simulator, frames_for(simulator, 0.6), center=beside)
        assert simulator.asleep
        if change == 'leaves':
            step(simulator, 1)
        else:
            simulator.set_probes(np.array([beside]), np.array([2 * RADIUS]), np.array([True]))
            simulator.step_frame()
        assert not simulator.asleep, change


def test_a_lowered_table_wakes_the_sheet_and_it_falls_onto_it():
    simulator = on_table()
    step(simulator, frames_for(simulator, 0.6))
    assert simulator.asleep
    lowered = dataclasses.replace(simulator.config, contact=dataclasses.replace(
        simulator.config.contact, ground_height=-0.05))
    simulator.reconfigure(lowered)
    assert not simulator.asleep
    step(simulator, frames_for(simulator, 1.0))
    heights = simulator.sheet.positions[:, 2]
    assert np.all(np.abs(heights + 0.05) < 1e-3), (heights.min(), heights.max())


def test_a_slowly_drifting_sheet_sleeps_in_air_but_keeps_its_momentum_in_a_vacuum():
    """Sleeping stops a slow drift only where something would: the air's drag here."""
    for air_damping, sleeps in ((0.2, True), (0.0, False)):
        simulator = Simulator(SimulationConfig(
            sheet=SheetConfig(nx=GRID, ny=GRID),
            solver=SolverConfig(gravity=(0.0, 0.0, 0.0), air_damping=air_damping,
                                air_density=0.0),
            damage=DamageConfig(enabled=False)))
        drift = np.array([3e-5, -2e-5, 1e-5])  # 0.04 mm/s, below sleep_speed
        simulator.sheet.velocities[:] = drift
        mass = simulator.sheet.vertex_mass[:, None]
        momentum = (mass * simulator.sheet.velocities).sum(axis=0)
        step(simulator, frames_for(simulator, 1.0))
        assert simulator.asleep == sleeps, air_damping
        if not sleeps:
            kept = (mass * simulator.sheet.velocities).sum(axis=0)
            # not stopped: kept to the solve's rounding (1e-13 kg m/s of 1.5e-7)
            assert np.abs(kept - momentum).max() < 1e-4 * np.abs(momentum).max()


def drifting_in_air() -> Simulator:
    """A 17² sheet in still air with no gravity: it keeps what velocity it is given but for
    the air's linear drag, which would stop it (so it may sleep)."""
    return Simulator(SimulationConfig(
        sheet=SheetConfig(nx=GRID, ny=GRID),
        solver=SolverConfig(gravity=(0.0, 0.0, 0.0), air_damping=0.2, air_density=0.0),
        damage=DamageConfig(enabled=False)))


def test_a_sheet_at_rest_but_for_a_jolt_now_and_then_falls_asleep():
    """What counts is each vertex's mean speed over sleep_time, not its speed in every frame:
    a crumpled sheet at rest whose creases' memories jolted one vertex to 0.2 mm/s every
    eleventh frame (65², seed 4) never slept while any frame's jolt restarted the count."""
    simulator = drifting_in_air()
    fastest = []
    for frame in range(frames_for(simulator, 1.0)):
        # still but for a jolt to 0.2 mm/s, twice sleep_speed, every eleventh frame
        simulator.sheet.velocities[:] = (0.0, 0.0, 2e-4 if frame % 11 == 0 else 0.0)
        step(simulator, 1)
        fastest.append(np.linalg.norm(simulator.sheet.velocities, axis=1).max())
        if simulator.asleep:
            break
    assert simulator.asleep
    # the jolts moved a vertex faster than sleep_speed after the step, within the window
    window = frames_for(simulator, 0.5)
    assert max(fastest[-window:]) > 1e-4 and fastest[-1] < 1e-4


def test_a_sheet_speeding_up_as_the_window_ends_is_not_frozen():
    """Its mean speed over the last 0.5 s is below sleep_speed, but it moves faster than
    that now: it stays awake; held at that speed it never sleeps."""
    simulator = drifting_in_air()
    window = frames_for(simulator, 0.5)
    direction = np.array([0.6, 0.8, 0.0])
    for frame in range(3 * window):
        speed = 1.5e-4 * min(1.0, frame / window)  # up to 1.5 sleep_speed over the window
        simulator.sheet.velocities[:] = speed * direction
        step(simulator, 1)
        assert not simulator.asleep, frame
