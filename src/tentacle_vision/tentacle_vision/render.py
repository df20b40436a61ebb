"""
Camera frames of the tentacle, drawn from a centreline in metres, with their ground truth.

Shared by the tracker's tests and the simulator. A ``Renderer`` holds what does not change
between frames (the size, the pixel map, a lit background with an optional channel phantom,
a bank of noise frames); ``render(centreline_m, width_m)`` draws the body (flat ends,
area-exact anti-aliasing, optional darker magnet segments along arc-length ranges), blurs it, adds
noise and returns the frame with the truth: the tip (m and px), its heading (rad about z,
the last segment's direction) and the centreline. ``to_bgr`` and ``to_bayer_rggb`` give the
colour encodings a camera sends.
"""

from dataclasses import dataclass

import cv2
import numba
import numpy as np

SUPERSAMPLE = 4          # coverage is drawn this much finer, then averaged
NOISE_FRAMES = 4         # noise frames kept and cycled (drawing fresh noise is slow)


@dataclass
class Rendered:
    """A frame and what it shows."""

    image: np.ndarray            # mono8, (height, width)
    tip_m: np.ndarray            # (2,) m, workspace frame
    tip_px: np.ndarray           # (2,) px (u, v)
    heading_rad: float           # tip direction, rad about z (workspace)
    centreline_m: np.ndarray     # (N, 2) m, base to tip
    centreline_px: np.ndarray    # (N, 2) px


def _lit_background(size, level, lighting, rng):
    """Return a float32 background: a level, vignetting and a tilt of ``lighting`` fraction."""
    width, height = size
    u = np.linspace(-1.0, 1.0, width, dtype=np.float32)
    v = np.linspace(-1.0, 1.0, height, dtype=np.float32)[:, None]
    tilt = rng.uniform(-1.0, 1.0, 2).astype(np.float32)
    shade = 1.0 - lighting * (0.5 * (u ** 2 + v ** 2) + 0.25 * (tilt[0] * u + tilt[1] * v))
    return (level * shade).astype(np.float32)


def _quads(points_px, width_px):
    """Return the body's outline as one quad per segment, flat ends (float px)."""
    d = np.diff(points_px, axis=0)
    lengths = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-9)
    n = np.column_stack([-d[:, 1], d[:, 0]]) / lengths[:, None]
    normals = np.vstack([n[:1], n[:-1] + n[1:], n[-1:]])
    normals /= np.maximum(np.hypot(normals[:, 0], normals[:, 1]), 1e-9)[:, None]
    # A mitred joint keeps the width across a bend.
    cosines = np.ones(len(points_px))
    cosines[1:-1] = np.maximum(np.einsum('ij,ij->i', normals[1:-1], n[:-1]), 0.5)
    offset = normals * (0.5 * width_px / cosines)[:, None]
    left, right = points_px + offset, points_px - offset
    return np.stack([left[:-1], left[1:], right[1:], right[:-1]], axis=1)


@numba.njit(cache=True)
def _raster(canvas, fine, quads, scale):
    """
    Add to ``canvas`` the coverage of convex quads (fine coordinates), sampled at fine pixels.

    A fine pixel counts once (``fine`` marks it), where its centre is inside any quad.
    """
    h, w = fine.shape
    share = 1.0 / (scale * scale)
    for q in range(quads.shape[0]):
        x, y = quads[q, :, 0], quads[q, :, 1]
        area = 0.0
        for k in range(4):
            area += x[k] * y[(k + 1) % 4] - x[(k + 1) % 4] * y[k]
        sign = 1.0 if area > 0 else -1.0
        y0, y1 = max(int(np.floor(y.min())), 0), min(int(np.ceil(y.max())), h - 1)
        for j in range(y0, y1 + 1):
            # Each edge bounds i on this row: sign ((bx - ax)(j - ay) - (by - ay)(i - ax)) >= 0.
            lo, hi = 0.0, w - 1.0
            for k in range(4):
                ax, ay = x[k], y[k]
                dx, dy = x[(k + 1) % 4] - ax, y[(k + 1) % 4] - ay
                c = sign * (dx * (j - ay) + dy * ax)
                a = sign * dy
                if a > 0:
                    hi = min(hi, c / a)
                elif a < 0:
                    lo = max(lo, c / a)
                elif c < 0:
                    hi = -1.0
            for i in range(int(np.ceil(lo)), int(np.floor(hi)) + 1):
                if not fine[j, i]:
                    fine[j, i] = 1
                    canvas[j // scale, i // scale] += share


def _fill(canvas, quads):
    """
    Add quads to a float32 coverage canvas (0-1), their area exact to 1/SUPERSAMPLE^2 px.

    Fine pixels are counted where their centres fall inside (a union: overlaps count once).
    OpenCV's own fills draw a slanted edge about half a pixel outside (the line through it
    is drawn too), which would bias every truth.
    """
    # Only the quads' box is sampled finely (the magnets are a small part of the body).
    lo = np.maximum(np.floor(quads.reshape(-1, 2).min(axis=0)).astype(int) - 1, 0)
    hi = np.minimum(np.ceil(quads.reshape(-1, 2).max(axis=0)).astype(int) + 2,
                    canvas.shape[::-1])
    if np.any(hi <= lo):
        return
    part = canvas[lo[1]:hi[1], lo[0]:hi[0]]
    h, w = part.shape
    fine = np.zeros((h * SUPERSAMPLE, w * SUPERSAMPLE), np.uint8)
    # Coarse pixel k spans [k - 0.5, k + 0.5): its fine pixels' centres are k S ... k S + S - 1.
    _raster(part, fine, (quads - lo + 0.5) * SUPERSAMPLE - 0.5, SUPERSAMPLE)
    np.minimum(part, 1.0, out=part)


def arc_lengths(points):
    """Return the cumulative arc length at each point of a polyline."""
    return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(points, axis=0).T))])


def centreline_of(segments, start_m=(0.0, 0.0), heading_rad=0.0, spacing_m=2e-4):
    """
    Return a centreline (N, 2), m, of constant-curvature pieces joined end to end.

    :param segments: (length m, curvature 1/m) pairs; curvature > 0 turns left (about +z)
    """
    pieces, end, heading = [np.asarray(start_m, float)[None, :]], np.asarray(start_m, float), \
        float(heading_rad)
    for length, curvature in segments:
        s = np.linspace(0.0, length, max(int(np.ceil(length / spacing_m)), 1) + 1)[1:]
        if abs(curvature) < 1e-12:
            d = np.column_stack([np.cos(heading) * s, np.sin(heading) * s])
        else:
            a = heading + curvature * s
            d = np.column_stack([np.sin(a) - np.sin(heading),
                                 np.cos(heading) - np.cos(a)]) / curvature
        pieces.append(end + d)
        end, heading = pieces[-1][-1], heading + curvature * length
    return np.vstack(pieces)


def resample(points, spacing):
    """Return a polyline resampled at a constant arc-length spacing (ends kept)."""
    s = arc_lengths(points)
    t = np.linspace(0.0, s[-1], max(int(np.ceil(s[-1] / spacing)) + 1, 2))
    return np.column_stack([np.interp(t, s, points[:, 0]), np.interp(t, s, points[:, 1])])


class Renderer:
    """Frames of one size and calibration; see the module docstring."""

    def __init__(self, pixel_map, size=(2048, 1536), *, background=200.0, body=60.0,
                 magnet=25.0, lighting=0.25, noise_sigma=3.0, blur_px=0.8,
                 phantom_m=None, phantom_width_m=0.006, obstacles_m=(), walls_m=(),
                 wall_width_m=3e-4, fluid=0.0, sheath_m=None, sheath_width_m=0.003,
                 sheath=35.0, glare_m=(), seed=0):
        """
        Set up the constant parts.

        :param pixel_map: pixels.ScaleMap or HomographyMap
        :param size: (width, height), px
        :param background, body, magnet: grey levels (0-255) of the lit background, the body
            and its magnet segments
        :param lighting: fraction the lighting falls off towards corners and across the frame
        :param noise_sigma: standard deviation of the sensor noise, grey levels
        :param blur_px: Gaussian blur of the body's edges (the optics), px
        :param phantom_m: a channel centreline (N, 2), m, drawn as a lighter channel with
            darker walls behind the body; None: no phantom
        :param obstacles_m: ((centre (2,), radius), ...) discs, m, drawn as darker phantom
        :param walls_m: ((k, 2) polylines, ...), m, drawn wall_width_m wide, as darker phantom
        :param fluid: how much darker the channel is for the fluid in it (0-1), with a mottle
        :param sheath_m: (k, 2) the inserter's sheath, m, drawn ``sheath_width_m`` wide at
            grey level ``sheath`` (it ends where the body comes out); None: none
        :param glare_m: ((centre (2,), radius), ...) specular glare, m: saturated spots
        """
        self.map, self.size = pixel_map, tuple(size)
        self.body, self.magnet, self.blur_px = float(body), float(magnet), float(blur_px)
        rng = np.random.default_rng(seed)
        bg = _lit_background(self.size, background, lighting, rng)
        if phantom_m is not None:
            channel = np.zeros(bg.shape, np.float32)
            walls = np.zeros(bg.shape, np.float32)
            path = self.map.to_pixels(resample(np.asarray(phantom_m, float), 5e-4))
            width_px = phantom_width_m / self.map.metres_per_px_at(path[0])
            _fill(walls, _quads(path, width_px + 6.0))
            _fill(channel, _quads(path, width_px))
            bg = bg * (1.0 - 0.25 * walls) + 0.25 * background * channel
            if fluid > 0:  # the fluid's mottle: smooth noise a few millimetres across
                mottle = cv2.GaussianBlur(rng.normal(0.0, 1.0, bg.shape).astype(np.float32),
                                          (0, 0), 25.0)
                mottle /= max(float(np.abs(mottle).max()), 1e-9)
                bg = bg * (1.0 - fluid * channel * (0.8 + 0.2 * mottle))
        if len(obstacles_m) or len(walls_m):
            solid = np.zeros(bg.shape, np.float32)
            v, u = np.mgrid[0:bg.shape[0], 0:bg.shape[1]].astype(np.float32)
            for centre, radius in obstacles_m:
                centre_px = self.map.to_pixels(np.asarray(centre, float).reshape(1, 2))[0]
                radius_px = radius / self.map.metres_per_px_at(centre_px)
                distance = np.hypot(u - centre_px[0], v - centre_px[1])
                np.maximum(solid, np.clip(radius_px + 0.5 - distance, 0.0, 1.0), out=solid)
            for wall in (w for w in walls_m if len(w) >= 2):
                line = self.map.to_pixels(resample(np.asarray(wall, float), 2e-4))
                _fill(solid, _quads(line, wall_width_m / self.map.metres_per_px_at(line[0])))
            bg = bg * (1.0 - 0.25 * solid)
        v = u = None
        for centre, radius in glare_m:
            if u is None:
                v, u = np.mgrid[0:bg.shape[0], 0:bg.shape[1]].astype(np.float32)
            centre_px = self.map.to_pixels(np.asarray(centre, float).reshape(1, 2))[0]
            radius_px = radius / self.map.metres_per_px_at(centre_px)
            spot = np.exp(-((u - centre_px[0]) ** 2 + (v - centre_px[1]) ** 2)
                          / (2 * (radius_px / 2) ** 2))
            bg = bg + (255.0 - bg) * spot
        if sheath_m is not None:
            tube = np.zeros(bg.shape, np.float32)
            line = self.map.to_pixels(np.asarray(sheath_m, float))
            _fill(tube, _quads(line, sheath_width_m / self.map.metres_per_px_at(line[-1])))
            bg = bg + tube * (float(sheath) - bg)
        self.background = np.clip(bg, 0, 255).astype(np.uint8)
        self.noise = []
        if noise_sigma > 0:
            for _ in range(NOISE_FRAMES):
                n = rng.normal(0.0, noise_sigma, bg.shape)
                self.noise.append((np.clip(n, 0, 255).astype(np.uint8),
                                   np.clip(-n, 0, 255).astype(np.uint8)))
        self._frame = 0

    def render(self, centreline_m, width_m, magnets_m=(), noise=True):
        """
        Draw one frame.

        :param centreline_m: (N, 2) the body's centreline, base to tip, m
        :param width_m: the body's width, m
        :param magnets_m: (start, end) arc-length ranges from the base drawn darker, m
        :return: Rendered
        """
        line_m = resample(np.asarray(centreline_m, float), 2e-4)
        line_px = self.map.to_pixels(line_m)
        width_px = width_m / self.map.metres_per_px_at(line_px[-1])
        # Draw and compose only around the body: the rest of the frame is the background.
        pad = int(3 * self.blur_px + width_px) + 2
        x0, y0 = np.maximum(np.floor(line_px.min(axis=0)).astype(int) - pad, 0)
        x1, y1 = np.minimum(np.ceil(line_px.max(axis=0)).astype(int) + pad, self.size)
        corner = np.array([x0, y0], float)
        coverage = np.zeros((y1 - y0, x1 - x0), np.float32)
        _fill(coverage, _quads(line_px - corner, width_px))
        shade = self.body  # the body's grey, darker along the magnets
        s = arc_lengths(line_m)
        for start, end in magnets_m:
            inside = (s >= start) & (s <= end)
            if inside.sum() >= 2:
                if np.isscalar(shade):
                    darker = np.zeros_like(coverage)
                _fill(darker, _quads(line_px[inside] - corner, width_px))
                shade = self.body + (self.magnet - self.body) * darker
        image = self.background.copy()
        roi = image[y0:y1, x0:x1].astype(np.float32)
        roi += coverage * (shade - roi)
        if self.blur_px > 0:
            roi = cv2.GaussianBlur(roi, (0, 0), self.blur_px)
        image[y0:y1, x0:x1] = np.clip(roi + 0.5, 0, 255).astype(np.uint8)
        if noise and self.noise:
            up, down = self.noise[self._frame % len(self.noise)]
            self._frame += 1
            cv2.add(image, up, image)
            cv2.subtract(image, down, image)
        d = line_m[-1] - line_m[-2]
        return Rendered(image, line_m[-1].copy(), line_px[-1].copy(),
                        float(np.arctan2(d[1], d[0])), line_m, line_px)


def to_bgr(mono, body_tint=(0.55, 0.75, 1.0)):
    """Return a bgr8 frame of a mono one: dark parts tinted (a reddish body), light grey."""
    f = mono.astype(np.float32) / 255.0
    tint = np.asarray(body_tint, np.float32)
    bgr = f[..., None] * (tint + (1 - tint) * f[..., None])
    return np.clip(bgr * 255.0 + 0.5, 0, 255).astype(np.uint8)


def to_bayer_rggb(bgr):
    """Return the bayer_rggb8 mosaic of a bgr8 frame (R at even rows and columns)."""
    mosaic = np.empty(bgr.shape[:2], np.uint8)
    mosaic[0::2, 0::2] = bgr[0::2, 0::2, 2]
    mosaic[0::2, 1::2] = bgr[0::2, 1::2, 1]
    mosaic[1::2, 0::2] = bgr[1::2, 0::2, 1]
    mosaic[1::2, 1::2] = bgr[1::2, 1::2, 0]
    return mosaic
