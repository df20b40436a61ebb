"""The planner's optimisation against plans with a known answer, and its exact gradient."""

import math
import pathlib

import numpy as np
import pytest
from tentacle_model.model import TentacleModel
from tentacle_model.tentacle_spec import load_tentacle
from tentacle_planner.optimise import (Constraints, KeepOff, leading, optimise, Problem,
                                       side_by_side, STABILITY_WEIGHT)
from tentacle_planner.scene import Sphere

ROOT = pathlib.Path(__file__).resolve().parents[3]
STEPS_M = (0.02, 0.03, 0.04, 0.05)


@pytest.fixture(scope='module')
def braided():
    return load_tentacle(ROOT / 'config' / 'tentacles' / 'braided_chapter5.yaml')


def known_plan(spec, dof, constraints, seed=3):
    """Return (model, true x, targets): targets are what the model does for the true x."""
    model = TentacleModel(spec, dof=dof, sublinks=1)
    blank = [np.zeros((model.chain(s).size + 1, 3)) for s in STEPS_M]
    problem = Problem(model, STEPS_M, blank, constraints)
    rng = np.random.default_rng(seed)
    x = rng.uniform(-1.0, 1.0, problem.size)
    x[problem.size - len(STEPS_M) * problem.field_size:] *= 10.0  # +-10 mT
    solutions = problem.simulate(x)
    assert all(s.equilibrium.converged and s.equilibrium.stability > 0 for s in solutions)
    return model, x, [s.points_m for s in solutions]


def central_gradient(problem, x, h):
    """Return the central-difference gradient of problem.objective at x."""
    return np.array([(problem.objective(x + e)[0] - problem.objective(x - e)[0]) / (2 * h)
                     for e in np.eye(len(x)) * h])


@pytest.mark.parametrize('dof', [1, 3])
def test_the_gradient_is_exact(braided, dof):
    constraints = Constraints(planar_magnetisation=dof == 1)
    model, _, targets = known_plan(braided, dof, constraints)
    problem = Problem(model, STEPS_M, targets, constraints)
    x = np.random.default_rng(7).uniform(-1.0, 1.0, problem.size)
    value, gradient = problem.objective(x)
    assert value > 1e-4
    fd = central_gradient(problem, x, 1e-6)
    assert gradient == pytest.approx(fd, abs=1e-6 * np.abs(fd).max())


@pytest.mark.parametrize('dof', [1, 3])
def test_the_stability_penalty_and_its_gradient(braided, dof):
    constraints = Constraints(planar_magnetisation=dof == 1)
    model, x, targets = known_plan(braided, dof, constraints)
    plain = Problem(model, STEPS_M, targets, constraints, min_margin=0)
    # Above every step's margin the penalty applies: STABILITY_WEIGHT (1 - margin / limit).
    strict = Problem(model, STEPS_M, targets, constraints, min_margin=50.0)
    assert plain.objective(x)[0] == pytest.approx(0.0, abs=1e-18)
    margins = [strict.margin(s, b) for s, b in zip(strict.simulate(x), strict.unpack(x)[1])]
    assert all(0 < m < 50 for m in margins)
    expected = sum((STABILITY_WEIGHT * (1 - m / 50.0)) ** 2 for m in margins)
    value, gradient = strict.objective(x)
    assert value == pytest.approx(expected, rel=1e-9)
    fd = central_gradient(strict, x, 1e-4)
    assert gradient == pytest.approx(fd, abs=2e-3 * np.abs(fd).max())


def test_a_reachable_plan_is_found_exactly_and_reproduced_by_its_seed(braided):
    constraints = Constraints(max_field_t=0.02)
    model, x_true, targets = known_plan(braided, 3, constraints)
    problem = Problem(model, STEPS_M, targets, constraints)
    plan = optimise(problem, seed=1, starts=4)
    assert plan.shape_rms_m < 1e-6 * braided.length_m
    assert plan.flags == []
    assert all(step.stability > 0 and step.converged for step in plan.steps)
    directions, fields = problem.unpack(x_true)
    # The answer, not just a fit; up to the one symmetry of a uniform field without
    # gravity: every moment and the field reversed together leave every torque m x B.
    sign = np.sign(plan.fields_t.ravel() @ fields.ravel())
    assert sign * plan.fields_t == pytest.approx(fields, abs=1e-6)
    # The proximal segment is in at the last step only: one field cannot tell its direction
    # from another whose difference is along that field (m x B alike). The others are fixed.
    assert sign * plan.directions[1:] == pytest.approx(directions[1:], abs=1e-5)
    # The same seed, its starts fitted side by side in a forked worker: the same plan.
    again = optimise(Problem(model, STEPS_M, targets, constraints), seed=1, starts=4,
                     workers=2)
    assert np.array_equal(again.fields_t, plan.fields_t)
    assert np.array_equal(again.directions, plan.directions)
    assert again.evaluations >= plan.evaluations - 1   # the worker's evaluations counted


def test_field_limits_hold_and_a_target_out_of_reach_is_approached(braided):
    # The known plan needs up to 10 mT; with 4 mT per axis the best plan sits on the limit.
    model, _, targets = known_plan(braided, 3, Constraints())
    constraints = Constraints(max_field_t=0.004, max_field_change_t=0.003,
                              max_total_field_t=0.006)
    problem = Problem(model, STEPS_M, targets, constraints)
    plan = optimise(problem, seed=0, starts=3)
    fields = plan.fields_t
    assert np.max(np.abs(fields)) <= 0.004 * (1 + 1e-6)
    assert np.max(np.linalg.norm(fields, axis=1)) <= 0.006 * (1 + 1e-6)
    assert np.max(np.abs(np.diff(fields, axis=0))) <= 0.003 * (1 + 1e-6)
    assert plan.flags == [] or all('unstable' in f for f in plan.flags)
    assert problem.violations(plan.directions, fields) == []


def test_the_tip_driven_baseline_plans_fields_only(braided):
    model, _, targets = known_plan(braided, 3, Constraints())
    constraints = Constraints(max_field_t=0.02, tip_driven=True)
    problem = Problem(model, STEPS_M, targets, constraints)
    assert problem.size == 3 * len(STEPS_M)
    baseline = optimise(problem, seed=0, starts=2)
    assert np.all(baseline.directions[:, 0] == 1.0)  # every magnetisation axial
    shaped = optimise(Problem(model, STEPS_M, targets, Constraints(max_field_t=0.02)),
                      seed=1, starts=4)
    assert shaped.shape_rms_m < 0.1 * baseline.shape_rms_m


def test_neighbouring_magnetisations_keep_within_the_angle_limit(braided):
    model, _, targets = known_plan(braided, 1, Constraints(planar_magnetisation=True))
    limit = math.radians(60)
    constraints = Constraints(max_field_t=0.02, planar_magnetisation=True,
                              max_neighbour_angle_rad=limit, distal_axial=True)
    problem = Problem(model, STEPS_M, targets, constraints)
    plan = optimise(problem, seed=0, starts=3)
    d = plan.directions
    angles = [math.acos(np.clip(d[i] @ d[i + 1], -1, 1)) for i in range(len(d) - 1)]
    assert max(angles) <= limit + 1e-4
    assert d[-1] == pytest.approx([1.0, 0.0, 0.0])  # the distal segment axial
    assert np.all(d[:, 2] == 0.0)  # planar magnetisation


@pytest.mark.parametrize('dof', [1, 3])
def test_the_torque_balance_stage_is_zero_at_an_equilibrium_and_its_gradient_exact(braided, dof):
    from tentacle_planner.balance import BalanceProblem
    constraints = Constraints(planar_magnetisation=dof == 1)
    model, x_true, targets = known_plan(braided, dof, constraints)
    balance = BalanceProblem(Problem(model, STEPS_M, targets, constraints))
    r, _ = balance.residuals(x_true)
    if dof == 1:  # a planar target fixes every joint angle: it is the equilibrium itself
        assert np.max(np.abs(r)) < 1e-7
    x = np.random.default_rng(5).uniform(-1.0, 1.0, balance.size)
    value, gradient = balance.objective(x)
    assert value > 1e-3
    fd = central_gradient(balance, x, 1e-6)
    assert gradient == pytest.approx(fd, abs=1e-6 * np.abs(fd).max())


def test_a_plan_staged_on_the_torque_balance_is_verified_in_the_forward_model(braided):
    constraints = Constraints(planar_magnetisation=True, max_field_t=0.02)
    model, _, targets = known_plan(braided, 1, constraints)
    problem = Problem(model, STEPS_M, targets, constraints)
    plan = optimise(problem, seed=1, starts=4, iterations=60, first_stage=True)
    assert plan.flags == [] and plan.shape_rms_m < 1e-6   # reachable: found exactly


def test_the_fields_of_a_backbone_schedule_are_recovered():
    """A given magnetisation, the backbone withdrawn step by step: fields only."""
    spec = load_tentacle(ROOT / 'config' / 'tentacles' / 'vsr_chapter6.yaml')
    model = TentacleModel(spec, dof=1)
    steps, backbones = [0.06] * 3, [0.05, 0.045, 0.04]
    own = np.array([s.magnetisation_a_per_m / np.linalg.norm(s.magnetisation_a_per_m)
                    for s in spec.segments])
    blank = [np.zeros((model.chain(0.06).size + 1, 3))] * 3
    truth = Problem(model, steps, blank, directions=own, backbones_m=backbones)
    assert truth.size == 6                                  # two field axes a step, no more
    x_true = np.array([3.0, 8.0, 1.0, 9.0, -2.0, 10.0])     # mT
    solutions = truth.simulate(x_true)
    for solution, backbone in zip(solutions, backbones):
        supported = solution.chain.s_start_m < backbone - 1e-9   # each step's own backbone
        stiffness = solution.chain.stiffness_n_m[:, 0]
        # An interior joint is EI / h (half of each neighbouring link in series): the
        # backbone's EI adds to the strip's where it reaches (the first free joint is mixed).
        ei = spec.segments[0].bend_stiffness_n_m2[0]
        np.testing.assert_allclose(stiffness[supported][1:], (ei + spec.backbone.stiffness_n_m2)
                                   / 0.0025, rtol=1e-9)
        np.testing.assert_allclose(stiffness[~supported][1:], ei / 0.0025, rtol=1e-9)
        bends = np.abs(solution.state[:, 0])
        assert bends[supported].max() < 0.02 * bends[~supported].max()
    problem = Problem(model, steps, [s.points_m for s in solutions], directions=own,
                      backbones_m=backbones)
    plan = optimise(problem, seed=0, starts=3, iterations=60)
    assert plan.shape_rms_m < 1e-8 and plan.flags == []
    np.testing.assert_allclose(problem.pack(plan.directions, plan.fields_t), x_true, atol=1e-5)
    assert [s.backbone_m for s in plan.steps] == backbones


def obstacle_on(points, link, off_m, radius_m):
    """Return a Sphere beside a link's middle, off_m from its axis surface to surface."""
    from tentacle_planner.scene import Sphere
    a, b = points[link], points[link + 1]
    side = np.cross(b - a, [0.0, 0.0, 1.0])
    side /= np.linalg.norm(side)
    return Sphere((a + b) / 2 + side * (off_m + radius_m), radius_m)


@pytest.mark.parametrize('dof', [1, 3])
def test_the_keep_off_gradient_is_exact(braided, dof):
    from tentacle_planner.optimise import KeepOff
    constraints = Constraints(planar_magnetisation=dof == 1)
    model, x, targets = known_plan(braided, dof, constraints)
    near = obstacle_on(targets[2], 3, 0.0005, 0.002)   # the link's axis 0.5 mm off its surface
    keep_off = KeepOff(spheres=(near,), margin_m=0.002)
    # No stability penalty: its derivative is a forward difference, not exact.
    problem = Problem(model, STEPS_M, targets, constraints, keep_off=keep_off, min_margin=0)
    y = x + np.random.default_rng(5).normal(0.0, 0.05, problem.size)
    plain = Problem(model, STEPS_M, targets, constraints, min_margin=0)
    value, gradient = problem.objective(y)
    assert value > plain.objective(y)[0] + 1e-6                 # within the margin: it counts
    fd = central_gradient(problem, y, 1e-6)
    assert gradient == pytest.approx(fd, abs=1e-6 * np.abs(fd).max())


def test_a_plan_that_keeps_off_moves_clear_of_an_obstacle_the_exact_one_runs_into(braided):
    from tentacle_planner.clearance import clearance
    from tentacle_planner.optimise import fit, KeepOff
    constraints = Constraints(planar_magnetisation=True)
    model, x, targets = known_plan(braided, 1, constraints)
    radii = [braided.segments[i].radius_m for i in model.chain(STEPS_M[2]).segment_index]
    # A ball the exact plan's body runs 0.2 mm into at the third step.
    ball = obstacle_on(targets[2], 3, -0.0002 - radii[3], 0.002)
    unaware = Problem(model, STEPS_M, targets, constraints)
    aware = Problem(model, STEPS_M, targets, constraints,
                    keep_off=KeepOff(spheres=(ball,), margin_m=2e-4))

    def least_gap(problem, solution):
        return min(clearance(s.points_m, [braided.segments[i].radius_m
                                          for i in s.chain.segment_index], [ball])[0]
                   for s in problem.simulate(solution))
    exact = fit(unaware, x)
    kept = fit(aware, x)
    assert least_gap(unaware, exact) < -1e-4                   # touches: 0.2 mm in
    assert least_gap(aware, kept) > 0.0                        # keeps off
    rms = math.sqrt(unaware.objective(kept)[0])                # what keeping off costs
    assert rms < 0.05


def test_the_neighbour_angle_residuals_gradient_is_exact(braided):
    constraints = Constraints(max_neighbour_angle_rad=math.radians(20))
    model, x, targets = known_plan(braided, 3, constraints)
    problem = Problem(model, STEPS_M, targets, constraints, min_margin=0)
    y = x + np.random.default_rng(7).normal(0.0, 0.3, problem.size)
    d = problem.unpack(y)[0]
    assert max(math.degrees(math.acos(np.clip(d[i] @ d[i + 1], -1, 1)))
               for i in range(len(d) - 1)) > 20          # past the limit: the rows count
    free = Problem(model, STEPS_M, targets, Constraints(), min_margin=0)
    value, gradient = problem.objective(y)
    assert value > free.objective(y)[0] + 1e-3
    fd = central_gradient(problem, y, 1e-6)
    assert gradient == pytest.approx(fd, abs=1e-6 * np.abs(fd).max())


def test_the_search_stops_once_a_round_gains_too_little(braided):
    constraints = Constraints(max_field_t=0.02)
    model, _, targets = known_plan(braided, 3, constraints)
    calls = []

    def progress(done, total, best):
        if best is not None:
            calls.append((done, total))
    # Targets shrunk to 0.8 of the known plan's shape: out of reach, no start is exact.
    problem = Problem(model, STEPS_M, [t * 0.8 for t in targets], constraints)
    every = optimise(problem, seed=0, starts=6, iterations=40, progress=progress)
    assert [c[0] for c in calls] == [1, 2, 3, 4, 5, 6]
    calls.clear()
    problem = Problem(model, STEPS_M, [t * 0.8 for t in targets], constraints)
    early = optimise(problem, seed=0, starts=6, iterations=40, min_gain=1.0,
                     progress=progress)
    assert [c[0] for c in calls] == [1, 2, 3, 4]   # two rounds: no gain can be 100%
    assert early.objective >= every.objective      # the first two rounds' best, not more


def test_the_search_goes_on_while_its_best_plan_touches(braided):
    # A ball around the insertion point: every plan runs into it, so no round's small gain
    # ends the search early; the two best plans come back, best first.
    constraints = Constraints(max_field_t=0.02)
    model, _, targets = known_plan(braided, 3, constraints)
    ball = Sphere(centre_m=targets[0][0], radius_m=0.003)
    calls = []
    problem = Problem(model, STEPS_M, targets, constraints, keep_off=KeepOff(spheres=(ball,)))
    plans = leading(problem, keep=2, seed=0, starts=6, iterations=20, min_gain=1.0,
                    progress=lambda done, total, best: calls.append(done) if best else None)
    assert calls == [1, 2, 3, 4, 5, 6]
    assert [problem.deepest_contact_m(p) > 0 for p in plans] == [True, True]
    keys = [(len(p.flags), problem.deepest_contact_m(p), p.objective) for p in plans]
    assert keys == sorted(keys)


def test_side_by_side_gives_what_one_process_gives_in_order():
    # The function is a closure (not picklable): the workers are forked with it.
    scale = np.linspace(1.0, 2.0, 5)

    def work(k):
        a = np.random.default_rng(k).normal(size=(40, 40)) * scale[k % 5]
        return k, float(np.linalg.svd(a @ a.T, compute_uv=False)[0])

    alone = side_by_side(work, range(5), workers=1)
    assert [k for k, _ in alone] == [0, 1, 2, 3, 4]
    assert side_by_side(work, range(5), workers=2) == alone


@pytest.mark.parametrize('dof', [1, 3])
def test_the_compiled_key_step_gives_the_generic_residuals(braided, dof):
    # A model without dipoles runs each key step compiled (step_residuals.py): the residuals
    # and Jacobian of the generic per-step path, through walls and a ball, non-converged
    # steps, a start state and held directions.
    from tentacle_planner.planner import problem_of
    from tentacle_planner.scene import load_scene
    scene = load_scene(ROOT / 'config' / 'scenes' / (
        'pancreatic_duct.yaml' if dof == 3 else 'ch3_b.yaml'))
    shipped = problem_of(scene)
    model = TentacleModel(braided, dof=dof, sublinks=2, max_iterations=4,   # some fail
                          gravity_m_s2=(0.0, -9.81, 0.0))
    targets = [model.chain(s).base_position_m + np.zeros((model.chain(s).size + 1, 3))
               for s in STEPS_M[1:]]
    ball = KeepOff(spheres=(Sphere(np.array([0.03, 0.004, 0.0]), 0.002),), margin_m=0.001)
    start = (np.full((model.chain(STEPS_M[0]).size, 3), 0.1), STEPS_M[0])
    held = Problem(model, STEPS_M[1:], targets, Constraints(max_neighbour_angle_rad=0.5),
                   directions=np.tile([0.0, 1.0, 0.0], (5, 1)), start=start, free=[3, 4],
                   keep_off=ball)
    rng = np.random.default_rng(11)
    failed = 0
    for problem in (shipped, held):
        assert problem._steps is not None   # the compiled path is the one in use
        n_dir = len(problem.free_segments) * problem.angles_per_segment
        for _ in range(12):
            x = np.concatenate([rng.uniform(-math.pi, math.pi, n_dir),
                                rng.uniform(-15.0, 15.0, problem.size - n_dir)])
            r, jac = problem.residuals(x)
            steps, problem._steps = problem._steps, None   # the generic path
            try:
                generic_r, generic_jac = problem.residuals(x)
            finally:
                problem._steps = steps
            np.testing.assert_allclose(r, generic_r, rtol=1e-12, atol=1e-15)
            np.testing.assert_allclose(jac, generic_jac, rtol=1e-9,
                                       atol=1e-12 * np.abs(generic_jac).max())
            failed += np.count_nonzero(r == 10.0) > 0
    assert failed   # some steps did not converge: their rows are the generic ones too


def test_the_last_simulation_is_kept_for_its_own_unknowns_only(braided):
    # plan() simulates x, then residuals() asks for x again: the second is not solved anew
    # (a model with dipoles takes the per-step Python path), any other x is.
    model = TentacleModel(braided, dof=3, sublinks=1, dipoles=True)
    targets = [np.zeros((model.chain(s).size + 1, 3)) for s in STEPS_M]
    problem = Problem(model, STEPS_M, targets, directions=np.tile([1.0, 0.0, 0.0], (5, 1)))
    x = np.full(problem.size, 3.0)
    first = problem.simulate(x)
    assert problem.simulate(x.copy())[-1] is first[-1]           # kept
    other = problem.simulate(x + 1.0)
    assert not np.allclose(other[-1].points_m, first[-1].points_m)
    again = problem.simulate(x)                                   # solved anew, the same
    assert again[-1] is not first[-1]
    np.testing.assert_array_equal(again[-1].points_m, first[-1].points_m)
    first.clear()                                                 # a caller's list only
    assert len(problem.simulate(x)) == len(STEPS_M)
