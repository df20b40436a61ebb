"""The model object: one state representation, carrying states, implicit sensitivities."""

import dataclasses

import numpy as np
import pytest
from tentacle_model import statics
from tentacle_model.model import TentacleModel

IN_PLANE = np.array([0.0, 0.005, 0.0])  # T: 90 degrees to the cantilever
BRAIDED_FIELD = np.array([0.004, 0.012, 0.006])  # T: out of plane, as bench/model_tradeoff.py


def test_one_state_representation_for_both_joint_models(cantilever):
    spec = cantilever[0]
    planar = TentacleModel(spec, dof=1, sublinks=8).solve(spec.length_m, IN_PLANE)
    spatial = TentacleModel(spec, dof=3, sublinks=8).solve(spec.length_m, IN_PLANE)
    assert planar.state.shape == spatial.state.shape == (8, 3)
    assert np.all(planar.state[:, 1:] == 0.0)
    assert TentacleModel.link_angles(planar.state) == pytest.approx(
        planar.equilibrium.angles_rad, abs=1e-15)
    # The same physics in the plane: the 3-DoF model finds the planar state.
    assert spatial.state == pytest.approx(planar.state, abs=1e-7)


@pytest.mark.parametrize('dof', [1, 3])
def test_a_state_is_carried_along_the_insertion(braided, dof):
    model = TentacleModel(braided, dof=dof, sublinks=2)
    field = BRAIDED_FIELD if dof == 3 else BRAIDED_FIELD * [1, 1, 0]
    state, previous, iterations = None, None, []
    for inserted_m in (0.020, 0.025, 0.0333, 0.040, 0.050):  # partial links included
        if state is not None:
            state = model.carry(state, previous, inserted_m)
        solution = model.solve(inserted_m, field, state)
        cold = model.solve(inserted_m, field)
        assert solution.equilibrium.converged and cold.equilibrium.converged
        assert solution.state == pytest.approx(cold.state, abs=1e-7)  # the same branch
        iterations.append((solution.equilibrium.iterations, cold.equilibrium.iterations))
        state, previous = solution.state, inserted_m
    assert sum(w for w, _ in iterations[1:]) < sum(c for _, c in iterations[1:])


def test_a_state_of_the_wrong_length_is_refused_by_name(braided):
    model = TentacleModel(braided, dof=3, sublinks=1)
    state = model.solve(0.030, BRAIDED_FIELD).state
    with pytest.raises(ValueError, match=r'state of shape \(3, 3\) for 4 links.*carry'):
        model.solve(0.040, BRAIDED_FIELD, state)
    assert model.carry(state, 0.030, 0.040).shape == (4, 3)


def central_difference(solve, field, h):
    """Return (d state / dB, d points / dB) by central differences of re-solves."""
    d_state, d_points = [], []
    for k in range(3):
        step = np.zeros(3)
        step[k] = h
        plus, minus = solve(field + step), solve(field - step)
        d_state.append((plus.state - minus.state) / (2 * h))
        d_points.append((plus.points_m - minus.points_m) / (2 * h))
    return np.stack(d_state, axis=-1), np.stack(d_points, axis=-1)


@pytest.mark.parametrize('name, dof, dipoles', [
    ('cantilever', 1, False), ('cantilever', 3, False), ('braided', 3, False),
    ('braided', 1, True), ('braided', 3, True)])
def test_field_sensitivity_matches_finite_differences(cantilever, braided, name, dof,
                                                      dipoles):
    spec = cantilever[0] if name == 'cantilever' else braided
    field = IN_PLANE if name == 'cantilever' else BRAIDED_FIELD * (
        [1, 1, 1] if dof == 3 else [1, 1, 0])
    model = TentacleModel(spec, dof=dof, sublinks=4 if name == 'cantilever' else 2,
                          dipoles=dipoles, tol=1e-13)
    solution = model.solve(spec.length_m, field)
    assert solution.equilibrium.converged and solution.equilibrium.stability > 0
    sensitivity = model.field_sensitivity(solution, field)
    d_state, d_points = central_difference(
        lambda b: model.solve(spec.length_m, b, solution.state), field, 1e-6)
    scale = np.abs(d_state).max()
    assert sensitivity.state == pytest.approx(d_state, abs=1e-4 * scale)
    assert sensitivity.points == pytest.approx(d_points, abs=1e-4 * np.abs(d_points).max())
    lowest = np.linalg.eigvalsh(sensitivity.hessian)[0]
    if dof == 3:  # the solver's coordinates: the same smallest eigenvalue
        assert lowest == pytest.approx(solution.equilibrium.stability, rel=1e-6)
    else:  # planar stability is in absolute link angles: another basis, the same sign
        assert lowest > 0


def test_moment_sensitivity_matches_finite_differences(braided):
    model = TentacleModel(braided, dof=3, sublinks=1, tol=1e-13)
    solution = model.solve(braided.length_m, BRAIDED_FIELD)
    sensitivity = model.moment_sensitivity(solution, BRAIDED_FIELD)
    d_q = sensitivity.state.reshape(5, 3, 5, 3)
    d_p = sensitivity.points.reshape(6, 3, 5, 3)
    chain = model.chain(braided.length_m)
    h = 1e-6 * np.abs(chain.moments_a_m2).max()
    for link, component in [(0, 1), (2, 0), (4, 2), (4, 1)]:
        moved = []
        for sign in (1, -1):
            moments = chain.moments_a_m2.copy()
            moments[link, component] += sign * h
            eq = statics.solve(dataclasses.replace(chain, moments_a_m2=moments), BRAIDED_FIELD,
                               dof=3, initial=solution.state, tol=1e-13)
            moved.append((eq.angles_rad, eq.points_m))
        fd = (moved[0][0] - moved[1][0]) / (2 * h)
        assert d_q[:, :, link, component] == pytest.approx(fd, abs=1e-4 * np.abs(fd).max())
        fd_points = (moved[0][1] - moved[1][1]) / (2 * h)
        assert d_p[:, :, link, component] == pytest.approx(
            fd_points, abs=1e-4 * np.abs(fd_points).max())
    with pytest.raises(ValueError, match='dipoles'):
        TentacleModel(braided, dipoles=True).moment_sensitivity(solution, BRAIDED_FIELD)


def test_a_planar_equilibrium_unstable_out_of_its_plane_is_seen():
    """Straight in a field against its moment: stable in the stiff plane, not out of it."""
    from tentacle_model.tentacle_spec import parse_tentacle
    spec = parse_tentacle({
        'base': {'position_m': [0, 0, 0], 'direction': [1, 0, 0], 'normal': [0, 1, 0]},
        'segments': [{'length_m': 0.01, 'section': {'diameter_m': 0.002},
                      'youngs_modulus_pa': {'bend_1': 4e5, 'bend_2': 1e5, 'twist': 1e5},
                      'density_kg_m3': 1000.0,
                      'magnetisation': {'remanence_t': 0.1, 'direction': [1, 0, 0]}}]})
    planar = TentacleModel(spec, dof=1)
    k_in, k_out, k_twist = planar.chain(0.01).stiffness_n_m[0]
    moment = float(np.linalg.norm(planar.chain(0.01).moments_a_m2[0]))
    field = 2.5 * k_out / moment          # |m| B between the two bending stiffnesses
    solution = planar.solve(0.01, [-field, 0.0, 0.0])
    # Energy -m.B = |m| B cos(bend): each bend's curvature is its stiffness less |m| B.
    assert solution.equilibrium.stability == pytest.approx(k_in - moment * field, rel=1e-6)
    assert planar.stability(solution, [-field, 0, 0]) == pytest.approx(
        min(k_out - moment * field, k_twist), rel=1e-6)
    assert planar.stability(solution, [-field, 0, 0]) < 0 < solution.equilibrium.stability


def test_the_chain_cache_stays_bounded_under_continuous_insertion(braided):
    # A simulator asks for a new inserted length every frame (a stage moving at 1 mm/s seen
    # at 30 Hz): the cache keeps the most recent chains only, and answers do not change.
    from tentacle_model.model import CHAIN_CACHE_SIZE
    model = TentacleModel(braided, dof=1, sublinks=2)
    lengths = np.linspace(0.001, braided.length_m, 10 * CHAIN_CACHE_SIZE)
    state, previous = None, None
    for inserted in lengths:
        if state is not None:
            state = model.carry(state, previous, inserted)
        state, previous = model.solve(inserted, IN_PLANE, state).state, inserted
        assert len(model._chains) <= CHAIN_CACHE_SIZE
    fresh = TentacleModel(braided, dof=1, sublinks=2).solve(lengths[0], IN_PLANE)
    again = model.solve(lengths[0], IN_PLANE)   # its chain was evicted long ago: rebuilt
    assert np.array_equal(again.points_m, fresh.points_m)
    recent = model.chain(lengths[-1])
    assert model.chain(lengths[-1]) is recent   # the one in use is kept


@pytest.mark.parametrize('dof', [1, 3])   # both solved by a compiled Newton, in calls
def test_a_solve_within_its_own_time_budget(braided, dof):
    model = TentacleModel(braided, dof=dof, sublinks=2)
    full = model.solve(braided.length_m, BRAIDED_FIELD)
    assert full.equilibrium.converged
    cut = model.solve(braided.length_m, BRAIDED_FIELD, time_limit_s=0.0)
    assert not cut.equilibrium.converged
    assert cut.equilibrium.reason == 'no convergence within the 0 s limit'
    assert cut.equilibrium.iterations == 0 and np.all(cut.state == 0.0)  # the start, as given
    # Solving on from where a cut solve stopped reaches the same equilibrium.
    assert model.solve(braided.length_m, BRAIDED_FIELD, cut.state).points_m == pytest.approx(
        full.points_m, abs=1e-9)
    for bad in (-1.0, np.nan, np.inf):
        with pytest.raises(ValueError, match='time limit'):
            model.solve(braided.length_m, BRAIDED_FIELD, time_limit_s=bad)
