"""
A plan's direction unknowns as magnetisation directions, and the neighbour-angle rows: compiled.

Each free segment's direction has an azimuth (and, off the plane, an elevation), rad:
d = (cos e cos a, cos e sin a, sin e) in the link frame. Both functions are called once an
evaluation of the objective; as numpy calls on a handful of segments they cost as much as a
key step of the model (28 us of the neighbour rows alone, pancreatic duct).
"""

import numba
import numpy as np


@numba.njit(cache=True)
def directions(x, held, free_segments, angles_per_segment):
    """
    Return each segment's direction (segments, 3) and d it / d its angles (segments, angles, 3).

    :param x: the unknowns; a free segment's angles come first, in free_segments' order
    :param held: (segments, 3) the directions of segments that are not free (zero: passive)
    :param free_segments: (f,) segment indices whose directions are unknowns
    :param angles_per_segment: 1 (azimuth) or 2 (azimuth, elevation)
    """
    out = held.copy()
    derivatives = np.zeros((held.shape[0], angles_per_segment, 3))
    for k in range(free_segments.shape[0]):
        i = free_segments[k]
        azimuth = x[k * angles_per_segment]
        elevation = x[k * angles_per_segment + 1] if angles_per_segment == 2 else 0.0
        ca, sa, ce, se = np.cos(azimuth), np.sin(azimuth), np.cos(elevation), np.sin(elevation)
        out[i, 0], out[i, 1], out[i, 2] = ce * ca, ce * sa, se
        derivatives[i, 0, 0], derivatives[i, 0, 1] = -ce * sa, ce * ca
        if angles_per_segment == 2:
            derivatives[i, 1, 0], derivatives[i, 1, 1], derivatives[i, 1, 2] = \
                -se * ca, -se * sa, ce
    return out, derivatives


@numba.njit(cache=True)
def neighbour_rows(directions, derivatives, a, b, column_a, column_b, cos_limit, weight,
                   size):
    """
    Return (r (p,), dr/dx (p, size)) of neighbouring segments a, b (p,) each.

    r = weight (cos_limit - d_a . d_b) where the pair is further apart than the limit, else
    0; column_a, column_b (p,): the first unknown of each segment's angles, -1 if it is held.
    """
    count, angles = a.shape[0], derivatives.shape[1]
    r, jac = np.zeros(count), np.zeros((count, size))
    for row in range(count):
        da, db = directions[a[row]], directions[b[row]]
        excess = cos_limit - (da[0] * db[0] + da[1] * db[1] + da[2] * db[2])
        if excess <= 0:
            continue
        r[row] = weight * excess
        for this, other, column in ((a[row], b[row], column_a[row]),
                                    (b[row], a[row], column_b[row])):
            if column < 0:
                continue
            d = directions[other]
            for j in range(angles):
                g = derivatives[this, j]
                jac[row, column + j] = -weight * (d[0] * g[0] + d[1] * g[1] + d[2] * g[2])
    return r, jac
