"""Dense playback with the magnetisation fixed; plans under perturbed models."""

import pathlib

import numpy as np
import pytest
from tentacle_model.model import TentacleModel
from tentacle_model.tentacle_spec import load_tentacle
from tentacle_planner.mismatch import perturbed
from tentacle_planner.optimise import Constraints, optimise, Plan, Problem
from tentacle_planner.playback import dense_lengths, playback
from tentacle_planner.robustness import perturbed_problems, report, RobustProblem

ROOT = pathlib.Path(__file__).resolve().parents[3]
KEY_M = (0.02, 0.03, 0.04, 0.05)


@pytest.fixture(scope='module')
def braided():
    return load_tentacle(ROOT / 'config' / 'tentacles' / 'braided_chapter5.yaml')


def truth(spec):
    """Return (model, directions, field(l) for any inserted length l): a known answer."""
    model = TentacleModel(spec, dof=3, sublinks=1)
    rng = np.random.default_rng(5)
    directions = rng.normal(size=(5, 3))
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    key_fields = rng.uniform(-8e-3, 8e-3, (len(KEY_M), 3))

    def field(inserted_m):
        return np.array([np.interp(inserted_m, KEY_M, key_fields[:, a]) for a in range(3)])
    return model, directions, field


def run(model, directions, field, lengths):
    """Return the points at each length, warm-started along the insertion."""
    out, state, previous = {}, None, None
    for length in lengths:
        chain = model.chain(length)
        moments = np.linalg.norm(chain.moments_a_m2, axis=1)[:, None] * directions[
            chain.segment_index]
        if state is not None:
            state = model.carry(state, previous, length)
        solution = model.solve(length, field(length), state, moments)
        out[round(length, 12)] = solution.points_m
        state, previous = solution.state, length
    return out


def known_plan(spec, **options):
    """Return (model, directions, field, problem, plan): truth's plan and its key steps."""
    model, directions, field = truth(spec)
    points = run(model, directions, field, KEY_M)
    problem = Problem(model, KEY_M, [points[round(k, 12)] for k in KEY_M],
                      Constraints(max_field_t=0.02), **options)
    return model, directions, field, problem, problem.plan(
        problem.pack(directions, [field(k) for k in KEY_M]))


def test_dense_lengths_include_every_key_step():
    assert dense_lengths([0.0025, 0.004], 0.001) == [0.001, 0.002, 0.0025, 0.003, 0.004]


def test_playback_recovers_every_intermediate_field(braided):
    model, directions, field = truth(braided)
    lengths = dense_lengths(list(KEY_M), 0.002)
    points = run(model, directions, field, lengths)
    constraints = Constraints(max_field_t=0.02)
    problem = Problem(model, KEY_M, [points[round(k, 12)] for k in KEY_M], constraints)
    key_plan = problem.plan(problem.pack(directions, [field(k) for k in KEY_M]))
    assert key_plan.shape_rms_m < 1e-9
    steps, flags = playback(model, key_plan, lambda chain, length: points[round(length, 12)],
                            0.002, constraints)
    assert [s.inserted_m for s in steps] == lengths and flags == []
    for step in steps:
        assert step.shape_rms_m < 1e-7 * braided.length_m
        assert step.field_t == pytest.approx(field(step.inserted_m), abs=1e-7)


def test_a_field_change_over_the_limit_between_dense_steps_is_fitted_within_it(braided):
    model, directions, field = truth(braided)
    lengths = dense_lengths(list(KEY_M), 0.002)
    points = run(model, directions, field, lengths)
    changes = np.abs(np.diff([field(length) for length in lengths], axis=0)).max(axis=1)
    limit = float(np.median(changes))  # about half of the truth's dense steps change by more
    constraints = Constraints(max_field_t=0.02, max_field_change_t=limit)
    problem = Problem(model, KEY_M, [points[round(k, 12)] for k in KEY_M], constraints)
    key_plan = problem.plan(problem.pack(directions, [field(k) for k in KEY_M]))
    steps, flags = playback(model, key_plan, lambda chain, length: points[round(length, 12)],
                            0.002, constraints)
    played = np.abs(np.diff([s.field_t for s in steps], axis=0)).max(axis=1)
    assert played.max() <= limit * (1 + 1e-9)   # what the rig would refuse is never planned
    assert flags == []      # each such step fitted again within the change the rig allows
    assert all(s.converged and s.stability > 0 for s in steps)
    # The truth's own fields, each clipped to the change from the step before, do no better.
    clipped, previous, start = [], None, None
    for length in lengths:
        b = field(length) if previous is None else np.clip(field(length), previous - limit,
                                                           previous + limit)
        one = Problem(model, [length], [points[round(length, 12)]], directions=directions,
                      start=start)
        x = one.pack(directions, [b])
        clipped.append(one.plan(x).steps[0].shape_rms_m)
        start, previous = (one.simulate(x)[-1].state, length), b
    assert np.mean([s.shape_rms_m for s in steps]) <= np.mean(clipped) + 1e-12


def test_perturbations_change_what_they_say(braided):
    soft = perturbed(braided, stiffness=0.8)
    assert soft.segments[0].modulus_pa[0] == pytest.approx(0.8 * braided.segments[0]
                                                           .modulus_pa[0])
    moved = perturbed(braided, sideways_m=0.5e-3)
    assert np.linalg.norm(moved.base_position_m - braided.base_position_m) == pytest.approx(
        0.5e-3)
    turned = perturbed(braided, turn_rad=np.radians(2.0))
    cos = turned.base_rotation[:, 0] @ braided.base_rotation[:, 0]
    assert np.degrees(np.arccos(cos)) == pytest.approx(2.0)


def test_robustness_report_and_robust_plan(braided):
    _, _, _, problem, nominal = known_plan(braided)
    problems = perturbed_problems(problem)
    rows = report(problems, nominal)
    assert [r[0] for r in rows][0] == 'nominal' and len(rows) == 7
    assert rows[0][2] < 1e-9 and all(r[2] > 1e-6 for r in rows[1:])
    robust = optimise(RobustProblem(problems), seed=0, starts=0,
                      initial=problem.pack(nominal.directions, nominal.fields_t))
    assert isinstance(robust, Plan)
    robust_rows = report(problems, robust)
    worst = max(r[2] for r in rows)
    robust_worst = max(r[2] for r in robust_rows)
    assert robust_worst < worst  # planning against them all lowers the worst case ...
    assert robust_rows[0][2] >= rows[0][2]  # ... at a price in the nominal model


def test_the_scene_mismatch_row_plays_the_plan_on_the_rig_the_sim_makes(braided):
    from tentacle_planner.mismatch import Mismatch
    from tentacle_planner.robustness import on_the_rig
    model, directions, field, problem, nominal = known_plan(braided)
    assert on_the_rig(problem, Mismatch()) == []               # no mismatch: no row
    # Every coil 10% strong acts as 10% more remanence (m x B; no magnet interaction here):
    # the row agrees with the perturbation of the report made another way.
    rig = on_the_rig(problem, Mismatch(actuation_matrix_factor=(1.1, 1.1, 1.1)))
    rows = report(perturbed_problems(problem), nominal, rig=rig)
    assert rows[-1][0] == "the scene's mismatch (coils x[1.1, 1.1, 1.1])"
    stronger = {name: total for name, _, total, _ in rows}['remanence x1.1']
    assert rows[-1][2] == pytest.approx(stronger, rel=1e-6) and rows[-1][2] > 1e-6
    # One coil out: only the fields on that axis change, so the shape changes.
    one = report([], nominal, rig=on_the_rig(problem, Mismatch(
        actuation_matrix_factor=(1.0, 1.0, 1.5))))
    assert one[0][2] != pytest.approx(rows[-1][2])


def test_the_report_says_how_deep_each_model_runs_into_an_obstacle(braided):
    from tentacle_planner.clearance import clearance
    from tentacle_planner.optimise import KeepOff
    from tentacle_planner.scene import Sphere
    _, _, _, plain, unaware = known_plan(braided)
    x = plain.pack(unaware.directions, unaware.fields_t)
    # A ball 0.05 mm off the nominal tip's capsule, on the side a 10% stronger magnet bends to.
    stronger = dict(perturbed_problems(plain))['remanence x1.1'].plan(x).steps[-1].points_m[-1]
    tip = plain.targets[-1][-1]
    radius_m, body_m = 1e-3, braided.segments[-1].radius_m
    ball = Sphere(tip + (stronger - tip) / np.linalg.norm(stronger - tip)
                  * (radius_m + body_m + 5e-5), radius_m)
    _, _, _, problem, nominal = known_plan(braided, keep_off=KeepOff(spheres=(ball,)))
    rows = {name: depth for name, _, _, depth in report(perturbed_problems(problem), nominal)}
    assert rows['nominal'] == 0.0 and rows['remanence x1.1'] > 0.0
    for name, p in perturbed_problems(problem):   # clearance.py's own account of each model
        played = p.plan(x)
        gap = min(clearance(s.points_m, s.link_radii_m, (ball,))[0] for s in played.steps)
        assert rows[name] == pytest.approx(max(0.0, -gap), abs=1e-12)


def test_the_rig_row_played_densely_runs_every_step_from_the_one_before(braided):
    from tentacle_planner.mismatch import Mismatch
    from tentacle_planner.optimise import Step
    from tentacle_planner.robustness import on_the_rig, played_densely
    model, directions, field, problem, nominal = known_plan(braided)
    coils = np.array([1.05, 1.0, 0.95])
    rig = on_the_rig(problem, Mismatch(remanence_factor=0.9, actuation_matrix_factor=coils))
    lengths = dense_lengths(list(KEY_M), 0.002)
    steps = [Step(length, field(length), None, 0.0, 0.0, 0.0, True) for length in lengths]
    [(name, per_step, _, depth)] = played_densely(rig, nominal, steps,
                                                  lambda s: float(s.points_m[-1][1]))
    assert name.endswith(', every playback step') and depth == 0.0   # nothing to touch
    # The mismatched tentacle run here step by step, warm-started, in the coils' fields:
    truth_tips = run(rig[0][1].model, directions, lambda length: field(length) * coils,
                     lengths)
    assert per_step == pytest.approx([truth_tips[round(length, 12)][-1][1]
                                      for length in lengths], abs=1e-12)
    assert len(per_step) == len(lengths) > len(KEY_M)
