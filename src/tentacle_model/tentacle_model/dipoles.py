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
link's own centre block is minus the sum of its blocks with the other links.
"""

from dataclasses import dataclass
import math

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


def _outer(x, y):
    """Return the outer products x y^T, (3, 3, p), of two (3, p) arrays (one per column)."""
    return x[:, None] * y[None]


def _sym_outer(x, y):
    """Return x y^T + y x^T, (3, 3, p), symmetric to the last bit."""
    xy = _outer(x, y)
    xy += xy.swapaxes(0, 1)  # numpy buffers the overlapping operand
    return xy


def _sum_by_link(links, values, n):
    """Return (..., n): the entries of values (..., q) summed by links (q,) in [0, n)."""
    lead = values.shape[:-1]
    rows = np.arange(math.prod(lead))[:, None] * n + links
    return np.bincount(rows.ravel(), values.ravel(), rows.shape[0] * n).reshape(*lead, n)


def _place(full, block, row_start, col_start, at_ij, at_ji):
    """
    Write symmetric blocks (3, 3, p) at (row link i, column link j) and at (j, i) of each pair.

    :param full: the (size, size) Hessian, C-contiguous
    :param row_start: 0 if the rows are moments, 3n if centres; col_start likewise
    :param at_ij: (p,) flat index of entry (3 i, 3 j), i.e. 3 (i size + j); at_ji likewise
    """
    size = len(full)
    row = row_start + np.arange(3)[:, None, None]  # (3, 1, 1)
    col = col_start + np.arange(3)[:, None]  # (3, 1)
    flat = full.reshape(-1)
    flat[(row * size + col) + at_ij] = block
    flat[(col * size + row) + at_ji] = block


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
    n = len(m)
    # Per-pair arrays are (3, p) and (3, 3, p): with the pairs last every operation runs
    # along one long contiguous axis.
    mt, ct = np.ascontiguousarray(m.T), np.ascontiguousarray(c.T)
    a, b = mt.take(i, axis=1), mt.take(j, axis=1)
    r = ct.take(j, axis=1) - ct.take(i, axis=1)
    d = np.sqrt(np.einsum('kp,kp->p', r, r))
    if min_distance_m is not None:
        touching = np.flatnonzero(d < min_distance_m)
        if touching.size:
            k = touching[np.argmin(d[touching] / np.asarray(min_distance_m)[touching])]
            raise Contact(f'the magnets of links {i[k]} and {j[k]} touch: centres '
                          f'{d[k] * 1e3:.3g} mm apart, closer than {min_distance_m[k] * 1e3:.3g}'
                          ' mm (contact is not modelled)')
    with np.errstate(divide='ignore', over='ignore'):
        e = _K / d**3
        f = e / d
        g = f / d  # the steepest power, d^-5
    coincident = np.flatnonzero(~np.isfinite(g))  # d = 0, or so small that d^-5 overflows
    if coincident.size:
        k = coincident[0]
        raise ValueError(f'links {i[k]} and {j[k]} are {d[k]} m apart: paired dipoles need '
                         f'distinct centres ({c[i[k]].tolist()} m)')
    u = r / d
    p, q = np.einsum('kp,kp->p', a, u), np.einsum('kp,kp->p', b, u)
    s = np.einsum('kp,kp->p', a, b)
    pq = p * q
    v = q * a + p * b
    energy = float(np.dot(e, s - 3 * pq))

    grad_r = f * (15 * pq * u - 3 * (s * u + v))
    grads = np.empty((2, 3, 2 * len(i)))  # [moment or centre, xyz, pair (i's, then j's)]
    np.multiply(e, b - 3 * q * u, out=grads[0, :, :len(i)])  # dU/da
    np.multiply(e, a - 3 * p * u, out=grads[0, :, len(i):])  # dU/db
    np.negative(grad_r, out=grads[1, :, :len(i)])  # dU/dc_i
    grads[1, :, len(i):] = grad_r  # dU/dc_j
    grads = _sum_by_link(np.concatenate([i, j]), grads, n)
    grad_moments, grad_centres = np.ascontiguousarray(grads.transpose(0, 2, 1))
    if not hessian:
        return Interaction(energy, grad_moments, grad_centres, None)

    # One block kind at a time, to keep the temporaries small. All four are symmetric, so
    # the block at (j, i) is the same matrix; with dr/dc_i = -I they are, at (i, j),
    # (m, m): h_ab, (m, c): h_ar, (c, m): -h_br, (c, c): -h_rr.
    size = 6 * n
    full = np.zeros((size, size))
    at_ij, at_ji = 3 * (i * size + j), 3 * (j * size + i)
    uu = _outer(u, u)
    block = -3 * e * uu
    diagonal = block.reshape(9, -1)[::4]  # (3, p) view of the xx, yy, zz entries
    diagonal += e
    _place(full, block, 0, 0, at_ij, at_ji)
    np.multiply(15 * f * q, uu, out=block)
    block -= 3 * f * _sym_outer(b, u)
    diagonal -= 3 * f * q
    _place(full, block, 0, 3 * n, at_ij, at_ji)
    np.multiply(-15 * f * p, uu, out=block)
    block += 3 * f * _sym_outer(a, u)
    diagonal += 3 * f * p
    _place(full, block, 3 * n, 0, at_ij, at_ji)
    np.multiply(g * (105 * pq - 15 * s), uu, out=block)
    block -= 15 * g * _sym_outer(v, u)
    block += 3 * g * _sym_outer(a, b)
    diagonal += g * (3 * s - 15 * pq)
    _place(full, block, 3 * n, 3 * n, at_ij, at_ji)

    # A link's own blocks. Its moment with itself: 0. Its centre column: minus the sum of the
    # other links' centre columns, in every row (translation invariance).
    blocks = full.reshape(2, n, 3, 2, n, 3)
    own = -(np.ones(n) @ blocks[:, :, :, 1].reshape(size, n, 3)).reshape(2, n, 3, 3)
    own_cc = 0.5 * (own[1] + own[1].swapaxes(1, 2))  # symmetric to the last bit, like the rest
    k = np.arange(n)
    blocks[0, k, :, 1, k, :] = own[0]
    blocks[1, k, :, 0, k, :] = own[0].swapaxes(1, 2)
    blocks[1, k, :, 1, k, :] = own_cc
    return Interaction(energy, grad_moments, grad_centres, full)
