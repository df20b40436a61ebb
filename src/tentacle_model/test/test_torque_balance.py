"""The planner's torque-balance residual: zero at solved equilibria, exact derivatives."""

import dataclasses

import numpy as np
import pytest
from tentacle_model import planar
from tentacle_model.chain import discretise
from tentacle_model.statics import solve, solve_planar
from tentacle_model.torque_balance import residual, residual_3dof


def test_residual_vanishes_at_a_forward_equilibrium(cantilever):
    spec, length, ei, ma = cantilever
    chain = discretise(spec, sublinks=12)
    b = np.array([0.003, 0.004, 0.0])
    eq = solve_planar(chain, b)
    q = np.diff(eq.angles_rad, prepend=0.0)
    lam, _, _ = residual(q, chain.stiffness_n_m[:, 0], chain.moments_a_m2[:, 0],
                         np.zeros(chain.size), b[:2])
    assert np.max(np.abs(lam)) < 1e-8 * ma * 0.005 * length
    # and it is minus the energy gradient in joint coordinates away from equilibrium
    theta = eq.angles_rad + 0.1
    a_, b_ = planar.loads(chain, b)
    grad_theta = planar.gradient(theta, chain.stiffness_n_m[:, 0], a_, b_)
    lam, _, _ = residual(np.diff(theta, prepend=0.0), chain.stiffness_n_m[:, 0],
                         chain.moments_a_m2[:, 0], np.zeros(chain.size), b[:2])
    np.testing.assert_allclose(lam, -np.cumsum(grad_theta[::-1])[::-1], rtol=1e-10,
                               atol=1e-18)


@pytest.mark.parametrize('seed', range(3))
def test_derivatives_match_finite_differences(seed):
    rng = np.random.default_rng(seed)
    n = 6
    q, k = rng.uniform(-0.5, 0.5, n), rng.uniform(1e-6, 1e-4, n)
    mu, psi, b = rng.uniform(1e-4, 1e-3, n), rng.uniform(-np.pi, np.pi, n), rng.normal(0, 0.01, 2)
    _, d_psi, d_b = residual(q, k, mu, psi, b)
    eps = 1e-7
    fd_psi = np.column_stack([(residual(q, k, mu, psi + eps * e, b)[0]
                               - residual(q, k, mu, psi - eps * e, b)[0]) / (2 * eps)
                              for e in np.eye(n)])
    fd_b = np.column_stack([(residual(q, k, mu, psi, b + eps * e)[0]
                             - residual(q, k, mu, psi, b - eps * e)[0]) / (2 * eps)
                            for e in np.eye(2)])
    np.testing.assert_allclose(d_psi, fd_psi, rtol=1e-6, atol=1e-14)
    np.testing.assert_allclose(d_b, fd_b, rtol=1e-6, atol=1e-12)


def test_three_dof_residual_vanishes_at_equilibrium_and_has_exact_derivatives(cantilever):
    spec = cantilever[0]
    chain = discretise(spec, sublinks=4)
    rng = np.random.default_rng(3)
    chain = dataclasses.replace(chain, moments_a_m2=chain.moments_a_m2
                                + rng.normal(0, 2e-5, chain.moments_a_m2.shape))
    b = np.array([0.002, 0.004, -0.003])
    eq = solve(chain, b, dof=3)
    lam, d_field, d_moment = residual_3dof(chain, eq.angles_rad, b)
    assert np.max(np.abs(lam)) < 1e-9 * np.max(np.abs(d_field)) * 0.005
    q = eq.angles_rad + rng.normal(0, 0.2, eq.angles_rad.shape)  # away from equilibrium
    lam, d_field, d_moment = residual_3dof(chain, q, b)
    eps = 1e-7
    for k in range(3):
        e = np.eye(3)[k] * eps
        fd = (residual_3dof(chain, q, b + e)[0] - residual_3dof(chain, q, b - e)[0]) / (2 * eps)
        np.testing.assert_allclose(d_field[:, :, k], fd, rtol=1e-6, atol=1e-15)
    for i in range(chain.size):
        for k in range(3):
            bumped = [chain.moments_a_m2.copy(), chain.moments_a_m2.copy()]
            bumped[0][i, k] += 1e-6
            bumped[1][i, k] -= 1e-6
            plus = residual_3dof(dataclasses.replace(chain, moments_a_m2=bumped[0]), q, b)[0]
            minus = residual_3dof(dataclasses.replace(chain, moments_a_m2=bumped[1]), q, b)[0]
            np.testing.assert_allclose(d_moment[:, :, i, k], (plus - minus) / 2e-6,
                                       rtol=1e-6, atol=1e-15)
