"""
How far a predicted body keeps off the scene's obstacles and walls (rig frame, m).

The body is its links, each a capsule of its segment's section radius around the chord from
joint to joint; a spherical obstacle is its ball, a wall its points. The gap is surface to
surface: negative where the body would run into the obstacle.
"""

import numba
import numpy as np


def _nearest(points_m, starts_m, ends_m):
    """Return (t (k, n), q (k, n, 3)): where on each of n segments each of k points is nearest."""
    ab = ends_m - starts_m                                        # (n, 3)
    ap = points_m[:, None, :] - starts_m[None, :, :]              # (k, n, 3)
    length2 = np.maximum(np.sum(ab * ab, axis=1), 1e-30)
    t = np.clip(np.einsum('knc,nc->kn', ap, ab) / length2, 0.0, 1.0)
    return t, starts_m[None] + t[..., None] * ab[None]


def _distances(points_m, starts_m, ends_m):
    """Return (k, n): the distance of each of k points from each of n segments, m."""
    return np.linalg.norm(points_m[:, None, :] - _nearest(points_m, starts_m, ends_m)[1], axis=2)


def link_gap_gradients(points_m, link_radii_m, spheres=(), walls=()):
    """
    Return (gaps (n, m), gradients (n, m, 2, 3)): link_gaps and their derivatives, m/m.

    gradients[i, j, 0] is d gaps[i, j] / d points[i] (the link's start), [i, j, 1] by
    points[i + 1] (its end). The nearest point on the link moves with it, its place along the
    link held (it is optimal there, or at an end); a wall's gap is its nearest point's. Where
    an obstacle's centre lies on a link's axis the direction is undefined: zero is returned.
    """
    return gap_gradients(np.ascontiguousarray(points_m, dtype=float),
                         np.asarray(link_radii_m, dtype=float), *gap_arrays(spheres, walls))


def gap_arrays(spheres=(), walls=()):
    """Return (centres (m, 3), radii (m,), wall points (k, 3), wall ends (w,)), m, as arrays."""
    centres = np.array([sphere.centre_m for sphere in spheres], dtype=float).reshape(-1, 3)
    radii = np.array([sphere.radius_m for sphere in spheres], dtype=float)
    wall_points = np.concatenate([np.zeros((0, 3))] + [wall.points_m for wall in walls])
    wall_ends = np.cumsum([len(wall.points_m) for wall in walls], dtype=np.int64)
    return centres, radii, np.ascontiguousarray(wall_points, dtype=float), wall_ends


@numba.njit(cache=True)
def gap_gradients(points, link_radii, centres, radii, wall_points, wall_ends):
    """Return link_gap_gradients' answer, compiled, for the obstacles as gap_arrays gives them."""
    n, spheres = link_radii.shape[0], radii.shape[0]
    columns = spheres + wall_ends.shape[0]
    gaps = np.zeros((n, columns))
    gradients = np.zeros((n, columns, 2, 3))
    for i in range(n):
        a0, a1, a2 = points[i]
        ab0, ab1, ab2 = points[i + 1, 0] - a0, points[i + 1, 1] - a1, points[i + 1, 2] - a2
        length2 = max(ab0 * ab0 + ab1 * ab1 + ab2 * ab2, 1e-30)
        for j in range(columns):
            if j < spheres:
                c0, c1, c2 = centres[j]
                radius = radii[j]
            else:   # a wall: its point nearest the link, radius 0
                first = 0 if j == spheres else wall_ends[j - spheres - 1]
                best, nearest = np.inf, first
                for k in range(first, wall_ends[j - spheres]):
                    p0, p1, p2 = wall_points[k, 0] - a0, wall_points[k, 1] - a1, \
                        wall_points[k, 2] - a2
                    t = min(max((p0 * ab0 + p1 * ab1 + p2 * ab2) / length2, 0.0), 1.0)
                    d0, d1, d2 = t * ab0 - p0, t * ab1 - p1, t * ab2 - p2
                    distance2 = d0 * d0 + d1 * d1 + d2 * d2
                    if distance2 < best:
                        best, nearest = distance2, k
                c0, c1, c2 = wall_points[nearest]
                radius = 0.0
            t = min(max(((c0 - a0) * ab0 + (c1 - a1) * ab1 + (c2 - a2) * ab2) / length2, 0.0),
                    1.0)
            away = np.array([a0 + t * ab0 - c0, a1 + t * ab1 - c1, a2 + t * ab2 - c2])
            distance = np.sqrt(away[0] ** 2 + away[1] ** 2 + away[2] ** 2)
            gaps[i, j] = distance - link_radii[i] - radius
            if distance > 1e-15:
                gradients[i, j, 0] = (1.0 - t) * away / distance
                gradients[i, j, 1] = t * away / distance
    return gaps, gradients


def link_gaps(points_m, link_radii_m, spheres=(), walls=()):
    """
    Return (n, m): each link's smallest surface-to-surface gap to each obstacle, then wall, m.

    :param points_m: (n + 1, 3) the body's joints and tip
    :param link_radii_m: (n,) each link's section radius, m
    :param spheres: scene.Sphere obstacles (the first columns)
    :param walls: scene.Wall point sets (the last columns)
    """
    points = np.asarray(points_m, dtype=float)
    radii = np.asarray(link_radii_m, dtype=float)
    a, b = points[:-1], points[1:]
    columns = [_distances(sphere.centre_m[None], a, b)[0] - radii - sphere.radius_m
               for sphere in spheres]
    columns += [np.min(_distances(wall.points_m, a, b), axis=0) - radii for wall in walls]
    return np.column_stack(columns) if columns else np.zeros((len(radii), 0))


def clearance(points_m, link_radii_m, spheres=(), walls=()):
    """
    Return (gap, what): the smallest surface-to-surface gap of the body, m, and what it is to.

    :param points_m: (n + 1, 3) the body's joints and tip
    :param link_radii_m: (n,) each link's section radius, m
    :param spheres: scene.Sphere obstacles
    :param walls: scene.Wall point sets
    :return: (inf, None) without obstacles; what is 'obstacle i' or 'wall i', from 1
    """
    gaps = link_gaps(points_m, link_radii_m, spheres, walls)
    if gaps.size == 0:
        return float('inf'), None
    least = np.min(gaps, axis=0)
    k = int(np.argmin(least))
    what = f'obstacle {k + 1}' if k < len(spheres) else f'wall {k - len(spheres) + 1}'
    return float(least[k]), what
