"""
Pixels to metres on the image plane (frame ``workspace``), and back.

Image pixels are (u right, v down), centres at integers. The workspace frame is REP-103 seen
from the camera above: x right, y up the image, z towards the camera, metres. Two maps, one
interface (``to_metres``, ``to_pixels``, ``metres_per_px_at``):

- ``ScaleMap(metres_per_px, origin_px)``: a uniform scale, origin at ``origin_px`` (the
  insertion point by default), y flipped.
- ``HomographyMap(h)``: a 3x3 homography from pixels to metres (a tilted camera), as
  ``fit_homography`` finds it from a checkerboard image (cv2.findChessboardCorners).
"""

import cv2
import numpy as np


class ScaleMap:
    """A uniform scale: x = s (u - u0), y = s (v0 - v)."""

    def __init__(self, metres_per_px, origin_px):
        """Scale ``metres_per_px`` (m/px), origin at ``origin_px`` (u0, v0), px."""
        if not (np.isfinite(metres_per_px) and metres_per_px > 0):
            raise ValueError(f'metres_per_px {metres_per_px!r} must be finite and positive')
        self.s = float(metres_per_px)
        self.origin = np.asarray(origin_px, float).reshape(2)

    def to_metres(self, px):
        """Return (N, 2) workspace points, m, of (N, 2) pixel points."""
        d = np.asarray(px, float).reshape(-1, 2) - self.origin
        return np.column_stack([d[:, 0], -d[:, 1]]) * self.s

    def to_pixels(self, m):
        """Return (N, 2) pixel points of (N, 2) workspace points, m."""
        m = np.asarray(m, float).reshape(-1, 2) / self.s
        return np.column_stack([m[:, 0], -m[:, 1]]) + self.origin

    def metres_per_px_at(self, px):
        """Return the scale (m/px) at a pixel: the same everywhere."""
        return self.s

    def heading(self, direction_px, at_px=None):
        """Return the angle about z (rad, workspace) of an image direction (du, dv)."""
        return float(np.arctan2(-direction_px[1], direction_px[0]))


class HomographyMap:
    """A plane-to-plane homography from pixels (u, v, 1) to metres (x, y, 1)."""

    def __init__(self, h):
        """Take 9 numbers (row-major) or a 3x3 array; it must be invertible."""
        self.h = np.asarray(h, float).reshape(3, 3)
        if not np.all(np.isfinite(self.h)) or abs(np.linalg.det(self.h)) < 1e-300:
            raise ValueError('homography must be 9 finite numbers of an invertible matrix')
        self.h_inv = np.linalg.inv(self.h)

    @staticmethod
    def _apply(h, points):
        p = np.asarray(points, float).reshape(-1, 2)
        q = p @ h[:, :2].T + h[:, 2]
        return q[:, :2] / q[:, 2:3]

    def to_metres(self, px):
        """Return (N, 2) workspace points, m, of (N, 2) pixel points."""
        return self._apply(self.h, px)

    def to_pixels(self, m):
        """Return (N, 2) pixel points of (N, 2) workspace points, m."""
        return self._apply(self.h_inv, m)

    def metres_per_px_at(self, px):
        """Return the local scale (m/px) at a pixel: the root of the Jacobian's determinant."""
        u, v = np.asarray(px, float).reshape(2)
        e = 0.5
        pts = self.to_metres([[u - e, v], [u + e, v], [u, v - e], [u, v + e]])
        jac = np.column_stack([pts[1] - pts[0], pts[3] - pts[2]]) / (2 * e)
        return float(np.sqrt(abs(np.linalg.det(jac))))

    def heading(self, direction_px, at_px):
        """Return the angle about z (rad, workspace) of an image direction at a pixel."""
        a = np.asarray(at_px, float).reshape(2)
        d = np.asarray(direction_px, float).reshape(2)
        d = d / max(np.hypot(*d), 1e-12)
        p = self.to_metres([a - 0.5 * d, a + 0.5 * d])
        return float(np.arctan2(p[1, 1] - p[0, 1], p[1, 0] - p[0, 0]))


def pixel_map(metres_per_px=0.0, homography=(), origin_px=(0.0, 0.0)):
    """
    Return the map the tracker's parameters describe: a homography if given, else a scale.

    :raises ValueError: neither, or a malformed one
    """
    if len(homography):
        if len(homography) != 9:
            raise ValueError(f'homography needs 9 numbers, got {len(homography)}')
        return HomographyMap(homography)
    return ScaleMap(metres_per_px, origin_px)


def fit_homography(image, pattern=(9, 6), square_m=0.01, origin_corner_m=(0.0, 0.0)):
    """
    Return the HomographyMap of a checkerboard image (inner corners ``pattern``).

    The first detected corner is at ``origin_corner_m``; rows run along +x and columns along
    -y by ``square_m`` (the board's square, m).

    :raises ValueError: the board was not found
    """
    gray = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    found, corners = cv2.findChessboardCorners(gray, pattern)
    if not found:
        raise ValueError(f'no {pattern[0]} x {pattern[1]} checkerboard found in the image')
    corners = cv2.cornerSubPix(gray, corners, (5, 5), (-1, -1),
                               (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-3))
    cols, rows = pattern
    grid = np.array([[origin_corner_m[0] + i * square_m, origin_corner_m[1] - j * square_m]
                     for j in range(rows) for i in range(cols)])
    h, _ = cv2.findHomography(corners.reshape(-1, 2), grid)
    if h is None:
        raise ValueError('the checkerboard corners gave no homography')
    return HomographyMap(h)
