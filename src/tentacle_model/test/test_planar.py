"""Planar energy: gradient and Hessian against central finite differences."""

import numpy as np
import pytest
from tentacle_model import dipoles, link_loads, planar
from tentacle_model.chain import Chain


def random_chain(n=7, seed=0):
    rng = np.random.default_rng(seed)
    return Chain(lengths_m=rng.uniform(1e-3, 5e-3, n),
                 stiffness_n_m=rng.uniform(1e-5, 1e-3, (n, 3)),
                 moments_a_m2=rng.normal(0, 1e-3, (n, 3)), masses_kg=rng.uniform(0, 1e-3, n),
                 s_start_m=np.zeros(n), base_position_m=np.zeros(3), base_rotation=np.eye(3))


@pytest.mark.parametrize('seed', range(4))
def test_gradient_and_hessian_match_finite_differences(seed):
    chain = random_chain(seed=seed)
    a, b = planar.loads(chain, [0.01, -0.02, 0.005], [0.0, -9.81, 0.0])
    k = chain.stiffness_n_m[:, 0]
    theta = np.random.default_rng(seed + 10).uniform(-2, 2, chain.size)
    eps = 1e-6
    eye = np.eye(chain.size)
    fd_grad = np.array([(planar.energy(theta + eps * e, k, a, b)
                         - planar.energy(theta - eps * e, k, a, b)) / (2 * eps) for e in eye])
    grad = planar.gradient(theta, k, a, b)
    np.testing.assert_allclose(grad, fd_grad, rtol=1e-6, atol=1e-9 * np.abs(grad).max())
    fd_hess = np.array([(planar.gradient(theta + eps * e, k, a, b)
                         - planar.gradient(theta - eps * e, k, a, b)) / (2 * eps) for e in eye])
    hess = planar.hessian_dense(theta, k, a, b)
    np.testing.assert_allclose(hess, fd_hess, rtol=1e-6, atol=1e-9 * np.abs(hess).max())


def test_gravity_energy_is_the_height_of_the_centres_of_mass():
    chain = random_chain(seed=5)
    chain = Chain(chain.lengths_m, chain.stiffness_n_m, np.zeros((chain.size, 3)),
                  chain.masses_kg, chain.s_start_m, chain.base_position_m, chain.base_rotation)
    theta = np.linspace(0.3, -1.2, chain.size)
    a, b = planar.loads(chain, [0, 0, 0], [0.0, -9.81, 0.0])
    pts = planar.points(chain, theta)
    centres = (pts[:-1] + pts[1:]) / 2
    elastic = 0.5 * np.dot(chain.stiffness_n_m[:, 0], np.diff(theta, prepend=0.0) ** 2)
    expected = elastic + np.sum(chain.masses_kg * 9.81 * centres[:, 1])
    assert planar.energy(theta, chain.stiffness_n_m[:, 0], a, b) == pytest.approx(
        expected, rel=1e-9, abs=0)


def test_dipole_interaction_derivatives_match_finite_differences():
    rng = np.random.default_rng(3)
    n = 6
    rotation = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    chain = Chain(rng.uniform(1e-3, 5e-3, n), np.zeros((n, 3)), rng.normal(0, 1e-3, (n, 3)),
                  np.zeros(n), np.zeros(n), rng.normal(size=3), rotation,
                  np.array([0, 0, 1, 1, 2, 3]))
    pairs = chain.interacting_pairs()
    loads = link_loads.of_chain(chain, dipoles=True)
    theta = rng.uniform(-2, 2, n)
    energy, grad, hess = planar.project_loads(chain, theta, loads)
    # The energy itself, from the world-frame points of planar.points.
    pts = planar.points(chain, theta)

    def turn(t):
        return np.array([[np.cos(t), -np.sin(t), 0.0], [np.sin(t), np.cos(t), 0.0],
                         [0.0, 0.0, 1.0]])

    world = [chain.base_rotation @ turn(t) @ m for t, m in zip(theta, chain.moments_a_m2)]
    reference = dipoles.interaction(np.array(world), (pts[:-1] + pts[1:]) / 2, pairs, False)
    assert energy == pytest.approx(reference.energy_j, rel=1e-12, abs=0)
    assert_projection_matches_differences(chain, theta, loads, grad, hess, 1e-4, 1e-5)


def test_a_dense_link_load_projects_to_its_finite_differences(dense_load):
    # At 20 links the projection's suffix sums over links must agree with the kinematics.
    rng = np.random.default_rng(8)
    n = 20
    rotation = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    chain = Chain(rng.uniform(1e-3, 5e-3, n), np.zeros((n, 3)), rng.normal(0, 1e-3, (n, 3)),
                  np.zeros(n), np.zeros(n), rng.normal(size=3), rotation)
    loads = (dense_load(n, 9),)
    theta = rng.uniform(-2, 2, n)
    _, grad, hess = planar.project_loads(chain, theta, loads)
    assert_projection_matches_differences(chain, theta, loads, grad, hess, 1e-6, 1e-6)
    np.testing.assert_array_equal(hess, hess.T)


def assert_projection_matches_differences(chain, theta, loads, grad, hess, eps, rtol_hess):
    """Check project_loads' gradient and Hessian against central differences (step eps)."""
    def differences(part):
        return np.array([(planar.project_loads(chain, theta + eps * e, loads, False)[part]
                          - planar.project_loads(chain, theta - eps * e, loads, False)[part])
                         / (2 * eps) for e in np.eye(len(theta))])
    fd_grad, fd_hess = differences(0), differences(1)
    np.testing.assert_allclose(grad, fd_grad, rtol=1e-6, atol=1e-7 * np.abs(fd_grad).max())
    np.testing.assert_allclose(hess, fd_hess, rtol=rtol_hess,
                               atol=0.1 * rtol_hess * np.abs(fd_hess).max())


@pytest.mark.parametrize('n', [1, 2, 7, 300])
def test_smallest_eigenvalue_by_bisection_matches_lapack(n):
    from scipy.linalg import eigvalsh_tridiagonal
    rng = np.random.default_rng(n)
    for scale in (1e-6, 1.0, 1e4):
        diagonal, off = scale * rng.normal(size=n), scale * rng.normal(size=n - 1)
        expected = np.linalg.eigvalsh(np.diag(diagonal) + np.diag(off, 1) + np.diag(off, -1))[0]
        if n > 1:
            assert expected == pytest.approx(eigvalsh_tridiagonal(diagonal, off)[0],
                                             rel=1e-12)
        assert planar.smallest_eigenvalue(diagonal, off) == pytest.approx(
            expected, rel=1e-12, abs=1e-14 * scale)
    # A stiff chain with a soft mode: k from 1e-3 to 1e6, a near-singular minimum.
    k = 10.0 ** rng.uniform(-3, 6, n)
    banded = planar.hessian_banded(np.zeros(n), k, np.zeros(n), np.zeros(n))
    dense = planar.hessian_dense(np.zeros(n), k, np.zeros(n), np.zeros(n))
    # Both are accurate to round-off of the matrix's norm, not of the small eigenvalue.
    assert planar.smallest_eigenvalue(banded[1], banded[0, 1:]) == pytest.approx(
        np.linalg.eigvalsh(dense)[0], rel=0, abs=1e-14 * np.max(banded[1]))
