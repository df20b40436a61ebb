"""Equilibria in batch: each point the equilibrium statics.solve finds from the same start."""

import numpy as np
import pytest
from tentacle_model import batch
from tentacle_model.model import TentacleModel


def sweep(spec, count, seed):
    """Return (directions (P, segments, 3), fields (P, 3)): turning magnets, a varying field."""
    rng = np.random.default_rng(seed)
    segments = len(spec.segments)
    angles = np.cumsum(rng.normal(0.0, 0.4, (count, segments)), axis=0)  # a walk: neighbours
    directions = np.stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)], axis=-1)
    magnetised = [np.linalg.norm(s.magnetisation_a_per_m) > 0 for s in spec.segments]
    directions[:, ~np.array(magnetised)] = 0.0
    fields = rng.normal(0.0, 4e-3, (count, 3))
    return directions, fields


@pytest.mark.parametrize('dof', [1, 3])
def test_every_point_is_the_equilibrium_solve_finds_from_the_last(braided, dof):
    model = TentacleModel(braided, dof=dof, sublinks=2, gravity_m_s2=[0.0, 0.0, -9.81])
    chain = model.chain(braided.length_m)
    directions, fields = sweep(braided, 40, dof)
    if dof == 1:
        fields[:, 2] = 0.0
    got = batch.solve(chain, directions, fields, model.gravity_m_s2, dof=dof,
                      tol=model.tol, max_iterations=model.max_iterations, points=True)
    magnitudes = np.linalg.norm(chain.moments_a_m2, axis=1)
    state = None
    for p in range(len(fields)):
        moments = magnitudes[:, None] * directions[p][chain.segment_index]
        solution = model.solve(braided.length_m, fields[p], state, moments)
        eq = solution.equilibrium
        assert got.converged[p] == eq.converged
        np.testing.assert_allclose(got.tips_m[p], eq.points_m[-1], rtol=0, atol=1e-12)
        np.testing.assert_allclose(got.points_m[p], eq.points_m, rtol=0, atol=1e-12)
        assert got.stability[p] == pytest.approx(eq.stability, rel=1e-9, abs=1e-15)
        assert got.iterations[p] == eq.iterations
        state = solution.state if eq.converged else None
    assert got.converged.all() and got.stable.any()
    assert np.ptp(got.tips_m[:, 1]) > 0.2 * braided.length_m   # the points differ


@pytest.mark.parametrize('dof', [1, 3])
def test_without_warm_starts_every_point_is_solved_from_straight(braided, dof):
    model = TentacleModel(braided, dof=dof, sublinks=2, gravity_m_s2=[0.0, 0.0, -9.81])
    chain = model.chain(braided.length_m)
    directions, fields = sweep(braided, 30, dof + 10)
    if dof == 1:
        fields[:, 2] = 0.0
    got = batch.solve(chain, directions, fields, model.gravity_m_s2, dof=dof, tol=model.tol,
                      max_iterations=model.max_iterations, warm=False)
    magnitudes = np.linalg.norm(chain.moments_a_m2, axis=1)
    for p in range(len(fields)):
        moments = magnitudes[:, None] * directions[p][chain.segment_index]
        eq = model.solve(braided.length_m, fields[p], None, moments).equilibrium
        np.testing.assert_allclose(got.tips_m[p], eq.points_m[-1], rtol=0, atol=1e-12)
        assert got.iterations[p] == eq.iterations
    backwards = batch.solve(chain, directions[::-1], fields[::-1], model.gravity_m_s2,
                            dof=dof, tol=model.tol, max_iterations=model.max_iterations,
                            warm=False)
    np.testing.assert_array_equal(backwards.tips_m[::-1], got.tips_m)   # order is nothing


def test_refuses_what_it_cannot_solve(braided):
    chain = TentacleModel(braided, dof=3).chain(braided.length_m)
    segments = len(braided.segments)
    with pytest.raises(ValueError, match='expected'):
        batch.solve(chain, np.zeros((2, segments + 1, 3)), np.zeros((2, 3)))
    with pytest.raises(ValueError, match='finite'):
        batch.solve(chain, np.zeros((1, segments, 3)), np.full((1, 3), np.nan))


def test_along_an_even_run_each_point_starts_where_its_neighbours_point(braided):
    """A grid's run: the solutions before extrapolated (a parabola, a line); a new row: none."""
    model = TentacleModel(braided, dof=3, gravity_m_s2=[0.0, 0.0, -9.81])
    chain = model.chain(braided.length_m)
    row = np.radians(np.arange(0.0, 360.0, 15.0))
    angles = np.concatenate([row, row + 0.1])   # two rows of 24: the second starts afresh
    directions = np.repeat(np.array([[1.0, 0.0, 0.0]] * len(braided.segments))[None],
                           len(angles), axis=0)
    directions[:, -1] = np.column_stack([np.cos(angles), np.sin(angles), 0 * angles])
    fields = np.tile([0.0, 0.005, 0.0], (len(angles), 1))
    got = batch.solve(chain, directions, fields, model.gravity_m_s2, dof=3, tol=model.tol,
                      max_iterations=model.max_iterations)
    magnitudes = np.linalg.norm(chain.moments_a_m2, axis=1)
    solved, previous_iterations = [], 0
    for p in range(len(angles)):
        along = p % len(row)   # its place in its row
        if along >= 3:
            start = 3 * (solved[-1] - solved[-2]) + solved[-3]
        elif along == 2:
            start = 2 * solved[-1] - solved[-2]
        else:
            start = solved[-1] if solved else None
        moments = magnitudes[:, None] * directions[p][chain.segment_index]
        solution = model.solve(braided.length_m, fields[p], start, moments)
        eq = solution.equilibrium
        # its start is extrapolated from statics' solutions, which differ from the batch's
        # by round-off within the tolerance: so do the two answers
        np.testing.assert_allclose(got.tips_m[p], eq.points_m[-1], rtol=0, atol=1e-9)
        assert abs(got.iterations[p] - eq.iterations) <= 1   # a residual at the tolerance
        previous_iterations += model.solve(braided.length_m, fields[p], solved[-1] if solved
                                           else None, moments).equilibrium.iterations
        solved.append(solution.state)
    assert got.converged.all()
    assert got.iterations.sum() < previous_iterations   # what the prediction is for
