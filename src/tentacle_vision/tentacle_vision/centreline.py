"""
The body's centreline, tip and heading from its mask, in pixels (no I/O, no ROS).

A faster equivalent of a skeleton that orders itself: the geodesic distance from the
insertion point through the body (Dial's algorithm on the 16-neighbour grid, chamfer
weights 5, 7 and 11, compiled), cut into bands of equal distance; each band's centroid is a
centreline point, sub-pixel, ordered from base to tip by construction, with no spurs to
prune. The tip
is where the body ends along it: a quadratic fit of the last part of the centreline against
distance gives the end's direction, and the grey-level profile along that direction places
the end edge to a fraction of a pixel. Where the body closes on itself (coiling) its mask
has a hole: ``loops`` reports it instead of a tip.
"""

from dataclasses import dataclass

import cv2
import numba
import numpy as np

UNIT = 5  # geodesic distances are in fifths of a pixel (axial 5, diagonal 7, knight 11)


@numba.njit(cache=True)
def _geodesic(mask, seed):
    """
    Return (visited flat indices, their distances in fifths of a px) from flat index seed.

    ``mask`` is padded by two (its border is background); only the seed's component is
    visited. Knight moves (weight 11) besides the eight neighbours bring the metric within
    2% of the Euclidean one in every direction: with the eight alone it was up to 6% long
    between axis and diagonal, which bent band centroids across a bend (heading p95 2.4 deg,
    now 1.3 deg).
    """
    h, w = mask.shape
    n = h * w
    flat = mask.ravel()
    big = np.int32(2 ** 30)
    dist = np.full(n, big, np.int32)
    items = np.empty(16 * n + 1, np.int32)
    nxt = np.empty(16 * n + 1, np.int32)
    head = np.full(16, -1, np.int32)
    visited = np.empty(n, np.int32)
    at = np.empty(n, np.int32)
    offsets = np.array([-w - 1, -w, -w + 1, -1, 1, w - 1, w, w + 1,
                        -2 * w - 1, -2 * w + 1, -w - 2, -w + 2, w - 2, w + 2,
                        2 * w - 1, 2 * w + 1])
    weights = np.array([7, 5, 7, 5, 5, 7, 5, 7, 11, 11, 11, 11, 11, 11, 11, 11])
    dist[seed] = 0
    items[0], nxt[0], head[0] = seed, -1, 0
    used, pending, d, count = 1, 1, 0, 0
    while pending > 0:
        b = d % 16
        while head[b] != -1:
            k = head[b]
            head[b] = nxt[k]
            pending -= 1
            i = items[k]
            if dist[i] != d:
                continue  # a stale entry: reached more cheaply since
            visited[count], at[count] = i, d
            count += 1
            for j in range(16):
                t = i + offsets[j]
                nd = d + weights[j]
                if flat[t] and nd < dist[t]:
                    dist[t] = nd
                    bt = nd % 16
                    items[used], nxt[used], head[bt] = t, head[bt], used
                    used += 1
                    pending += 1
        d += 1
    return visited[:count], at[:count]


def geodesic_px(mask, seed_rc):
    """
    Return (rows, cols, distance px) of the pixels of seed's component in a boolean mask.

    The distance is geodesic, from the seed (row, col) through the component (connected by
    the eight neighbours, measured with knight moves too: see _geodesic).
    """
    padded = cv2.copyMakeBorder(mask.view(np.uint8), 2, 2, 2, 2, cv2.BORDER_CONSTANT, value=0)
    w = padded.shape[1]
    visited, at = _geodesic(padded, (seed_rc[0] + 2) * w + seed_rc[1] + 2)
    return visited // w - 2, visited % w - 2, at.astype(np.float64) / UNIT


def warm_up():
    """Load (or compile, the first time on a machine) the compiled pass before frames come."""
    geodesic_px(np.ones((3, 3), bool), (1, 1))


@dataclass
class Centreline:
    """Ordered centreline points of a body (px), their distances from the base, its end."""

    points_px: np.ndarray     # (N, 2) u, v: band centroids, base to tip
    s_px: np.ndarray          # (N,) mean geodesic distance of each band, px
    end_s_px: float           # the largest distance in the body, px
    width_px: float           # the body's mean width: area / length, px
    counts: np.ndarray        # (N,) pixels in each band
    band_px: float            # the bands' width along the body, px

    def width_near_base_px(self, skip=5, bands=20):
        """
        Return the width near the base (px), where a coiled body is single.

        The first ``skip`` bands are left out: about the seed they are half discs.
        """
        counts = self.counts[skip:skip + bands]
        return float(np.mean(counts if len(counts) else self.counts)) / self.band_px


def bands(rows, cols, s, band_px=2.0, min_pixels=3):
    """
    Return the Centreline of pixels (rows, cols) at distances s (px): a centroid per band.

    :param band_px: the bands' width along the body, px
    :param min_pixels: bands with fewer pixels are dropped (a grazing end)
    """
    index = (s / band_px).astype(np.int64)
    count = np.bincount(index)
    keep = count >= min_pixels
    u = np.bincount(index, cols)[keep] / count[keep]
    v = np.bincount(index, rows)[keep] / count[keep]
    mean_s = np.bincount(index, s)[keep] / count[keep]
    end = float(s.max())
    return Centreline(np.column_stack([u, v]), mean_s, end, len(s) / max(end, 1.0),
                      count[keep], float(band_px))


def end_fit(line, fit_length_px=40.0):
    """
    Return (end point px, unit direction px) of the centreline's end.

    A quadratic in distance fitted to the centreline over ``fit_length_px`` up to the last
    whole band (a line where that part is short), evaluated at the body's end distance. The
    bands the end cuts at a slant are left out: their centroids slip sideways. A band is
    whole while it holds at least 90% of the median band's pixels over the last widths.
    """
    near_end = line.s_px >= line.end_s_px - 3 * line.width_px
    reference = np.median(line.counts[near_end]) if near_end.sum() >= 3 else 0.0
    whole = np.nonzero(line.counts >= 0.9 * reference)[0]
    stop = line.s_px[whole[-1]] if len(whole) else line.s_px[-1]
    last = (line.s_px >= stop - fit_length_px) & (line.s_px <= stop)
    s, p = line.s_px[last], line.points_px[last]
    if len(s) < 2:
        s, p = line.s_px[-2:], line.points_px[-2:]
    degree = 2 if len(s) >= 6 else 1
    coeffs = np.polynomial.polynomial.polyfit(s - line.end_s_px, p, degree)
    end, tangent = coeffs[0], coeffs[1]  # P(x) = c0 + c1 x (+ c2 x^2) at x = 0, the end
    return end, tangent / max(np.hypot(*tangent), 1e-12)


def refine_end(gray, end_px, direction, width_px):
    """
    Return the end point moved along ``direction`` to the grey-level edge (sub-pixel).

    The profile is the mean over the body's middle half, sampled every 0.1 px from two
    widths before the end to one after; the body's level is its median inside, the
    background's beyond the end, and the edge is where the profile crosses halfway between
    them. Where no crossing is found the end is kept.
    """
    normal = np.array([-direction[1], direction[0]])
    steps = np.arange(-2.0 * width_px - 4.0, width_px + 6.0, 0.1)
    across = np.linspace(-0.25, 0.25, 5) * width_px
    points = (end_px[None, None, :] + steps[None, :, None] * direction
              + across[:, None, None] * normal)
    # Sample a small crop only: converting the whole window to float costs more than this.
    lo = np.maximum(np.floor(points.reshape(-1, 2).min(axis=0)).astype(int) - 2, 0)
    hi = np.minimum(np.ceil(points.reshape(-1, 2).max(axis=0)).astype(int) + 3,
                    gray.shape[1::-1])
    if np.any(hi - lo < 2):
        return end_px
    crop = gray[lo[1]:hi[1], lo[0]:hi[0]].astype(np.float32)
    maps = (points - lo).astype(np.float32)
    profile = cv2.remap(crop, maps[..., 0], maps[..., 1], cv2.INTER_LINEAR,
                        borderMode=cv2.BORDER_REPLICATE).mean(axis=0)
    body_level = np.median(profile[steps < -0.5 * width_px])
    background_level = np.median(profile[steps > 3.0])
    middle = 0.5 * (body_level + background_level)
    inside = profile < middle if body_level < background_level else profile > middle
    # From the rough end walk back into the body, then out to the first crossing.
    i = int(np.searchsorted(steps, 0.0))
    while i > 0 and not inside[i]:
        i -= 1
    while i + 1 < len(steps) and inside[i + 1]:
        i += 1
    if i + 1 >= len(steps) or not inside[i]:
        return end_px
    a, b = profile[i] - middle, profile[i + 1] - middle
    t = steps[i] + 0.1 * a / (a - b) if a != b else steps[i]
    return end_px + t * direction


def loops(body_mask, min_area_px=50.0):
    """
    Return the holes of a body mask as (centre (u, v) px, radius px, area px^2), largest first.

    A body that closes on itself encloses background: the hole's centroid is the loop's
    centre and the radius of a circle of its area, plus half the body's width where the
    caller wants the centreline's, its radius.
    """
    contours, hierarchy = cv2.findContours(body_mask.astype(np.uint8), cv2.RETR_CCOMP,
                                           cv2.CHAIN_APPROX_NONE)
    found = []
    if hierarchy is None:
        return found
    for contour, (_, _, _, parent) in zip(contours, hierarchy[0]):
        if parent < 0:
            continue  # an outer boundary
        area = cv2.contourArea(contour)
        if area >= min_area_px:
            moments = cv2.moments(contour)
            centre = np.array([moments['m10'], moments['m01']]) / moments['m00']
            found.append((centre, float(np.sqrt(area / np.pi)), float(area)))
    return sorted(found, key=lambda loop: -loop[2])
