"""The planner's torque-balance residual: zero at solved equilibria, exact derivatives."""

import numpy as np
import pytest
from tentacle_planner import planar
from tentacle_planner.chain import discretise
from tentacle_planner.statics import solve_planar
from tentacle_planner.torque_balance import residual


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
