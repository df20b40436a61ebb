"""
Magnetostatic interaction of point dipoles: energy and its exact first and second derivatives.

Moments m_i (A m^2) at centres c_i (m), both in the world frame. A pair (i, j) with
a = m_i, b = m_j and r = c_j - c_i = d u (|u| = 1) has the energy

    U_ij = e [a.b - 3 (a.u)(b.u)],   e = mu0 / (4 pi d^3)

With p = a.u, q = b.u, s = a.b and v = q a + p b its derivatives are

    dU/da = e (b - 3 q u)  (minus the field of b at c_i),   dU/db = e (a - 3 p u)
    dU/dr = e / d (15 p q u - 3 (s u + v))
    d2U/da db = e (I - 3 u u^T)
    d2U/da dr = e / d (15 q u u^T - 3 (b u^T + u b^T + q I))   (b and r: swap a, p for b, q)
    d2U/dr dr = e / d^2 (15 (s u u^T + v u^T + u v^T + p q I) - 105 p q u u^T
                         - 3 (s I + a b^T + b a^T))

and dU/dc_j = dU/dr = -dU/dc_i (rows index the first variable, columns the second). U is
bilinear in the moments of two different links, so d2U/da da = 0; it depends on the centres
only through their differences, so in every row the blocks of the centres sum to zero and a
link's own centre block is minus the sum of its blocks with the other links. All of it is
one compiled pass over the pairs (_compiled).
"""

from dataclasses import dataclass
import math

import numba
import numpy as np
from tentacle_model.tentacle_spec import MU0

_K = MU0 / (4 * math.pi)  # T m / A


@dataclass(frozen=True)
class Interaction:
    """
    The interaction energy of the given pairs and its derivatives, world frame, SI units.

    The Hessian is with respect to x = concatenate([moments.ravel(), centres.ravel()]): the
    first 3n entries are the moments in link order (x, y, z each), the last 3n the centres.
    """

    energy_j: float
    grad_moments: np.ndarray  # (n, 3) dU/dm_i, T; the other links' field at c_i is minus this
    grad_centres: np.ndarray  # (n, 3) dU/dc_i, N; the force on link i is minus this
    hessian: np.ndarray | None  # (6n, 6n), symmetric; None unless asked for


def pairs_between_groups(groups):
    """
    Return the pairs (i, j) with i < j whose groups differ, two (p,) index arrays.

    Links of one segment are one magnet, so they exert nothing on each other.

    :param groups: (n,) group of each link (e.g. its segment index)
    """
    groups = np.asarray(groups)
    if groups.ndim != 1:
        raise ValueError(f'groups must be one-dimensional, got shape {groups.shape}')
    i, j = np.triu_indices(len(groups), 1)
    keep = groups[i] != groups[j]
    return i[keep], j[keep]


def _checked(moments_a_m2, centres_m, pairs):
    """Return moments, centres (n, 3) and the pair indices i, j (p,), or raise ValueError."""
    m = np.asarray(moments_a_m2, dtype=float)
    c = np.asarray(centres_m, dtype=float)
    if m.ndim != 2 or m.shape[1] != 3 or c.shape != m.shape:
        raise ValueError(f'moments and centres must both be (n, 3), got {m.shape} and {c.shape}')
    if not (np.isfinite(m).all() and np.isfinite(c).all()):
        raise ValueError('moments and centres must be finite')
    i, j = (np.asarray(k) for k in pairs)  # a (2, p) array works too
    if i.shape != j.shape or i.ndim != 1:
        raise ValueError(f'pairs must be two (p,) index arrays, got {i.shape} and {j.shape}')
    if i.size == 0:  # np.asarray([]) is float
        return m, c, i.astype(np.intp), j.astype(np.intp)
    if not (np.issubdtype(i.dtype, np.integer) and np.issubdtype(j.dtype, np.integer)):
        raise ValueError('pair indices must be integers')
    n = len(m)
    if min(i.min(), j.min()) < 0 or max(i.max(), j.max()) >= n:
        raise ValueError(f'pair indices must lie in [0, {n})')
    same = np.flatnonzero(i == j)
    if same.size:
        raise ValueError(f'pair {same[0]} couples link {i[same[0]]} with itself')
    # The Hessian is assembled by assignment, not accumulation: each pair must be unique.
    # Sorted keys (as from pairs_between_groups) are checked in O(p), others by sorting.
    key = np.minimum(i, j) * n + np.maximum(i, j)
    if not (np.diff(key) > 0).all() and np.unique(key).size != key.size:
        raise ValueError('pairs must not repeat (in either order)')
    return m, c, i.astype(np.intp), j.astype(np.intp)


class Contact(ValueError):
    """Two paired magnets closer than they can be: the point-dipole model has no contact."""


def interaction(moments_a_m2, centres_m, pairs, hessian=True, min_distance_m=None):
    """
    Return the Interaction (energy, gradients, optionally the Hessian) of the given pairs.

    :param moments_a_m2: (n, 3) magnetic moment of each link, world frame, A m^2
    :param centres_m: (n, 3) position of each dipole, world frame, m
    :param pairs: (i, j), two (p,) integer arrays, each unordered pair at most once (e.g. from
        pairs_between_groups); only these pairs interact
    :param hessian: also compute the (6n, 6n) Hessian
    :param min_distance_m: (p,) the closest each pair's centres may come (the magnets touch)
    :raises Contact: a pair closer than its min_distance_m (point dipoles would attract
        without bound there)
    :raises ValueError: on malformed or non-finite input, or two paired dipoles at one point
    """
    m, c, i, j = _checked(moments_a_m2, centres_m, pairs)
    return pair_interaction(m, c, i, j, hessian, min_distance_m)


def pair_interaction(moments_a_m2, centres_m, i, j, hessian=True, min_distance_m=None):
    """
    Return interaction()'s answer for pairs known to be well formed (link_loads' own).

    One compiled pass over the pairs (_compiled): 0.2 ms of numpy calls a solve step on
    ch6_coiling's 32 links became a few microseconds.

    :param i, j: (p,) integer link indices of the pairs, each unordered pair once
    :raises Contact: as interaction()
    :raises ValueError: non-finite moments or centres, or two paired dipoles at one point
    """
    m = np.ascontiguousarray(moments_a_m2, dtype=float)
    c = np.ascontiguousarray(centres_m, dtype=float)
    if not (np.isfinite(m).all() and np.isfinite(c).all()):
        raise ValueError('moments and centres must be finite')
    limits = np.zeros(0) if min_distance_m is None else np.asarray(min_distance_m, float)
    energy, grad_m, grad_c, full, problem, k, d = _compiled(
        m, c, np.asarray(i, dtype=np.intp), np.asarray(j, dtype=np.intp), limits, hessian)
    if problem == _TOUCHING:
        raise Contact(f'the magnets of links {i[k]} and {j[k]} touch: centres '
                      f'{d * 1e3:.3g} mm apart, closer than {limits[k] * 1e3:.3g}'
                      ' mm (contact is not modelled)')
    if problem == _COINCIDENT:
        raise ValueError(f'links {i[k]} and {j[k]} are {d} m apart: paired dipoles need '
                         f'distinct centres ({c[i[k]].tolist()} m)')
    return Interaction(energy, grad_m, grad_c, full if hessian else None)


_TOUCHING, _COINCIDENT = 1, 2


@numba.njit(cache=True, error_model='numpy')   # d = 0: inf, refused by name
def _compiled(m, c, i, j, limits, hessian):
    """
    Return (energy, dU/dm (n, 3), dU/dc (n, 3), Hessian (6n, 6n), problem, pair, distance).

    problem: 0, _TOUCHING (the pair closest to its limit, relatively) or _COINCIDENT (the
    first pair whose d^-5 is not finite); the module docstring's formulae, pair by pair.
    """
    n, count = m.shape[0], i.shape[0]
    d = np.empty(count)
    for k in range(count):
        r0, r1, r2 = c[j[k], 0] - c[i[k], 0], c[j[k], 1] - c[i[k], 1], c[j[k], 2] - c[i[k], 2]
        d[k] = np.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
    size = 6 * n if hessian else 0
    full = np.zeros((size, size))
    grad_m, grad_c = np.zeros((n, 3)), np.zeros((n, 3))
    if limits.shape[0]:
        worst, closest = -1, np.inf
        for k in range(count):
            if d[k] < limits[k] and d[k] / limits[k] < closest:
                worst, closest = k, d[k] / limits[k]
        if worst >= 0:
            return 0.0, grad_m, grad_c, full, _TOUCHING, worst, d[worst]
    for k in range(count):
        e = _K / d[k] ** 3
        if not np.isfinite(e / d[k] / d[k]):   # d = 0, or so small that d^-5 overflows
            return 0.0, grad_m, grad_c, full, _COINCIDENT, k, d[k]
    energy = 0.0
    own_mc = np.zeros((n, 3, 3))   # a link's moment-centre block: minus its others' sum
    own_cc = np.zeros((n, 3, 3))
    # Scratch written in place pair by pair: an array made per pair cost more than its maths.
    u, v = np.empty(3), np.empty(3)
    h_ab, h_ar, h_br, h_rr = (np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3)),
                              np.empty((3, 3)))
    for k in range(count):
        a, b = m[i[k]], m[j[k]]
        e = _K / d[k] ** 3
        f = e / d[k]
        g = f / d[k]
        p = q = s = 0.0
        for x in range(3):
            u[x] = (c[j[k], x] - c[i[k], x]) / d[k]
            p += a[x] * u[x]
            q += b[x] * u[x]
            s += a[x] * b[x]
        pq = p * q
        energy += e * (s - 3 * pq)
        for x in range(3):
            v[x] = q * a[x] + p * b[x]
            grad_r = f * (15 * pq * u[x] - 3 * (s * u[x] + v[x]))
            grad_m[i[k], x] += e * (b[x] - 3 * q * u[x])
            grad_m[j[k], x] += e * (a[x] - 3 * p * u[x])
            grad_c[i[k], x] -= grad_r
            grad_c[j[k], x] += grad_r
        if not hessian:
            continue
        for row in range(3):
            for col in range(row, 3):
                uu = u[row] * u[col]
                eye = 1.0 if row == col else 0.0
                h_ab[row, col] = e * eye - 3 * e * uu
                h_ar[row, col] = 15 * f * q * uu - 3 * f * (b[row] * u[col] + u[row] * b[col]) \
                    - 3 * f * q * eye
                h_br[row, col] = 15 * f * p * uu - 3 * f * (a[row] * u[col] + u[row] * a[col]) \
                    - 3 * f * p * eye
                h_rr[row, col] = g * (15 * (s * uu + (v[row] * u[col] + u[row] * v[col])
                                            + pq * eye) - 105 * pq * uu
                                      - 3 * (s * eye + (a[row] * b[col] + b[row] * a[col])))
                for block in (h_ab, h_ar, h_br, h_rr):
                    block[col, row] = block[row, col]
        mi, mj, ci, cj = 3 * i[k], 3 * j[k], 3 * n + 3 * i[k], 3 * n + 3 * j[k]
        for row in range(3):
            for col in range(3):
                full[mi + row, mj + col] = full[mj + col, mi + row] = h_ab[row, col]
                full[mi + row, cj + col] = full[cj + col, mi + row] = h_ar[row, col]
                full[ci + row, mj + col] = full[mj + col, ci + row] = -h_br[row, col]
                full[ci + row, cj + col] = full[cj + col, ci + row] = -h_rr[row, col]
                own_mc[i[k], row, col] -= h_ar[row, col]
                own_mc[j[k], row, col] += h_br[row, col]
                own_cc[i[k], row, col] += h_rr[row, col]
                own_cc[j[k], row, col] += h_rr[row, col]
    if hessian:
        for link in range(n):
            mi, ci = 3 * link, 3 * n + 3 * link
            for row in range(3):
                for col in range(3):
                    full[mi + row, ci + col] = full[ci + col, mi + row] = own_mc[link, row, col]
                    full[ci + row, ci + col] = 0.5 * (own_cc[link, row, col]
                                                      + own_cc[link, col, row])
    return energy, grad_m, grad_c, full, 0, -1, 0.0
