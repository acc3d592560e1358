"""Damage that stays (SPEC §4, paper §3.2–3.3): breakable hinge springs, folds, crumpling,
the adaptive mesh, and the headless runner's damage metrics. Every test asserts numbers."""
from dataclasses import replace
import inspect
import logging
import math

import numpy as np
import pytest

from paper_sim_ros.core import (AUX, BEND, HINGE, MATERIAL_PRESETS, ContactConfig, DamageConfig,
                                SheetConfig, SimulationConfig, Simulator, SolverConfig,
                                build_simulator, material_preset, mesh_problems, plane_deviation,
                                load_scenario, run_scenario)
from paper_sim_ros.core import kernels
from paper_sim_ros.core.damage import DamageModel
from paper_sim_ros.core.mesh_editing import MeshEditor
from paper_sim_ros.core.metrics import ridge_heights
from paper_sim_ros.core.scenarios import builtin_mapping, scenario_from_mapping, with_overrides
from paper_sim_ros.core.sheet import build_flat_sheet
from paper_sim_ros.core.topology import check_mesh, mesh_edges
from paper_sim_ros.headless import main

SMALL = SheetConfig(nx=17, ny=17)


def exact_mass(sheet) -> float:
    """The correctly rounded sum of the vertex masses (independent of summation order)."""
    return math.fsum(sheet.vertex_mass.tolist())


def squeeze_mapping(grid: int = 33, membrane: bool = True, **damage) -> dict:
    """The squeeze at ``grid``² with ``damage`` settings; without ``membrane`` the squeezed
    sheet is crushed, as built before the membrane (it then breaks and folds far more), and
    its fingertips hold it however the paper behind them stretches (``grip_give`` 0: the
    crushed sheet stretched there, and they let go before it broke)."""
    mapping = with_overrides(builtin_mapping('squeeze'), grid=grid)
    mapping['damage'] = damage
    if not membrane:
        mapping['solver'] = {**(mapping.get('solver') or {}), 'membrane_weight': 0.0}
        mapping['contact'] = {**(mapping.get('contact') or {}), 'grip_give': 0.0}
    return mapping


def run_squeeze(substeps: int = 1, seed: int = 0, enabled: bool = True,
                fragility: float = 1.0, relax: bool = True, grid: int = 33,
                membrane: bool = True) -> dict:
    """Metrics of the squeeze, 33 × 33 unless told. Without ``relax`` only the 3 s in which
    the probes act are run (no relaxation metrics); ``membrane``: squeeze_mapping's."""
    mapping = with_overrides(squeeze_mapping(grid, membrane, enabled=enabled,
                                             fragility=fragility),
                             substeps=substeps, seed=seed, duration=None if relax else 3.0)
    scenario = scenario_from_mapping(mapping)
    simulator = build_simulator(scenario)
    mass = exact_mass(simulator.sheet)
    if relax:
        metrics = run_scenario(scenario, simulator=simulator)
    else:
        dt = scenario.config.solver.dt
        for frame in range(scenario.frame_count):
            simulator.set_probes(*scenario.probe_inputs((frame + 1) * dt))
            simulator.step_frame()
        metrics = {'breaks': simulator.breaks, 'folds': simulator.folds,
                   'final_positions_sha256': simulator.sheet.positions_sha256()}
    metrics['mass_conserved'] = exact_mass(simulator.sheet) == mass
    metrics['problems'] = mesh_problems(simulator.sheet)
    return metrics


@pytest.fixture(scope='module')
def squeeze():
    """run_squeeze, each run once in this module: tests share runs (the 33² one with seed 0,
    1 sub-step and φ = 1 serves two). Arguments are keyed with their defaults filled in."""
    signature = inspect.signature(run_squeeze)
    runs = {}

    def cached(**arguments) -> dict:
        bound = signature.bind(**arguments)
        bound.apply_defaults()
        key = tuple(bound.arguments.items())
        if key not in runs:
            runs[key] = run_squeeze(**arguments)
        return runs[key]
    return cached


# ------------------------------------------------------------------ the single operations
def compressed_sheet(ratio: float):
    """A 5 × 5 sheet whose central horizontal HINGE spring is pushed to ratio × l0."""
    sheet = build_flat_sheet(SheetConfig(nx=5, ny=5, width=0.04, height=0.04))
    centre, right = 12, 13
    spring = int(np.flatnonzero((sheet.spring_kind == HINGE)
                                & (np.sort(sheet.spring_vertices, axis=1) == [centre, right])
                                .all(axis=1))[0])
    l0 = sheet.spring_rest_length[spring]
    sheet.positions[right, 0] = sheet.positions[centre, 0] + ratio * l0
    return sheet, spring, centre, right, float(l0)


@pytest.mark.parametrize('psi', [0.0, 0.5, 1.0, 1.5])
def test_a_break_follows_eq_8_and_fig_4(psi):
    sheet, spring, i, j, l0 = compressed_sheet(0.8)
    mass, vertices = exact_mass(sheet), sheet.vertex_count
    counts = np.bincount(sheet.spring_kind, minlength=3)
    sheet.velocities[i] = (1.0, 0.0, 0.0)
    sheet.velocities[j] = (0.0, 3.0, 0.0)
    momentum_before = (sheet.vertex_mass[:, None] * sheet.velocities).sum(axis=0)
    editor = MeshEditor(sheet, aux_stiffness=3e4)
    m = editor.break_spring(spring, 0.8 * l0, np.random.default_rng(0), psi)
    editor.commit()
    assert m == vertices and sheet.vertex_count == vertices + 1
    assert mesh_problems(sheet) == []
    assert exact_mass(sheet) == mass, 'total mass must be conserved to the last bit'
    np.testing.assert_allclose(sheet.total_mass, mass, rtol=4e-16)
    # Eq. 8: m sits h = ψ/2·sqrt(l0² − l_t²) off the midpoint, along the normal (±z here)
    height = 0.5 * psi * math.sqrt(l0 ** 2 - (0.8 * l0) ** 2)
    midpoint = 0.5 * (sheet.positions[i] + sheet.positions[j])
    np.testing.assert_allclose(np.abs(sheet.positions[m] - midpoint), [0.0, 0.0, height],
                               atol=1e-15, err_msg='m not at the Eq. 8 height on the normal')
    # texture coordinates follow the material: m is the midpoint of its edge on the flat sheet
    np.testing.assert_allclose(sheet.material[m], 0.5 * (sheet.material[i] + sheet.material[j]))
    # velocity: mass-weighted mean of the ends, so momentum is conserved
    momentum = (sheet.vertex_mass[:, None] * sheet.velocities).sum(axis=0)
    np.testing.assert_allclose(momentum, momentum_before, rtol=1e-12)
    np.testing.assert_allclose(sheet.velocities[m], [0.5, 1.5, 0.0], rtol=1e-12)
    # springs: the halves l0/2, two new HINGE (m, r), (m, l), one AUX; four triangles for two
    new_counts = np.bincount(sheet.spring_kind, minlength=3)
    assert new_counts[HINGE] - counts[HINGE] == 3 and new_counts[AUX] - counts[AUX] == 1
    assert new_counts[BEND] == counts[BEND]
    ends = np.sort(sheet.spring_vertices, axis=1)
    is_half = ((ends == sorted((i, m))).all(1)) | ((ends == sorted((m, j))).all(1))
    halves = np.flatnonzero((sheet.spring_kind == HINGE) & is_half)
    np.testing.assert_allclose(sheet.spring_rest_length[halves], [0.5 * l0] * 2)
    aux = np.flatnonzero(sheet.spring_kind == AUX)[0]
    assert sorted(sheet.spring_vertices[aux]) == sorted((i, j))
    assert sheet.spring_rest_length[aux] == pytest.approx(math.sqrt(l0 ** 2 - 4 * height ** 2))
    assert len(sheet.triangles) == 2 * 4 * 4 + 2


def test_with_psi_one_the_halves_come_out_at_rest_length():
    sheet, spring, i, j, l0 = compressed_sheet(0.7)
    editor = MeshEditor(sheet, aux_stiffness=3e4)
    m = editor.break_spring(spring, 0.7 * l0, np.random.default_rng(1), 1.0)
    editor.commit()
    for end in (i, j):
        half = np.linalg.norm(sheet.positions[m] - sheet.positions[end])
        assert half == pytest.approx(0.5 * l0, rel=1e-12), 'a half is not at rest length'
    aux = np.flatnonzero(sheet.spring_kind == AUX)[0]
    assert sheet.spring_rest_length[aux] == pytest.approx(0.7 * l0, rel=1e-12), \
        'with ψ = 1 the AUX spring must remember l_t'


def test_the_new_vertex_goes_to_the_side_the_sheet_bulges():
    for sign in (1.0, -1.0):
        sheet, spring, i, j, l0 = compressed_sheet(0.9)
        # a dome (sign > 0: it bulges up) or a bowl (it bulges down): z = −sign·k·(x² + y²)
        xy = sheet.positions[:, :2] - sheet.positions[i, :2]
        sheet.positions[:, 2] = -sign * 20.0 * (xy ** 2).sum(axis=1)
        editor = MeshEditor(sheet, aux_stiffness=3e4)
        m = editor.break_spring(spring, 0.9 * l0, np.random.default_rng(0), 1.0)
        editor.commit()
        rise = sheet.positions[m, 2] - 0.5 * (sheet.positions[i, 2] + sheet.positions[j, 2])
        assert sign * rise > 0.4 * 0.5 * math.sqrt(l0 ** 2 - (0.9 * l0) ** 2), \
            f'bulge {sign:+}: m moved {rise:+.2e} m'


def test_a_fold_replaces_the_bend_spring_and_stays():
    sheet = build_flat_sheet(SheetConfig(nx=9, ny=9, width=0.08, height=0.08))
    # fold the sheet sharply along the middle row of vertices (material y = 0)
    y = sheet.material[:, 1]
    sheet.positions[y > 1e-9, 1] = 0.0
    sheet.positions[y > 1e-9, 2] = y[y > 1e-9] * 0.6
    sheet.positions[y > 1e-9, 1] = y[y > 1e-9] * 0.8
    bend_before = int(np.sum(sheet.spring_kind == BEND))
    model = DamageModel(DamageConfig(fold_threshold=0.95), seed=0, aux_stiffness=3e4,
                        held_inextensible=True)
    assert model.check(sheet)
    assert model.folds > 0 and model.breaks == 0
    assert int(np.sum(sheet.spring_kind == BEND)) == bend_before - model.folds
    aux = np.flatnonzero(sheet.spring_kind == AUX)
    lengths = np.linalg.norm(np.diff(sheet.positions[sheet.spring_vertices[aux]], axis=1)[:, 0],
                             axis=1)
    np.testing.assert_allclose(sheet.spring_rest_length[aux], lengths,
                               err_msg='a fold remembers the length it had')
    assert mesh_problems(sheet) == []
    # the fold stays: flat again, nothing more folds and the AUX springs remain
    sheet.positions[:, 1:] = np.column_stack([y, np.zeros_like(y)])
    folds = model.folds
    assert not model.check(sheet)
    assert model.folds == folds and np.sum(sheet.spring_kind == AUX) == aux.size


def squashed_sheet(squash: float, extra: bool = False):
    """A 41² sheet, 0.2 m square, whose left half is squashed along x by ``squash`` (its
    x-running HINGE springs there compressed by it, those along y not); with ``extra``, one
    x-running spring at the right edge too, two cells away from the rest."""
    sheet = build_flat_sheet(SheetConfig(nx=41, ny=41, width=0.2, height=0.2))
    x = sheet.material[:, 0]
    left = x < -0.05
    sheet.positions[left, 0] = -0.05 + (x[left] + 0.05) * (1.0 - squash)
    if extra:
        edge = np.flatnonzero(np.isclose(x, x.max()) & np.isclose(sheet.material[:, 1], 0.0))
        sheet.positions[edge, 0] -= squash * 0.005  # the cell is 5 mm wide
    return sheet


def broken_pairs(model: DamageModel) -> set:
    return {(min(i, j), max(i, j)) for i, _, j in model.creases}


@pytest.mark.parametrize('fragility, squash', [(1.0, 0.6), (2.0, 0.7)])
def test_eq_7_breaks_a_spring_compressed_at_a_check_with_its_probability(fragility, squash):
    """At one check a spring compressed by c breaks with probability P = c^φ (Eq. 7): of
    the 410 x-running HINGE springs of the squashed half, P (0.6 and 0.49 here) of them
    break, within three standard deviations. This checks the hazard's scale: drawn as
    E < P instead of E < −ln(1 − P), 45 % and 39 % would break."""
    probability = squash ** fragility
    sheet = squashed_sheet(squash)
    model = DamageModel(DamageConfig(fragility=fragility, max_vertices=10**6), seed=4,
                        aux_stiffness=3e4, held_inextensible=False)
    candidates = int(np.sum((model.compression(sheet) > 0.1) & (sheet.spring_kind == HINGE)
                            & (sheet.material[sheet.spring_vertices[:, 0], 1]
                               == sheet.material[sheet.spring_vertices[:, 1], 1])))
    material = sheet.material.copy()
    model.check(sheet)
    # the diagonals, compressed less, break too: count the x-running springs only
    broken = sum(material[i, 1] == material[j, 1] for i, j in broken_pairs(model))
    assert candidates == 410
    spread = 3.0 * math.sqrt(probability * (1.0 - probability) / candidates)
    assert abs(broken / candidates - probability) < spread, (broken, candidates)
    assert mesh_problems(sheet) == []


def test_which_springs_break_does_not_hinge_on_the_other_candidates():
    """Each spring breaks when its own compression takes its own seeded threshold: a
    sheet with one more compressed spring elsewhere breaks the same springs in the
    squashed half, check after check: 100 of them and the extra one. (Drawn afresh per
    candidate and check, the one extra draw shifted every later one: 69 of the 99 breaks
    of the plain sheet were not among the other's.)"""
    models, sheets = [], []
    for extra in (False, True):
        sheets.append(squashed_sheet(0.06, extra))
        models.append(DamageModel(DamageConfig(max_vertices=10**6), seed=7,
                                  aux_stiffness=3e4, held_inextensible=False))
    for _ in range(3):
        for model, sheet in zip(models, sheets):
            model.check(sheet)
    plain, other = (broken_pairs(model) for model in models)
    assert len(plain) > 20
    extra_springs = other - plain
    assert plain <= other and len(extra_springs) <= 1, (len(plain), len(extra_springs))


# -------------------------------------------------------------- invariants, property-style
@pytest.mark.slow
def test_tens_of_thousands_of_random_breaks_and_folds_keep_the_mesh_valid():
    """Property-style: 24 seeded sheets × 1000 random events, checked after every 250."""
    config = DamageConfig(max_vertices=100_000, min_breakable_length=1e-4)
    events = 0
    for seed in range(24):
        sheet = build_flat_sheet(SheetConfig(nx=9 + 4 * (seed % 3), ny=9 + 4 * (seed % 3)))
        mass = exact_mass(sheet)
        model = DamageModel(replace(config, crumple_fold_fraction=0.2 + 0.3 * (seed % 3)),
                            seed=seed, aux_stiffness=3e4)
        for round_ in range(4):
            events += model.crumple(sheet, 250, seed=1000 * seed + round_)
            problems = mesh_problems(sheet)
            assert problems == [], f'seed {seed} round {round_}: {problems}'
            assert exact_mass(sheet) == mass, f'seed {seed}: mass changed'
            assert np.all(sheet.vertex_mass > 0)
        assert model.breaks > 100 and model.folds > 30
    assert events >= 20_000


def test_a_crumpled_sheet_keeps_mass_and_validity_through_simulation():
    config = SimulationConfig(sheet=SMALL, solver=SolverConfig(gravity=(0.0, 0.0, 0.0)))
    simulator = Simulator(config)
    mass = exact_mass(simulator.sheet)
    simulator.crumple(150, seed=3)
    for _ in range(60):
        simulator.step_frame()
    assert not simulator.nan_seen
    assert mesh_problems(simulator.sheet) == []
    assert exact_mass(simulator.sheet) == mass
    assert simulator.breaks >= 50 and simulator.folds >= 50
    # crumpling is random damage, not a rule: the same seed gives the same sheet
    again = Simulator(config)
    again.crumple(150, seed=3)
    for _ in range(60):
        again.step_frame()
    assert again.sheet.positions_sha256() == simulator.sheet.positions_sha256()


def test_random_damage_is_plastic_and_a_memory_the_paper_cannot_follow_gives_way():
    """Crumpling lifts creases out of a flat sheet; an isolated crease is not developable,
    so the paper around it rests in its new shape (no spring starts stretched), and a
    crease's memory (AUX) pulls towards its length gradually, only while the sheet follows
    unstretched, keeping what it reached: the HINGE springs stay near the strain band all
    along, some memories are reached in part, none is longer than the paper between its
    ends. Set at once, the memories strained this sheet 40 % and more."""
    config = SimulationConfig(sheet=SheetConfig(nx=33, ny=33),
                              solver=SolverConfig(gravity=(0.0, 0.0, 0.0), air_damping=3.0))
    simulator = Simulator(config)
    simulator.crumple(100, seed=7)
    sheet = simulator.sheet
    assert sheet.strain(HINGE).max() < 1e-12
    aux = np.flatnonzero(sheet.spring_kind == AUX)
    target = simulator._memory_target[aux].copy()
    started = sheet.spring_rest_length[aux].copy()
    assert np.isfinite(target).sum() > 40 and np.all(started[np.isfinite(target)] > target[
        np.isfinite(target)])
    worst = 0.0
    for _ in range(120):
        simulator.step_frame()
        worst = max(worst, simulator.max_strain())
    strain = np.abs(sheet.strain(HINGE))
    assert worst < 0.03 and np.percentile(strain, 99) < 0.004, (worst, strain.max())
    assert not np.isfinite(simulator._memory_target).any()
    assert np.any(sheet.spring_rest_length[aux] < 0.99 * started)
    assert np.all(sheet.spring_rest_length[aux] <= simulator._memory_longest + 1e-15)


def test_check_mesh_reports_broken_invariants():
    sheet = build_flat_sheet(SMALL)
    args = (sheet.vertex_count, sheet.positions, sheet.spring_vertices)
    assert check_mesh(sheet.triangles, *args, spring_kind=sheet.spring_kind) == []
    flipped = sheet.triangles.copy()
    flipped[5] = flipped[5, ::-1]
    assert any('orientation' in p for p in check_mesh(flipped, *args))
    # a bow tie: two triangles that share only a vertex, on their own
    bow = np.array([[0, 1, 17], [1, 2, 19]], dtype=np.int32)
    assert any('non-manifold' in p for p in check_mesh(bow, *args))
    kinds = sheet.spring_kind.copy()
    kinds[np.flatnonzero(kinds == HINGE)[0]] = AUX
    assert any('HINGE' in p for p in check_mesh(sheet.triangles, *args, spring_kind=kinds))
    bend = sheet.spring_vertices.copy()
    bend[np.flatnonzero(kinds == BEND)[0]] = (0, sheet.vertex_count - 1)
    assert any('BEND' in p for p in check_mesh(sheet.triangles, sheet.vertex_count,
                                               sheet.positions, bend,
                                               spring_kind=sheet.spring_kind))
    squashed = sheet.positions.copy()
    squashed[sheet.triangles[0]] = squashed[sheet.triangles[0][0]]
    assert any('degenerate' in p for p in check_mesh(sheet.triangles, sheet.vertex_count,
                                                     squashed, sheet.spring_vertices))
    edges, _ = mesh_edges(sheet.triangles, sheet.vertex_count)
    assert len(edges) == np.sum(sheet.spring_kind == HINGE)


# -------------------------------------------------------------------------- the squeeze
def assert_squeezes_keep_a_set(squeeze) -> None:
    """Seeds 0–4 at 65², one sub-step: the relaxed sheet keeps a set, 2.5 mm at the median
    and beyond the 1 mm an undamaged sheet must relax within at every seed. The squeeze is
    chaotic: a seed's figure moves with round-off (seed 0 gave 3.42 mm, then 2.06 mm once
    folds updated the factors in place; seeds 0–4 then: 2.06, 3.15, 3.74, 9.49, 3.52 mm),
    so one seed is not the measure."""
    relaxed = [squeeze(grid=65, seed=seed)['relaxed_deviation_m'] for seed in range(5)]
    assert np.median(relaxed) >= 2.5e-3 and min(relaxed) > 1e-3, relaxed


@pytest.mark.slow
def test_squeeze_keeps_its_damage_and_rubber_springs_back(squeeze):
    """Issue 3's check, at the default grid (65²) and seed: the relaxed sheet keeps what
    it remembers (creases, plastic set: metrics.relax keeps the rest shape). Measured on
    65², seed 0: 3.97 mm with damage (seeds 0–4: 2.6–7.4 mm; before a memory gave its
    pull where the paper at its ends is held beyond twice the band, 3.59 mm and
    3.6–5.8 mm), 0.00 mm without. Issue 3
    asked for 5 mm; seed 0 gave 6.24 mm until the table's contacts were held exactly in
    the bending solve (seeds 0–4 then: 3.2–7.3 mm): the set a squeeze leaves depends on
    the seed that much (docs/contact.md). Since the strain band lets a gripped sheet
    buckle (2026-11-29) seed 0 keeps 10.78 mm (seeds 0-4: 9.47-10.78 mm) with no break:
    its set is plastic, where the sheet bends round the fingertips' fronts."""
    damaged = squeeze(grid=65)
    rubber = squeeze(enabled=False, grid=65)
    assert_squeezes_keep_a_set(squeeze)
    assert damaged['relaxed_deviation_m'] > 5e-3, damaged  # issue 3 asked 5 mm
    assert rubber['relaxed_deviation_m'] < 1e-5, rubber  # issue 3 asks < 1 mm
    assert rubber['breaks'] == rubber['folds'] == 0
    for metrics in (damaged, rubber):
        assert metrics['mesh_valid'] and metrics['problems'] == [], metrics['problems']
        assert metrics['mass_conserved']
        assert not metrics['nan']


@pytest.mark.slow
@pytest.mark.parametrize('seed', [0, 1, 4])
def test_a_break_never_puts_its_vertex_into_a_fingertip_or_under_the_table(seed):
    """A break lifts its new vertex to the side the sheet bulges; in the squeeze that side
    was at times inside a fingertip (33², seeds 0, 1, 3: 2.5, 2.2, 2.6 mm deep) or under
    the table (65², seed 0: 0.6 mm), the squeeze's only penetrations. Issue 13 asks no
    vertex deeper than 0.5 mm; now none is (Simulator._keep_creases_out). Seeds whose
    squeeze breaks (1, 3 and 8 breaks since Eq. 7 is drawn as a hazard; seed 3 none),
    without the membrane that keeps a squeezed sheet from crushing (with it, 0-1 break)."""
    scenario = scenario_from_mapping(with_overrides(squeeze_mapping(33, membrane=False),
                                                    seed=seed, duration=3.0))
    simulator = build_simulator(scenario)
    dt = scenario.config.solver.dt
    deepest = 0.0
    for frame in range(scenario.frame_count):
        simulator.set_probes(*scenario.probe_inputs((frame + 1) * dt))
        simulator.step_frame()
        deepest = max(deepest, simulator.max_probe_penetration(),
                      simulator.max_table_penetration())
    assert simulator.breaks > 0
    assert deepest < 5e-4, deepest


@pytest.mark.slow
def test_same_seed_same_damage_other_seed_other_damage(squeeze):
    # without the membrane: with it the 33² squeeze rarely breaks, and a run without damage
    # events is the same at every seed
    first = squeeze(seed=5, relax=False, membrane=False)
    second = run_squeeze(seed=5, relax=False, membrane=False)  # run again, not from the cache
    other = squeeze(seed=6, relax=False, membrane=False)
    for key in ('final_positions_sha256', 'breaks', 'folds'):
        assert first[key] == second[key], key
    assert other['final_positions_sha256'] != first['final_positions_sha256']
    assert (other['breaks'], other['folds']) != (first['breaks'], first['folds']) \
        or other['final_positions_sha256'] != first['final_positions_sha256']


@pytest.mark.slow
def test_squeeze_keeps_a_set_with_one_and_with_four_substeps(squeeze):
    """The squeeze's lasting damage is mostly plastic set where the sheet bends sharply
    at the fingertips' fronts (DamageConfig.yield_curvature: 100–200 /m there), with a few
    breaks: at 65², seed 0, it keeps a set with 1 and with 4 sub-steps. Measured with
    the table's contacts held exactly in the bending solve: relaxed 3.59 mm, 2 breaks,
    42 folds with 1 sub-step; 1.30 mm, no break, 7 folds with 4, where the sheet arches
    smoothly instead of folding (2026-11-26, memories giving their pull beyond twice the
    band: 3.97 mm, 2 breaks, 84 folds; 1.15 mm, no break, 7 folds; before that: 6.24 and
    1.25 mm;
    with hinges for bending, before issue 14: 5.97 and 3.71 mm). Since the table's friction
    acts while probes push and the strain band lets a gripped sheet buckle (2026-11-29) the
    four sub-steps keep 0.52 mm (seeds 0-4: 0.52-1.07 mm; 1.06-1.66 mm on the frictionless
    table before), with 1 sub-step 10.78 mm; an undamaged sheet relaxes to 0.00 mm. How much
    depends on the sub-step count and the seed: README, known limitations."""
    one = squeeze(substeps=1, grid=65)
    four = squeeze(substeps=4, grid=65)
    assert_squeezes_keep_a_set(squeeze)
    assert four['relaxed_deviation_m'] > 2.5e-4, four
    for metrics in (one, four):
        assert metrics['breaks'] < 40 and metrics['mesh_valid'], metrics


def crush_crumpled_sheet(simulator: Simulator, frames: int) -> None:
    """Crumple ``simulator``'s sheet, then press a 2 cm probe into it by 0.2 mm a frame."""
    simulator.crumple(60, seed=2)
    centre = np.array([[0.0, 0.0, 0.02]])
    for frame in range(frames):
        centre[0, 2] = 0.02 - 0.0002 * frame
        simulator.set_probes(centre, [0.02], [True])
        simulator.step_frame()


def crushed_crumpled_sheet_breaks(fragility: float) -> int:
    """Breaks when a 2 cm probe presses 6 mm into a crumpled 17² sheet on the table, with
    the paper's own solver: its springs are forces, so Eq. 7 sees the literal l / l0."""
    simulator = Simulator(SimulationConfig(
        sheet=SMALL, solver=SolverConfig(method='paper', substeps=4),
        contact=ContactConfig(ground_enabled=True), damage=DamageConfig(fragility=fragility)))
    crush_crumpled_sheet(simulator, 30)
    return simulator.breaks


@pytest.mark.slow
def test_breaks_fall_as_fragility_rises():
    """Paper Fig. 13: small φ is fragile, large φ rubbery, Eq. 7 as the paper has it
    (measured: 5844, 2710, 1359, 534, 380 breaks; 7702, 2657, 1100, 512, 236 while the
    crumple still lifted half its folds into the table, which the paper's solver then
    pushed out: DamageModel.crumple's floor)."""
    breaks = [crushed_crumpled_sheet_breaks(phi) for phi in (0.5, 0.75, 1.0, 1.5, 2.0)]
    assert all(a > b for a, b in zip(breaks, breaks[1:])), breaks
    assert breaks[0] > 10 * max(breaks[-1], 1), breaks


def test_ridges_grow_with_area_conservation():
    """Paper Fig. 12: small ψ bends like a bank note, large ψ creases like card board."""
    heights = []
    for psi in (0.0, 0.5, 1.0, 1.5):
        mapping = with_overrides(builtin_mapping('crumple'), grid=17, duration=1.0)
        mapping['crumple'] = 120
        mapping['damage'] = {'area_conservation': psi, 'crumple_fold_fraction': 0.0,
                             'fold_threshold': 0.0}
        scenario = scenario_from_mapping(mapping)
        simulator = build_simulator(scenario)
        run_scenario(scenario, simulator=simulator)
        heights.append(float(ridge_heights(simulator.sheet.positions,
                                           simulator.damage.creases).mean()))
    assert heights[0] < 1e-4, heights
    assert all(a < b for a, b in zip(heights, heights[1:])), heights


# ------------------------------------------------------------------------ no false damage
def test_a_sheet_resting_on_the_table_for_a_minute_does_not_break():
    config = SimulationConfig(sheet=SMALL, contact=ContactConfig(ground_enabled=True),
                              damage=DamageConfig(fragility=0.5))
    simulator = Simulator(config)
    for _ in range(60 * 60):
        simulator.step_frame()
    assert simulator.breaks == 0 and simulator.folds == 0
    assert simulator.sheet.vertex_count == SMALL.nx * SMALL.ny
    assert plane_deviation(simulator.sheet.positions) < 1e-6


def test_at_the_vertex_cap_damage_stops_with_one_warning(caplog):
    cap = 33 * 33 + 12
    mapping = squeeze_mapping(max_vertices=cap, fragility=0.5)  # fragile: it reaches the cap
    mapping['duration'] = 3.0
    scenario = scenario_from_mapping(mapping)
    simulator = build_simulator(scenario)
    with caplog.at_level(logging.WARNING, logger='paper_sim_ros.core.damage'):
        metrics = run_scenario(scenario, simulator=simulator)
        simulator.crumple(50, seed=1)
    warnings = [r for r in caplog.records if 'vertex cap' in r.getMessage()]
    assert len(warnings) == 1, [r.getMessage() for r in caplog.records]
    assert simulator.sheet.vertex_count == cap
    assert metrics['breaks'] <= 12 and metrics['mesh_valid'] and not metrics['nan']


# ------------------------------------------------------------------- other solvers, config
def test_damage_works_with_the_papers_solver():
    config = SimulationConfig(sheet=SMALL, solver=SolverConfig(method='paper', substeps=4),
                              contact=ContactConfig(ground_enabled=True))
    simulator = Simulator(config)
    mass = exact_mass(simulator.sheet)
    crush_crumpled_sheet(simulator, 90)
    assert not simulator.nan_seen
    assert mesh_problems(simulator.sheet) == []
    assert exact_mass(simulator.sheet) == mass
    assert simulator.breaks >= 30


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_a_sheet_switched_to_the_constrained_solver_breaks_only_where_probes_push(seed):
    """Crumpled under the paper's force solver, then run on by the constrained one without a
    probe: Eq. 7 reads what that solver says compression is (what probes impose), not the
    lengths of a crumpled sheet held in its strain band. No new break, the mesh valid."""
    config = SimulationConfig(sheet=SheetConfig(nx=25, ny=19, width=0.17, height=0.13),
                              solver=SolverConfig(method='paper'), seed=seed,
                              contact=ContactConfig(ground_enabled=True))
    simulator = Simulator(config)
    simulator.crumple(60, seed=seed)
    for _ in range(10):
        simulator.step_frame()
    breaks = simulator.breaks
    constrained = SolverConfig(method='constrained', dt=1.0 / 30.0)
    simulator.reconfigure(replace(config, solver=constrained))
    for _ in range(30):
        simulator.step_frame()
    assert simulator.breaks == breaks, (breaks, simulator.breaks)
    assert mesh_problems(simulator.sheet) == [] and not simulator.nan_seen


def test_damage_config_refuses_bad_values_with_reasons():
    for field, value in (('fragility', 0.0), ('fragility', float('nan')),
                         ('area_conservation', -0.1), ('fold_threshold', 1.0),
                         ('check_rate', 0.0), ('compression_floor', 1.0),
                         ('min_breakable_length', -1.0), ('max_vertices', 2),
                         ('min_crease_ratio', 0.0), ('crumple_fold_fraction', 1.5),
                         ('enabled', 'yes')):
        with pytest.raises(ValueError, match=field):
            DamageConfig(**{field: value})
    with pytest.raises(ValueError, match='crumple'):
        scenario_from_mapping({'crumple': -3})
    with pytest.raises(ValueError, match='unknown DamageConfig keys: nonsense'):
        scenario_from_mapping({'damage': {'nonsense': 1}})


def test_material_presets_are_valid_and_ordered_like_fig_12_and_13():
    assert set(MATERIAL_PRESETS) >= {'printer_paper', 'cardboard', 'banknote'}
    for name in MATERIAL_PRESETS:
        preset = material_preset(name)
        config = scenario_from_mapping({'sheet': preset['sheet'], 'damage': preset['damage']})
        assert config.config.damage.enabled
    damage = {name: DamageConfig(**material_preset(name)['damage']) for name in MATERIAL_PRESETS}
    assert damage['cardboard'].area_conservation > damage['printer_paper'].area_conservation \
        > damage['banknote'].area_conservation
    assert damage['banknote'].fragility > damage['printer_paper'].fragility \
        > damage['cardboard'].fragility
    with pytest.raises(ValueError, match='unknown material'):
        material_preset('papyrus')


def test_headless_no_damage_flag_and_metrics(tmp_path, capsys):
    import json
    path = tmp_path / 'crumple.json'
    assert main(['--scenario', 'crumple', '--grid', '17', '--duration', '0.5',
                 '--metrics-json', str(path)]) == 0
    metrics = json.loads(path.read_text())
    assert metrics['breaks'] + metrics['folds'] >= 300 and metrics['mesh_valid']
    assert metrics['relaxed_deviation_m'] > 1e-3
    assert main(['--scenario', 'crumple', '--grid', '17', '--duration', '0.5', '--no-damage',
                 '--metrics-json', str(path)]) == 0
    metrics = json.loads(path.read_text())
    assert metrics['breaks'] == metrics['folds'] == 0 and metrics['mesh_valid']
    assert metrics['relaxed_deviation_m'] < 1e-6
    capsys.readouterr()


def _spun_crumpled_sheet(grid: int, seed: int, **solver) -> Simulator:
    """A crumpled sheet without gravity, set spinning and drifting as a rigid body."""
    mapping = with_overrides(builtin_mapping('crumple'), grid=grid, seed=seed)
    mapping['solver'] = {'gravity': [0.0, 0.0, 0.0], **solver}
    simulator = build_simulator(scenario_from_mapping(mapping))
    sheet = simulator.sheet
    centre = np.average(sheet.positions, axis=0, weights=sheet.vertex_mass)
    spin = np.array([0.4, -0.3, 1.1])  # rad/s
    sheet.velocities[:] = np.cross(spin, sheet.positions - centre) + [0.02, 0.0, -0.01]
    return simulator


def _momenta(simulator: Simulator) -> tuple[np.ndarray, np.ndarray]:
    sheet = simulator.sheet
    return (np.sum(sheet.vertex_mass[:, None] * sheet.velocities, axis=0),
            kernels.angular_momentum(sheet.positions, sheet.velocities, sheet.vertex_mass))


@pytest.mark.parametrize('seed, option', [(0, None), (5, None), (0, 'energy_restoring'),
                                          (0, 'length_projection'), (0, 'membrane_weight')])
def test_a_crumpled_sheet_in_free_flight_keeps_its_momentum(seed, option):
    """Issue 14: a damaged sheet with no gravity, no drag and nothing touching it keeps its
    linear and angular momentum (the angular about its centre of mass), relative drift
    under 1e-6 over 5 s; without the correction (Simulator._keep_angular_momentum) the
    sub-steps' own torque changed it by tens of percent. Restoring energy scales only the
    velocities less the rigid motion, so it keeps them too; the length projection moves
    the ends of a spring along it in inverse proportion to their masses; the membrane's
    terms come in equal and opposite pairs."""
    options = {option: True} if option else {}
    if option == 'membrane_weight':  # in every sub-step: nothing squeezes this sheet
        options = {'membrane_weight': 30.0, 'membrane_scope': 'always'}
    simulator = _spun_crumpled_sheet(17, seed, air_damping=0.0, air_density=0.0, **options)
    linear, angular = _momenta(simulator)
    for _ in range(300):
        simulator.step_frame()
    linear_now, angular_now = _momenta(simulator)
    assert np.linalg.norm(linear_now - linear) < 1e-6 * np.linalg.norm(linear)
    assert np.linalg.norm(angular_now - angular) < 1e-6 * np.linalg.norm(angular)
    assert not simulator.nan_seen and mesh_problems(simulator.sheet) == []


@pytest.mark.parametrize('seed', [0, 1])
def test_a_sheet_crumpled_on_the_table_rests_on_it_unstrained(seed):
    """The node's defaults: a sheet flat on the table, crumpled 20 events at a time (the
    paper/crumple service). A fold or break that went down into the table comes up instead,
    so the crumpled rest shape is one the sheet can take on the table (it rested 16-23 %
    strained, 34-48 % on the way: 65², 5 calls, seeds 0-2; now 0.30-0.31 % and 0.93-1.25 %)."""
    scenario = load_scenario({'name': 'crumpled_on_the_table', 'duration': 1.0, 'seed': seed,
                              'sheet': {'nx': 65, 'ny': 65},
                              'contact': {'ground_enabled': True}})
    simulator = build_simulator(scenario)
    strain = 0.0
    for call in range(3):
        simulator.crumple(20, 100 * seed + call)
        assert simulator.sheet.positions[:, 2].min() >= 0.0, 'nothing crumpled into the table'
        for _ in range(30):
            simulator.step_frame()
            strain = max(strain, simulator.max_strain())
    for _ in range(30):
        simulator.step_frame()
    assert strain < 0.03, strain
    assert np.abs(simulator.sheet.strain(HINGE)).max() < 0.01
    assert not simulator.nan_seen and mesh_problems(simulator.sheet) == []


@pytest.mark.parametrize('seed', [0, 2])
def test_a_crumpled_sheet_hung_from_a_clamp_is_not_held_to_the_flat_sheets_reach(seed):
    """A crumple's plastic set lengthens the paper's path from the clamp: the long-range
    attachments must allow what the crumpled rest shape reaches, not the flat sheet's
    distances (held to those, the springs by the clamp rested compressed: 33², 150 events,
    seeds 0–3, 8.6–15.3 % after 1 s; now 0.37–0.47 %)."""
    scenario = load_scenario({'name': 'crumpled_hanging', 'duration': 1.0, 'seed': seed,
                              'pin': 'short_edge', 'crumple': 150,
                              'sheet': {'nx': 33, 'ny': 33, 'elevation': 0.5}})
    simulator = build_simulator(scenario)
    for _ in range(scenario.frame_count):
        simulator.step_frame()
    strain = np.abs(simulator.sheet.strain(HINGE))
    assert strain.max() < 0.01, strain.max()
    assert not simulator.nan_seen and mesh_problems(simulator.sheet) == []


@pytest.mark.slow
@pytest.mark.parametrize('seed', [0, 1, 2, 3, 4])
def test_a_crumpled_sheet_comes_to_rest(seed):
    """Issue 14: the `crumple` scenario at 65² (no gravity, air drag 3/s): from 3 s on the
    99th-percentile vertex speed is under 1 mm/s (it was 0.2 m/s: the sheet spun up on
    the sub-steps' own torque and never came to rest), and it stays so."""
    scenario = load_scenario('crumple', grid=65, seed=seed)
    simulator = build_simulator(scenario)
    metrics = run_scenario(scenario, simulator=simulator)
    assert metrics['final_p99_speed_mps'] < 1e-3, metrics['final_p99_speed_mps']
    for _ in range(60):
        simulator.step_frame()
    speed = np.linalg.norm(simulator.sheet.velocities, axis=1)
    assert np.percentile(speed, 99) < 1e-3
    # and it is never stretched, at rest or on the way: random damage is plastic and a
    # crease's memory pulls only as far as the paper follows (Simulator._yield_memory).
    # Measured, seeds 0–4: over the run 1.09–1.63 % (1.00–1.72 % over seeds 0–9), at rest
    # p99 |HINGE strain| 0.30 %, the worst 0.33–0.46 % (it was 79 % and ≥ 15.8 % p99,
    # ≥ 3 900 springs beyond 1 %; then 1.1–2.3 % over the run and 0.30–1.08 % at rest,
    # until memories stopped pulling, and gave their pull, where the paper at their ends is
    # held beyond twice the band). Issue 13 asks < 2 % over the run, issue 14 < 1 % at rest.
    strain = np.abs(simulator.sheet.strain(HINGE))
    assert metrics['max_strain'] < 0.02, metrics['max_strain']
    assert np.percentile(strain, 99) < 0.004
    assert strain.max() < 0.01, strain.max()
