"""World-frame link loads: one definition, projected alike by the planar and 3-DoF models."""

import dataclasses

import numpy as np
import pytest
from tentacle_model import link_loads, planar, spatial
from tentacle_model.chain import Chain
from tentacle_model.dipoles import Interaction


class FieldLoad:
    """-sum m_i . B: a uniform field written as a link load (the compiled passes have it)."""

    def __init__(self, field_t):
        self.field_t = np.asarray(field_t, dtype=float)

    def __call__(self, moments, centres, hessian):
        n = len(moments)
        return Interaction(-float(np.sum(moments @ self.field_t)),
                           -np.broadcast_to(self.field_t, (n, 3)).copy(), np.zeros((n, 3)),
                           np.zeros((6 * n, 6 * n)) if hessian else None)


class Tether:
    """1/2 kappa sum |c_i - p|^2: every link centre pulled towards a point (N/m, m)."""

    def __init__(self, kappa, point_m):
        self.kappa, self.point = kappa, np.asarray(point_m, dtype=float)

    def __call__(self, moments, centres, hessian):
        n, d = len(moments), centres - self.point
        h = None
        if hessian:
            h = np.zeros((6 * n, 6 * n))
            h[3 * n:, 3 * n:] = self.kappa * np.eye(3 * n)
        return Interaction(0.5 * self.kappa * float(np.sum(d * d)), np.zeros((n, 3)),
                           self.kappa * d, h)


def chain_of(n, seed):
    rng = np.random.default_rng(seed)
    rotation = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    return Chain(rng.uniform(1e-3, 5e-3, n), rng.uniform(1e-5, 1e-3, (n, 3)),
                 rng.normal(0, 1e-3, (n, 3)), np.zeros(n), np.zeros(n), rng.normal(size=3),
                 rotation), rng


def test_a_field_given_as_a_load_is_the_compiled_field_in_both_models():
    chain, rng = chain_of(5, 1)
    field = rng.normal(0, 0.01, 3)
    q = rng.uniform(-1, 1, (5, 3))
    compiled = spatial.evaluate(chain, q, field)
    loaded = spatial.evaluate(chain, q, np.zeros(3), loads=(FieldLoad(field),))
    assert loaded.energy_j == pytest.approx(compiled.energy_j, rel=1e-12)
    np.testing.assert_allclose(loaded.gradient, compiled.gradient, rtol=1e-10, atol=1e-18)
    np.testing.assert_allclose(loaded.hessian, compiled.hessian, rtol=1e-10, atol=1e-18)
    theta = rng.uniform(-1, 1, 5)
    k = chain.stiffness_n_m[:, 0]
    in_plane = field - (field @ chain.base_rotation[:, 2]) * chain.base_rotation[:, 2]
    a, b = planar.loads(chain, in_plane, np.zeros(3))
    energy, gradient, banded = planar.evaluate(theta, k, a, b, False, True)
    zero_a, zero_b = planar.loads(chain, np.zeros(3), np.zeros(3))
    base_energy, base_gradient, base_banded = planar.evaluate(theta, k, zero_a, zero_b, False,
                                                              True)
    extra = planar.project_loads(chain, theta, (FieldLoad(in_plane),))
    assert base_energy + extra[0] == pytest.approx(energy, rel=1e-12)
    np.testing.assert_allclose(base_gradient + extra[1], gradient, rtol=1e-10, atol=1e-18)
    dense = planar.hessian_dense(theta, k, a, b)
    base_dense = planar.hessian_dense(theta, k, zero_a, zero_b)
    np.testing.assert_allclose(base_dense + extra[2], dense, rtol=1e-9, atol=1e-18)


@pytest.mark.parametrize('dof', [1, 3])
def test_a_new_load_is_projected_exactly_by_either_joint_model(dof):
    chain, rng = chain_of(4, 2)
    loads = (Tether(0.3, rng.normal(0, 0.005, 3)), FieldLoad(rng.normal(0, 0.01, 3)))
    if dof == 3:
        def evaluate(x, hessian=False):
            state = spatial.evaluate(chain, x.reshape(4, 3), np.zeros(3), hessian=hessian,
                                     loads=loads)
            return state.energy_j, state.gradient.reshape(-1), state.hessian
        x = rng.uniform(-1, 1, 12)
    else:
        def evaluate(x, hessian=False):
            return planar.project_loads(chain, x, loads, hessian)
        x = rng.uniform(-1, 1, 4)
    energy, gradient, hessian = evaluate(x, True)
    eps, eye = 1e-6, np.eye(len(x))
    fd_gradient = [(evaluate(x + eps * e)[0] - evaluate(x - eps * e)[0]) / (2 * eps)
                   for e in eye]
    np.testing.assert_allclose(gradient, fd_gradient, rtol=1e-6,
                               atol=1e-8 * np.abs(fd_gradient).max())
    fd_hessian = np.array([(evaluate(x + eps * e)[1] - evaluate(x - eps * e)[1]) / (2 * eps)
                           for e in eye])
    np.testing.assert_allclose(hessian, fd_hessian, rtol=1e-5,
                               atol=1e-7 * np.abs(fd_hessian).max())
    summed = link_loads.total(loads, rng.normal(size=(4, 3)), rng.normal(size=(4, 3)))
    assert summed.hessian.shape == (24, 24)


def test_no_loads_is_nothing():
    assert link_loads.total((), np.zeros((2, 3)), np.zeros((2, 3))) is None
    chain, _ = chain_of(3, 3)
    one_segment = dataclasses.replace(chain, segment_index=np.zeros(3, dtype=int))
    assert link_loads.of_chain(one_segment, dipoles=True) == ()   # no pair to interact
    assert link_loads.of_chain(chain, dipoles=False) == ()
    assert len(link_loads.of_chain(chain, dipoles=True)) == 1       # every link its own
