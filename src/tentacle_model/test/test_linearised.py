"""The small-angle (linearised) model: exact beam theory, and where it stops being valid."""

import numpy as np
import pytest
from tentacle_model import planar
from tentacle_model.chain import discretise
from tentacle_model.statics import solve


def closed_form_tip_deflection(length, ei, ma, b_t):
    """Cantilever under a uniform distributed moment M A B: delta = M A B L^3 / (3 E I)."""
    return ma * b_t * length ** 3 / (3 * ei)


def test_linear_model_is_beam_theory_at_any_load(cantilever):
    spec, length, ei, ma = cantilever
    chain = discretise(spec, sublinks=200)
    for b_t in (1e-4, 5e-3):  # beta 0.14 and 6.8
        eq = solve(chain, [0.0, b_t, 0.0], linear=True)
        assert eq.converged and eq.iterations <= 2
        assert eq.tip_m[1] == pytest.approx(closed_form_tip_deflection(length, ei, ma, b_t),
                                            rel=1e-4)


def test_linear_agrees_with_nonlinear_at_small_load_only(cantilever):
    spec = cantilever[0]
    chain = discretise(spec, sublinks=40)
    small, large = [0.0, 2e-5, 0.0], [0.0, 5e-3, 0.0]
    assert solve(chain, small, linear=True).tip_m[1] == pytest.approx(
        solve(chain, small).tip_m[1], rel=1e-3)
    assert solve(chain, large, linear=True).tip_m[1] > 1.5 * solve(chain, large).tip_m[1]


def test_obtuse_field_has_no_linear_minimum(cantilever):
    chain = discretise(cantilever[0], sublinks=20)
    eq = solve(chain, [-5e-3, 1e-4, 0.0], linear=True)
    assert not eq.converged and 'no minimum' in eq.reason and eq.stability < 0


def test_linear_gradient_matches_finite_differences(cantilever):
    chain = discretise(cantilever[0], sublinks=6)
    a, b = planar.loads(chain, [0.002, 0.004, 0.0], [0.0, -9.81, 0.0])
    k = chain.stiffness_n_m[:, 0]
    theta = np.linspace(-0.3, 0.4, 6)
    eps = 1e-6
    fd = [(planar.energy_linear(theta + eps * e, k, a, b)
           - planar.energy_linear(theta - eps * e, k, a, b)) / (2 * eps) for e in np.eye(6)]
    np.testing.assert_allclose(planar.gradient_linear(theta, k, a, b), fd, rtol=1e-6,
                               atol=1e-12)


def test_spatial_linear_model_is_the_planar_one_in_the_plane(cantilever):
    chain = discretise(cantilever[0], sublinks=20)
    field = [1e-3, 2e-3, 0.0]
    flat = solve(chain, field, linear=True)
    full = solve(chain, field, dof=3, linear=True)
    assert full.converged and full.iterations <= 2
    np.testing.assert_allclose(full.points_m, flat.points_m, atol=1e-12)
    np.testing.assert_allclose(full.angles_rad[:, 0], np.diff(flat.angles_rad, prepend=0.0),
                               atol=1e-12)


def test_spatial_linear_model_is_second_order_accurate_out_of_the_plane(braided):
    # An out-of-plane field on the braided tentacle: the linear model's tip error against
    # the nonlinear one falls as the square of the load (deflection ~ B, error ~ B^2).
    chain = discretise(braided, sublinks=4)
    errors = []
    for scale in (2e-5, 4e-5):
        field = scale * np.array([0.3, 1.0, 0.7])
        exact = solve(chain, field, dof=3)
        approx = solve(chain, field, dof=3, linear=True)
        assert exact.converged and approx.converged
        errors.append(np.linalg.norm(approx.tip_m - exact.tip_m))
    assert errors[1] / errors[0] == pytest.approx(4.0, rel=0.1)


def test_spatial_linear_model_reports_no_minimum_for_an_obtuse_field(cantilever):
    chain = discretise(cantilever[0], sublinks=20)
    eq = solve(chain, [-5e-3, 0.0, 1e-4], dof=3, linear=True)
    assert not eq.converged and 'no minimum' in eq.reason and eq.stability < 0
