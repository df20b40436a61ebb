"""
How far a predicted body keeps off the scene's obstacles and walls (rig frame, m).

The body is its links, each a capsule of its segment's section radius around the chord from
joint to joint; a spherical obstacle is its ball, a wall its points. The gap is surface to
surface: negative where the body would run into the obstacle.
"""

import numpy as np


def _distances(points_m, starts_m, ends_m):
    """Return (k, n): the distance of each of k points from each of n segments, m."""
    ab = ends_m - starts_m                                        # (n, 3)
    ap = points_m[:, None, :] - starts_m[None, :, :]              # (k, n, 3)
    length2 = np.maximum(np.sum(ab * ab, axis=1), 1e-30)
    t = np.clip(np.einsum('knc,nc->kn', ap, ab) / length2, 0.0, 1.0)
    return np.linalg.norm(ap - t[..., None] * ab[None], axis=2)


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
