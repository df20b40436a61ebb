"""Dipole-dipole interaction: textbook numbers, exact derivatives and the conservation laws."""

import math

import numpy as np
import pytest
from tentacle_model.dipoles import interaction, pairs_between_groups

MU0 = 4e-7 * math.pi  # written out here, so the references do not share the module's constant


def field(moment, r):
    """Return the textbook B (3,), tesla, of a dipole (3,) at displacement r (3,) from it."""
    d = np.linalg.norm(r)
    u = r / d
    return MU0 / (4 * math.pi) * (3 * u * np.dot(u, moment) - moment) / d**3


def reference_energy(moments, centres, pairs):
    """Return sum over pairs of -m_i . B_j(c_i), one pair at a time."""
    return sum(-np.dot(moments[i], field(moments[j], centres[i] - centres[j]))
               for i, j in zip(*pairs))


def random_dipoles(n, seed):
    """Return moments (~1e-4 A m^2), centres (1 cm box, >= 1 mm apart) and mixed groups."""
    rng = np.random.default_rng(seed)
    moments = rng.normal(0, 1e-4, (n, 3))
    while True:
        centres = rng.uniform(0, 1e-2, (n, 3)) + rng.normal(0, 0.1, 3)  # off the origin
        gaps = np.linalg.norm(centres[:, None] - centres[None], axis=2) + np.eye(n)
        if gaps.min() > 1e-3:
            break
    groups = rng.permutation(np.arange(n) % 3)
    return moments, centres, groups, rng


def rotation(rng):
    """Return a random proper rotation matrix, (3, 3)."""
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def rotate(axis, angle, vector):
    """Return vector turned by angle about the unit axis (Rodrigues)."""
    return (vector * math.cos(angle) + np.cross(axis, vector) * math.sin(angle)
            + axis * np.dot(axis, vector) * (1 - math.cos(angle)))


def flat(result):
    """Return the gradient as one vector in the Hessian's order (moments, then centres)."""
    return np.concatenate([result.grad_moments.ravel(), result.grad_centres.ravel()])


M1, M2, R = 2e-4, 3e-4, 4e-3  # A m^2, A m^2, m
ONE_PAIR = (np.array([0]), np.array([1]))


def test_coaxial_dipoles_attract():
    result = interaction([[M1, 0, 0], [M2, 0, 0]], [[0, 0, 0], [R, 0, 0]], ONE_PAIR)
    # pytest.approx adds abs=1e-12 unless told otherwise: far too loose for these numbers.
    energy = -MU0 * M1 * M2 / (2 * math.pi * R**3)
    assert energy == pytest.approx(-1.875e-7, rel=1e-12, abs=0)
    assert result.energy_j == pytest.approx(energy, rel=1e-12, abs=0)
    force = 3 * MU0 * M1 * M2 / (2 * math.pi * R**4)  # magnitude, N
    assert force == pytest.approx(1.40625e-4, rel=1e-12, abs=0)
    # The force (minus the gradient) pulls each dipole towards the other.
    np.testing.assert_allclose(result.grad_centres, [[-force, 0, 0], [force, 0, 0]],
                               rtol=1e-12, atol=1e-12 * force)


def test_side_by_side_dipoles_repel():
    result = interaction([[0, M1, 0], [0, M2, 0]], [[0, 0, 0], [R, 0, 0]], ONE_PAIR)
    energy = MU0 * M1 * M2 / (4 * math.pi * R**3)
    assert energy == pytest.approx(9.375e-8, rel=1e-12, abs=0)
    assert result.energy_j == pytest.approx(energy, rel=1e-12, abs=0)
    force = 3 * MU0 * M1 * M2 / (4 * math.pi * R**4)
    np.testing.assert_allclose(result.grad_centres, [[force, 0, 0], [-force, 0, 0]],
                               rtol=1e-12, atol=1e-12 * force)


@pytest.mark.parametrize('seed', range(3))
def test_moment_gradient_is_minus_the_partners_field_and_gives_the_torque(seed):
    moments, centres, groups, rng = random_dipoles(5, seed)
    pairs = pairs_between_groups(groups)
    result = interaction(moments, centres, pairs)
    for k in range(5):
        partners = [j for i, j in zip(*pairs) if i == k] + [i for i, j in zip(*pairs) if j == k]
        b = sum((field(moments[j], centres[k] - centres[j]) for j in partners), np.zeros(3))
        np.testing.assert_allclose(-result.grad_moments[k], b, rtol=1e-12,
                                   atol=1e-12 * np.abs(b).max())
        # Torque m x B against the energy's change as m_k alone turns: dU/dangle = -axis . tau.
        torque = np.cross(moments[k], b)
        for axis in np.eye(3):
            def energy(angle):
                turned = moments.copy()
                turned[k] = rotate(axis, angle, moments[k])
                return interaction(turned, centres, pairs, hessian=False).energy_j
            step = 1e-6
            slope = (energy(step) - energy(-step)) / (2 * step)
            assert -slope == pytest.approx(np.dot(axis, torque), rel=1e-6,
                                           abs=1e-9 * np.abs(torque).max())


@pytest.mark.parametrize('seed', range(5))
def test_energy_matches_the_pairwise_textbook_sum(seed):
    moments, centres, groups, _ = random_dipoles(6, seed)
    pairs = pairs_between_groups(groups)
    assert interaction(moments, centres, pairs).energy_j == pytest.approx(
        reference_energy(moments, centres, pairs), rel=1e-12, abs=0)


@pytest.mark.parametrize('seed', range(4))
def test_gradient_and_hessian_match_finite_differences(seed):
    n = 5
    moments, centres, groups, _ = random_dipoles(n, seed)
    pairs = pairs_between_groups(groups)
    x = np.concatenate([moments.ravel(), centres.ravel()])
    # Central differences: the energy is bilinear in the moments (exact up to rounding); in
    # the centres the truncation error is ~ (step / gap)^2 with gaps >= 1 mm.
    steps = np.concatenate([np.full(3 * n, 1e-9), np.full(3 * n, 1e-8)])  # A m^2, m

    def at(x, hessian=False):
        return interaction(x[:3 * n].reshape(n, 3), x[3 * n:].reshape(n, 3), pairs, hessian)

    result = at(x, hessian=True)
    basis = np.eye(6 * n) * steps
    fd_grad = np.array([(at(x + h).energy_j - at(x - h).energy_j) for h in basis]) / (2 * steps)
    np.testing.assert_allclose(flat(result), fd_grad, rtol=1e-6,
                               atol=1e-8 * np.abs(fd_grad).max())
    fd_hess = np.column_stack([flat(at(x + h)) - flat(at(x - h)) for h in basis]) / (2 * steps)
    np.testing.assert_allclose(result.hessian, fd_hess, rtol=1e-6,
                               atol=1e-8 * np.abs(fd_hess).max())


@pytest.mark.parametrize('seed', range(3))
def test_hessian_structure_and_homogeneity(seed):
    n = 6
    moments, centres, groups, _ = random_dipoles(n, seed)
    result = interaction(moments, centres, pairs_between_groups(groups))
    h = result.hessian
    assert h.shape == (6 * n, 6 * n)
    np.testing.assert_array_equal(h, h.T)
    blocks = h.reshape(2, n, 3, 2, n, 3)
    for k in range(n):
        for ell in range(n):
            if groups[k] == groups[ell] and k != ell:  # one magnet: no coupling at all
                assert not blocks[:, k, :, :, ell, :].any()
        assert not blocks[0, k, :, 0, k, :].any()  # U is linear in each moment
    # U is homogeneous of degree 2 in the moments and -3 in the centres (translation
    # invariant, so about any origin); Euler's theorem for U and for its gradient.
    gm, gc = result.grad_moments.ravel(), result.grad_centres.ravel()
    m, c = moments.ravel(), centres.ravel()
    u = result.energy_j
    assert np.dot(m, gm) == pytest.approx(2 * u, rel=1e-12, abs=0)
    assert np.dot(c, gc) == pytest.approx(-3 * u, rel=1e-9, abs=0)  # |c| >> gaps: cancels
    hmm, hmc = h[:3 * n, :3 * n], h[:3 * n, 3 * n:]
    hcm, hcc = h[3 * n:, :3 * n], h[3 * n:, 3 * n:]
    for product, expected in ((hmm @ m, gm), (hcm @ m, 2 * gc),
                              (hmc @ c, -3 * gm), (hcc @ c, -4 * gc)):
        np.testing.assert_allclose(product, expected, rtol=1e-9,
                                   atol=1e-9 * np.abs(expected).max())


@pytest.mark.parametrize('seed', range(3))
def test_newtons_third_law_and_torque_balance(seed):
    moments, centres, groups, _ = random_dipoles(7, seed)
    result = interaction(moments, centres, pairs_between_groups(groups))
    grad_c = result.grad_centres  # minus the forces
    np.testing.assert_allclose(grad_c.sum(axis=0), 0, atol=1e-12 * np.abs(grad_c).max())
    # Rotating everything leaves U alone: the internal torques, m x dU/dm + c x dU/dc, cancel.
    terms = np.cross(moments, result.grad_moments) + np.cross(centres, grad_c)
    scale = np.abs(np.cross(centres, grad_c)).max()
    np.testing.assert_allclose(terms.sum(axis=0), 0, atol=1e-12 * scale)
    # Moving all centres together changes no derivative either: in every row of the Hessian
    # the centre columns sum to zero. (The module fills each link's own centre block that
    # way, so this checks the assembly; the finite differences check the values.)
    sums = result.hessian[:, 21:].reshape(42, 7, 3).sum(axis=1)
    np.testing.assert_allclose(sums, 0, atol=1e-12 * np.abs(result.hessian).max())


@pytest.mark.parametrize('seed', range(3))
def test_rigid_motion_leaves_the_energy_and_turns_the_derivatives(seed):
    n = 5
    moments, centres, groups, rng = random_dipoles(n, seed)
    pairs = pairs_between_groups(groups)
    turn, shift = rotation(rng), rng.normal(0, 0.05, 3)
    before = interaction(moments, centres, pairs)
    after = interaction(moments @ turn.T, centres @ turn.T + shift, pairs)
    assert after.energy_j == pytest.approx(before.energy_j, rel=1e-12, abs=0)
    big = np.kron(np.eye(2 * n), turn)  # turns every (x, y, z) triple of the state
    np.testing.assert_allclose(flat(after), big @ flat(before), rtol=1e-9,
                               atol=1e-12 * np.abs(flat(before)).max())
    np.testing.assert_allclose(after.hessian, big @ before.hessian @ big.T, rtol=1e-9,
                               atol=1e-12 * np.abs(before.hessian).max())


def test_pairs_between_groups_skips_links_of_one_segment():
    i, j = pairs_between_groups([0, 0, 1, 1, 2])
    assert list(zip(i.tolist(), j.tolist())) == [(0, 2), (0, 3), (0, 4), (1, 2), (1, 3),
                                                 (1, 4), (2, 4), (3, 4)]
    groups = np.repeat(np.arange(5), 10)  # 50 links, 5 segments
    i, j = pairs_between_groups(groups)
    assert len(i) == 50 * 49 // 2 - 5 * 10 * 9 // 2
    assert (i < j).all() and (groups[i] != groups[j]).all()
    for groups in ([3, 3, 3], [7], []):
        i, j = pairs_between_groups(groups)
        assert len(i) == len(j) == 0
    with pytest.raises(ValueError):
        pairs_between_groups([[0, 1]])


def test_no_pairs_no_interaction():
    moments, centres, _, _ = random_dipoles(4, 0)
    for pairs in (pairs_between_groups([1, 1, 1, 1]), ([], [])):
        result = interaction(moments, centres, pairs)
        assert result.energy_j == 0.0
        assert result.grad_moments.shape == result.grad_centres.shape == (4, 3)
        assert not result.grad_moments.any() and not result.grad_centres.any()
        assert result.hessian.shape == (24, 24) and not result.hessian.any()
    assert interaction(moments, centres, ([], []), hessian=False).hessian is None


def test_without_hessian_the_rest_is_the_same():
    moments, centres, groups, _ = random_dipoles(5, 3)
    pairs = pairs_between_groups(groups)
    full, light = interaction(moments, centres, pairs), interaction(moments, centres, pairs,
                                                                    hessian=False)
    assert light.hessian is None
    assert light.energy_j == full.energy_j
    np.testing.assert_array_equal(light.grad_moments, full.grad_moments)
    np.testing.assert_array_equal(light.grad_centres, full.grad_centres)


def test_pair_order_does_not_matter():
    moments, centres, groups, rng = random_dipoles(6, 4)
    i, j = pairs_between_groups(groups)
    order = rng.permutation(len(i))
    flip = rng.random(len(i)) < 0.5
    i2, j2 = np.where(flip, j, i)[order], np.where(flip, i, j)[order]
    a, b = interaction(moments, centres, (i, j)), interaction(moments, centres, (i2, j2))
    assert b.energy_j == pytest.approx(a.energy_j, rel=1e-12, abs=0)
    np.testing.assert_allclose(flat(b), flat(a), rtol=1e-12, atol=1e-15 * np.abs(flat(a)).max())
    np.testing.assert_allclose(b.hessian, a.hessian, rtol=1e-12,
                               atol=1e-15 * np.abs(a.hessian).max())


def test_coincident_centres_are_refused_by_name():
    moments, centres, _, _ = random_dipoles(4, 1)
    centres[3] = centres[1]
    with pytest.raises(ValueError, match='links 1 and 3 '):
        interaction(moments, centres, pairs_between_groups([0, 1, 2, 3]))
    # Not paired (one segment): no problem.
    interaction(moments, centres, pairs_between_groups([0, 1, 2, 1]))
    centres[3, 0] += 1e-200  # d^-5 overflows
    with pytest.raises(ValueError, match='links 1 and 3 '):
        interaction(moments, centres, pairs_between_groups([0, 1, 2, 3]), hessian=False)


@pytest.mark.parametrize('bad', [math.nan, math.inf])
def test_non_finite_input_is_refused(bad):
    moments, centres, _, _ = random_dipoles(3, 2)
    pairs = pairs_between_groups([0, 1, 2])
    for which in (moments, centres):
        spoilt = which.copy()
        spoilt[1, 2] = bad
        args = (spoilt, centres) if which is moments else (moments, spoilt)
        with pytest.raises(ValueError, match='finite'):
            interaction(*args, pairs)


@pytest.mark.parametrize('pairs', [([0, 1], [1, 1]),            # a link with itself
                                   ([0, 1], [1, 0]),            # one pair twice
                                   ([0, 0], [1, 1]),
                                   ([0], [3]), ([-1], [0]),     # no such link
                                   ([0.0], [1.0]),              # not indices
                                   ([0, 1], [2])])              # unequal lengths
def test_malformed_pairs_are_refused(pairs):
    moments, centres, _, _ = random_dipoles(3, 5)
    with pytest.raises(ValueError):
        interaction(moments, centres, pairs)


def test_malformed_arrays_are_refused():
    with pytest.raises(ValueError, match='n, 3'):
        interaction(np.zeros((3, 2)), np.zeros((3, 2)), ([0], [1]))
    with pytest.raises(ValueError, match='n, 3'):
        interaction(np.zeros((3, 3)), np.zeros((4, 3)), ([0], [1]))
