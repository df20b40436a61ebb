"""3-DoF joints: exact derivatives, and agreement with the planar model in the plane."""

import dataclasses

import numpy as np
import pytest
from tentacle_model import link_loads, spatial
from tentacle_model.chain import Chain, discretise
from tentacle_model.statics import solve


def random_chain(n, seed):
    rng = np.random.default_rng(seed)
    rotation = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    return Chain(rng.uniform(1e-3, 5e-3, n), rng.uniform(1e-5, 1e-3, (n, 3)),
                 rng.normal(0, 1e-3, (n, 3)), rng.uniform(0, 1e-3, n), np.zeros(n),
                 rng.normal(size=3), rotation), rng


@pytest.mark.parametrize('seed', range(3))
def test_gradient_and_hessian_match_finite_differences(seed):
    chain, rng = random_chain(4, seed)
    field, gravity = rng.normal(0, 0.01, 3), rng.normal(0, 5.0, 3)
    q = rng.uniform(-1, 1, (4, 3))

    def energy(q):
        return spatial.evaluate(chain, q, field, gravity, hessian=False).energy_j

    def gradient(q):
        return spatial.evaluate(chain, q, field, gravity, hessian=False).gradient

    eps = 1e-6
    basis = np.eye(12).reshape(12, 4, 3)
    fd_grad = np.array([(energy(q + eps * e) - energy(q - eps * e)) / (2 * eps)
                        for e in basis]).reshape(4, 3)
    np.testing.assert_allclose(gradient(q), fd_grad, rtol=1e-6,
                               atol=1e-8 * np.abs(fd_grad).max())
    fd_hess = np.column_stack([((gradient(q + eps * e) - gradient(q - eps * e))
                                / (2 * eps)).reshape(-1) for e in basis])
    hess = spatial.evaluate(chain, q, field, gravity).hessian
    np.testing.assert_allclose(hess, fd_hess, rtol=1e-6, atol=1e-8 * np.abs(fd_hess).max())


def test_a_dense_link_load_projects_to_its_finite_differences(dense_load):
    # At 20 links the projection's suffix sums over links must agree with the kinematics.
    chain, rng = random_chain(20, 4)
    loads = (dense_load(20, 5),)
    q = rng.uniform(-1, 1, (20, 3))

    def state(q, hessian=False):
        return spatial.evaluate(chain, q, np.zeros(3), hessian=hessian, loads=loads)

    full = state(q, True)
    assert_matches_differences(state, q, full, 1e-6, 1e-6)
    np.testing.assert_array_equal(full.hessian, full.hessian.T)


def assert_matches_differences(state, q, full, eps, rtol_hess):
    """Check full's gradient and Hessian against central differences of state (step eps)."""
    basis = np.eye(q.size).reshape(q.size, *q.shape)
    fd_grad = np.array([(state(q + eps * e).energy_j - state(q - eps * e).energy_j)
                        / (2 * eps) for e in basis]).reshape(q.shape)
    np.testing.assert_allclose(full.gradient, fd_grad, rtol=1e-6,
                               atol=1e-7 * np.abs(fd_grad).max())
    fd_hess = np.column_stack([((state(q + eps * e).gradient - state(q - eps * e).gradient)
                                / (2 * eps)).reshape(-1) for e in basis])
    np.testing.assert_allclose(full.hessian, fd_hess, rtol=rtol_hess,
                               atol=0.1 * rtol_hess * np.abs(fd_hess).max())


def test_gravity_energy_is_the_height_of_the_centres_of_mass():
    chain, rng = random_chain(5, 7)
    q = rng.uniform(-1, 1, (5, 3))
    state = spatial.evaluate(chain, q, np.zeros(3), [0.0, 0.0, -9.81])
    pts = state.points_m
    centres = (pts[:-1] + pts[1:]) / 2
    elastic = 0.5 * np.sum(chain.stiffness_n_m * q * q)
    expected = elastic + np.sum(chain.masses_kg * 9.81 * (centres[:, 2]
                                                          - chain.base_position_m[2]))
    assert state.energy_j == pytest.approx(expected, rel=1e-9, abs=0)


@pytest.mark.parametrize('degrees', [60, 135])
def test_in_plane_loads_give_the_planar_solution(cantilever, degrees):
    chain = discretise(cantilever[0], sublinks=16)
    field = 5e-3 * np.array([np.cos(np.radians(degrees)), np.sin(np.radians(degrees)), 0.0])
    flat = solve(chain, field, dof=1)
    full = solve(chain, field, dof=3)
    assert flat.converged and full.converged and full.stability > 0
    np.testing.assert_allclose(full.points_m, flat.points_m, atol=1e-9)
    np.testing.assert_allclose(full.angles_rad[:, 1:], 0.0, atol=1e-12)


def test_out_of_plane_field_bends_out_of_plane(cantilever):
    chain = discretise(cantilever[0], sublinks=16)
    eq = solve(chain, [0.0, 0.0, 5e-3], dof=3)
    in_plane = solve(chain, [0.0, 5e-3, 0.0], dof=1)  # the same problem, turned by 90 deg
    assert eq.converged
    np.testing.assert_allclose(eq.tip_m, in_plane.tip_m[[0, 2, 1]], atol=1e-9)


@pytest.mark.parametrize('seed', range(2))
def test_dipole_interaction_derivatives_match_finite_differences(seed):
    chain, rng = random_chain(5, seed)
    # Soft joints and strong magnets: the interaction is a large part of the Hessian.
    chain = dataclasses.replace(chain, moments_a_m2=rng.normal(0, 1e-3, (5, 3)),
                                stiffness_n_m=1e-3 * chain.stiffness_n_m,
                                segment_index=np.array([0, 0, 1, 2, 2]))
    loads = link_loads.of_chain(chain, dipoles=True)
    q = rng.uniform(-1, 1, (5, 3))
    field, gravity = rng.normal(0, 1e-4, 3), np.zeros(3)

    def state(q, hessian=False):
        return spatial.evaluate(chain, q, field, gravity, hessian=hessian, loads=loads)

    plain = spatial.evaluate(chain, q, field, gravity)
    full = state(q, True)
    assert np.abs(full.hessian - plain.hessian).max() > 0.1 * np.abs(plain.hessian).max()
    # eps: the pair energies cancel to a few digits, round-off rules below 1e-4
    assert_matches_differences(state, q, full, 1e-4, 1e-5)
