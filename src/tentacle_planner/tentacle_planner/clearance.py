"""
How far a predicted body keeps off the scene's obstacles and walls (rig frame, m).

The body is its links, each a capsule of its segment's section radius around the chord from
joint to joint; a spherical obstacle is its ball, a wall its points. The gap is surface to
surface: negative where the body would run into the obstacle.
"""

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
    points = np.asarray(points_m, dtype=float)
    radii = np.asarray(link_radii_m, dtype=float)
    a, b = points[:-1], points[1:]
    n = len(radii)
    centres = [(sphere.centre_m, sphere.radius_m) for sphere in spheres]
    for wall in walls:   # each wall as its point nearest each link, radius 0
        distances = _distances(wall.points_m, a, b)                 # (k, n)
        nearest = wall.points_m[np.argmin(distances, axis=0)]       # (n, 3)
        centres.append((nearest, 0.0))
    gaps = np.zeros((n, len(centres)))
    gradients = np.zeros((n, len(centres), 2, 3))
    ab = b - a
    length2 = np.maximum(np.sum(ab * ab, axis=1), 1e-30)
    for j, (centre, radius) in enumerate(centres):
        c = np.broadcast_to(centre, (n, 3))   # a wall's nearest point differs per link
        t = np.clip(np.sum((c - a) * ab, axis=1) / length2, 0.0, 1.0)
        away = a + t[:, None] * ab - c
        distance = np.linalg.norm(away, axis=1)
        gaps[:, j] = distance - radii - radius
        unit = np.divide(away, distance[:, None], out=np.zeros_like(away),
                         where=distance[:, None] > 1e-15)
        gradients[:, j, 0] = (1.0 - t)[:, None] * unit
        gradients[:, j, 1] = t[:, None] * unit
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
