"""
Track the tentacle in frames: tip, heading and centreline, or a loop, or lost (no ROS).

``Tracker(base_px, pixel_map, settings).track(image)`` segments the frame (segmentation.py),
takes the connected component that reaches the insertion point as the body, orders its
centreline from the base (centreline.py) and returns a ``Track``: the tip (px and m), its
heading (rad about z, workspace) and the centreline, base to tip. It searches a region of
interest around the last body; when the body is not found there or leaves it (or on the
first frame) it looks for it in a frame four times smaller, tracks it in the window found
there, and searches the whole frame at full size only if that fails. When the body closes
on itself the track is a loop (centre, radius, turned angle) and has no tip; when no body
is found, or it leaves the frame (its tip out of sight), the track says why, and has no tip
either.
"""

from dataclasses import dataclass
import time

import cv2
import numpy as np

from tentacle_vision import image_codec
from tentacle_vision.centreline import bands, end_fit, geodesic_px, loops, refine_end
from tentacle_vision.segmentation import changed, foreground, to_gray


COARSE = 4  # a lost body is looked for in a frame this many times smaller first


@dataclass
class Settings:
    """What the tracker is told; pixels unless named otherwise."""

    segmentation: str = 'otsu'        # otsu, adaptive, fixed or colour
    dark: bool = True                 # the body is darker than the background
    threshold: int = 128              # for 'fixed'
    block_px: int = 51                # for 'adaptive'
    offset: int = 10                  # for 'adaptive'
    colour_low: tuple = (0, 0, 0)     # for 'colour', bgr
    colour_high: tuple = (255, 255, 255)
    blur_px: float = 1.0              # before thresholding
    max_width_px: float = 40.0        # the body is at most this wide (for 'otsu')
    base_search_px: float = 30.0      # the body must come this close to the insertion point
    min_body_px: int = 150            # fewer pixels are not a body
    band_px: float = 2.0              # centreline spacing along the body
    fit_length_px: float = 80.0       # the end's direction is fitted over this much body
    roi_margin_px: int = 80           # the search window around the last body
    min_loop_area_px: float = 150.0   # a smaller hole is not a loop


@dataclass
class Loop:
    """The body closed on itself: the loop it makes (workspace, m and rad)."""

    centre_m: np.ndarray
    radius_m: float                   # of the loop's centreline
    turned_rad: float                 # the body's turn from the insertion to its end
    centre_px: np.ndarray
    radius_px: float


@dataclass
class Track:
    """One frame's answer; ``found`` with a tip, or ``loop``, or neither and ``reason``."""

    found: bool
    reason: str
    tip_px: np.ndarray = None
    tip_m: np.ndarray = None
    heading_rad: float = float('nan')
    centreline_px: np.ndarray = None
    centreline_m: np.ndarray = None
    loop: Loop = None
    window: tuple = (0, 0, 0, 0)      # x, y, width, height searched, px
    full_frame: bool = True
    seconds: float = 0.0


def status_of(track):
    """Return (level 'ok' | 'warn', message) of a Track for diagnostics."""
    if track.found:
        return 'ok', 'tracking'
    if track.loop is not None:
        return 'ok', track.reason
    return 'warn', f'lost: {track.reason}'


class Tracker:
    """Tip and shape from frames of one camera; keeps the search window between frames."""

    def __init__(self, base_px, pixel_map, settings=None, background=None):
        """
        Track from the insertion point ``base_px`` (u, v); pixels to metres by pixel_map.

        :param background: a frame of the empty scene (mono8 or bgr8, the frames' size), or
            None: with one, the body is what differs from it (segmentation.changed) and the
            segmentation settings are not used
        """
        self.base_px = np.asarray(base_px, float).reshape(2)
        if not np.all(np.isfinite(self.base_px)):
            raise ValueError(f'base_px {base_px!r} must be two finite numbers')
        self.map = pixel_map
        self.settings = settings or Settings()
        self.window = None  # (x0, y0, x1, y1) around the last body, or None: whole frame
        self.set_background(background)

    def set_background(self, background):
        """Use a frame of the empty scene from now on (mono8 or bgr8); None: none."""
        self.background = None if background is None else np.ascontiguousarray(background)
        self._small_background = None  # its COARSE-times smaller copy, made when first needed
        self.window = None

    def _mask(self, crop, window, small=False):
        """Return the body mask of a crop (of a frame COARSE times smaller if small)."""
        s = self.settings
        if self.background is None:
            return foreground(crop, s.segmentation, dark=s.dark, threshold=s.threshold,
                              block_px=max(s.block_px // COARSE, 3) if small else s.block_px,
                              offset=s.offset, colour_low=s.colour_low,
                              colour_high=s.colour_high, blur_px=0.0 if small else s.blur_px,
                              max_width_px=s.max_width_px / (COARSE if small else 1))[0]
        x0, y0, x1, y1 = window
        background = self._small_background if small else self.background
        return changed(crop, background[y0:y1, x0:x1], 0.0 if small else s.blur_px)[0]

    def _colour(self):
        """Return whether crops are taken in colour (colour segmentation or background)."""
        if self.background is not None:
            return self.background.ndim == 3
        return self.settings.segmentation == 'colour'

    def track(self, image, encoding='mono8'):
        """
        Return the Track of one frame, as decoded by image_codec.from_message.

        Only the searched window is converted to grey (or bgr for colour segmentation):
        demosaicking a whole bayer frame would cost more than tracking in it.
        """
        t0 = time.perf_counter()
        height, width = image.shape[:2]
        whole = (0, 0, width, height)
        result = None
        if self.window is not None:
            result = self._track_in(image, encoding, self.window)
        if result is None or not (result.found or result.loop is not None):
            # Lost, or the first frame: find the body at a quarter size first, then track it in
            # its window at full size; the whole frame at full size is the last resort.
            coarse = self._coarse_window(image, encoding)
            if coarse is not None:
                result = self._track_in(image, encoding, coarse) or result
            if result is None or not (result.found or result.loop is not None):
                result = self._track_in(image, encoding, whole) or result
        self.window = self._window_of(result, width, height)
        result.seconds = time.perf_counter() - t0
        return result

    # -- one window -------------------------------------------------------------------------
    def _track_in(self, image, encoding, window):
        """Return a Track in a window, or None if the body leaves a window smaller than all."""
        x0, y0, x1, y1 = window
        s = self.settings
        full = (x0, y0) == (0, 0) and (x1, y1) == image.shape[1::-1]
        if encoding == 'bayer_rggb8':  # keep the mosaic's phase: even corners
            x0, y0 = x0 & ~1, y0 & ~1
        crop = image_codec.for_tracking(encoding, image[y0:y1, x0:x1], colour=self._colour())
        mask = self._mask(crop, (x0, y0, x1, y1))
        base = self.base_px - (x0, y0)
        lost = Track(False, '', window=(x0, y0, x1 - x0, y1 - y0), full_frame=full)
        found = self._component(mask, base)
        if found is not None and found[3].any():
            # Joined to something that runs off the window: the inserter's sheath, say, is
            # dark too. What is wider than the body can be is not body: without it, again.
            narrow = without_wide_parts(mask, s.max_width_px)
            if narrow is not mask:
                retry = self._component(narrow, base)
                if retry is not None and not retry[3].any():
                    mask, found = narrow, retry
        if found is None:
            lost.reason = (f'no body within {s.base_search_px:g} px of the insertion point '
                           f'{tuple(np.round(self.base_px, 1))}')
            return lost
        rows, cols, dist, edge = found
        if edge.any():
            if not full:
                return None  # it leaves the window: look at the whole frame
            lost.reason = ('the body leaves the frame (at px '
                           f'{cols[edge][0] + x0}, {rows[edge][0] + y0}): its tip is not seen')
            return lost
        if len(rows) < s.min_body_px:
            lost.reason = f'no body at the insertion point: only {len(rows)} px there'
            return lost
        line = bands(rows, cols, dist, s.band_px)
        offset = np.array([x0, y0], float)
        r0, c0 = rows.min(), cols.min()
        body = np.zeros((rows.max() - r0 + 3, cols.max() - c0 + 3), np.uint8)
        body[rows - r0 + 1, cols - c0 + 1] = 1
        holes = loops(body, s.min_loop_area_px)
        if holes:
            return self._loop_track(lost, holes[0], line, offset + (c0 - 1, r0 - 1),
                                    offset, len(rows))
        end, direction = end_fit(line, s.fit_length_px)
        tip = refine_end(to_gray(crop), end, direction, line.width_px)
        tip_px = tip + offset
        centreline_px = np.vstack([line.points_px + offset, tip_px])
        return Track(True, 'tracking', tip_px, self.map.to_metres(tip_px)[0],
                     self.map.heading(direction, tip_px), centreline_px,
                     self.map.to_metres(centreline_px), window=lost.window, full_frame=full)

    def _coarse_window(self, image, encoding):
        """Return the window of the body found in a frame COARSE times smaller, or None."""
        s = self.settings
        if s.segmentation == 'colour' and self.background is None:
            return None
        if encoding == 'bayer_rggb8' and not self._colour():
            small = image[0::2, 1::2]  # the green sites: a half-size grey frame, for free
            step = 2
        else:
            small = image_codec.for_tracking(encoding, image, colour=self._colour())
            step = 1
        shrink = COARSE // step
        h, w = small.shape[:2]
        small = cv2.resize(small, (w // shrink, h // shrink), interpolation=cv2.INTER_AREA)
        if self.background is not None and self._small_background is None:
            bh, bw = self.background.shape[:2]
            self._small_background = cv2.resize(self.background, (bw // COARSE, bh // COARSE),
                                                interpolation=cv2.INTER_AREA)
        if self.background is not None and self._small_background.shape != small.shape:
            return None   # the frame is not the background's size: the full-size pass says so
        mask = self._mask(small, (0, 0, small.shape[1], small.shape[0]), small=True)
        seed = self._seed(mask, self.base_px / COARSE, s.base_search_px / COARSE + 1)
        if seed is None:
            return None
        rows, cols, _ = geodesic_px(mask, seed)
        if len(rows) * COARSE ** 2 < s.min_body_px:
            return None
        margin = s.roi_margin_px
        height, width = image.shape[:2]
        lo = np.minimum([cols.min() * COARSE, rows.min() * COARSE], self.base_px) - margin
        hi = np.maximum([(cols.max() + 1) * COARSE, (rows.max() + 1) * COARSE],
                        self.base_px) + margin
        x0, y0 = np.maximum(lo, 0).astype(int)
        x1, y1 = np.minimum(hi, (width, height)).astype(int)
        return int(x0), int(y0), int(x1), int(y1)

    def _component(self, mask, base):
        """
        Return (rows, cols, geodesic distance, at the mask's edge) of the body's component.

        At the edge: its pixels on the mask's border, away from the insertion point. None: no
        body near the insertion point.
        """
        seed = self._seed(mask, base)
        if seed is None:
            return None
        rows, cols, dist = geodesic_px(mask, seed)   # the seed's component, and distances
        h, w = mask.shape
        edge = (rows == 0) | (cols == 0) | (rows == h - 1) | (cols == w - 1)
        edge &= (cols - base[0]) ** 2 + (rows - base[1]) ** 2 > (
            2 * self.settings.base_search_px) ** 2
        return rows, cols, dist, edge

    def _seed(self, mask, base, reach_px=None):
        """Return the body pixel (row, col) nearest the base within reach, or None."""
        r = self.settings.base_search_px if reach_px is None else reach_px
        h, w = mask.shape
        c0, c1 = int(max(base[0] - r, 0)), int(min(base[0] + r + 1, w))
        r0, r1 = int(max(base[1] - r, 0)), int(min(base[1] + r + 1, h))
        if c0 >= c1 or r0 >= r1:
            return None
        rows, cols = np.nonzero(mask[r0:r1, c0:c1])
        if not len(rows):
            return None
        d2 = (cols + c0 - base[0]) ** 2 + (rows + r0 - base[1]) ** 2
        k = int(np.argmin(d2))
        return (int(rows[k] + r0), int(cols[k] + c0)) if d2[k] <= r * r else None

    def _loop_track(self, lost, hole, line, hole_offset, offset, area_px):
        """Return the Track of a body that closed on itself (no tip)."""
        centre_px = hole[0] + hole_offset
        # The width near the base, where the body is single; its length from its area.
        width_px = line.width_near_base_px()
        radius_px = hole[1] + 0.5 * width_px
        length_px = area_px / width_px
        to_centre = np.hypot(*(line.points_px + offset - centre_px).T)
        entry = line.s_px[np.argmax(to_centre <= radius_px + width_px)]
        turned = max(length_px - entry, 0.0) / radius_px
        scale = self.map.metres_per_px_at(centre_px)
        lost.reason = 'loop: the body closed on itself; no tip'
        lost.loop = Loop(self.map.to_metres(centre_px)[0], radius_px * scale, float(turned),
                         centre_px, float(radius_px))
        lost.centreline_px = line.points_px + offset
        lost.centreline_m = self.map.to_metres(lost.centreline_px)
        return lost

    def _window_of(self, result, width, height):
        """Return the next search window: the last body's box plus a margin, or None."""
        if result.centreline_px is None:
            return None
        margin = self.settings.roi_margin_px
        lo = np.floor(np.minimum(result.centreline_px.min(axis=0), self.base_px)) - margin
        hi = np.ceil(np.maximum(result.centreline_px.max(axis=0), self.base_px)) + margin
        x0, y0 = np.maximum(lo, 0).astype(int)
        x1, y1 = np.minimum(hi, (width, height)).astype(int)
        return int(x0), int(y0), int(x1), int(y1)


def without_wide_parts(mask, max_width_px):
    """
    Return the mask without what is wider than max_width_px (the mask itself if nothing is).

    A part is too wide where the distance to the mask's edge exceeds half the width; it is
    removed with everything within half a width of it, so a wide dark thing (the sheath the
    body comes out of) goes whole and the body beside it stays.
    """
    distance = cv2.distanceTransform(mask.view(np.uint8), cv2.DIST_L2, 3)
    core = distance > 0.5 * max_width_px + 1.0
    if not core.any():
        return mask
    r = int(np.ceil(0.5 * max_width_px)) + 2
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
    return mask & (cv2.dilate(core.view(np.uint8), disc) == 0)
