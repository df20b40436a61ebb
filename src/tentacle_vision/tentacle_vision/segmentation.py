"""
Foreground segmentation: which pixels are the tentacle (no I/O, no ROS).

``foreground(image, method, ...)`` returns a boolean mask: Otsu's threshold of the contrast
to the local background (the default: uneven lighting does not fool it), an adaptive (local
mean) threshold, a fixed grey level, or a colour range (bgr images only). The
body is dark on a light background unless ``dark=False``. A light Gaussian blur first keeps
sensor noise from breaking the body's edge into specks. ``changed(image, background)`` is
the mask against a frame of the empty scene instead: what differs from it, in any colour
channel (the sheath, the phantom's walls, fluid and glare are in both frames, the body only
in one).
"""

import cv2
import numpy as np

METHODS = ('otsu', 'adaptive', 'fixed', 'colour')


def to_gray(image):
    """Return a mono8 view or copy of a mono8 or bgr8 frame."""
    return image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)


def foreground(image, method='otsu', *, dark=True, threshold=128, block_px=51, offset=10,
               colour_low=(0, 0, 0), colour_high=(255, 255, 255), blur_px=1.0,
               max_width_px=40.0):
    """
    Return (mask, threshold used) of the body in a mono8 or bgr8 frame (or a crop of one).

    :param method: 'otsu' (Otsu's threshold of the contrast to the local background, see
        ``contrast``), 'adaptive' (local mean over ``block_px`` minus ``offset``), 'fixed'
        (``threshold``, a grey level) or 'colour' (bgr within [colour_low, colour_high])
    :param max_width_px: the body is at most this wide (px): for 'otsu'
    :param dark: the body is darker than the background
    :raises ValueError: an unknown method, or 'colour' on a mono frame
    """
    if method not in METHODS:
        raise ValueError(f'segmentation {method!r} is not one of {METHODS}')
    if method == 'colour':
        if image.ndim != 3:
            raise ValueError("segmentation 'colour' needs a colour (bgr8) frame")
        return cv2.inRange(image, np.asarray(colour_low, np.uint8),
                           np.asarray(colour_high, np.uint8)) > 0, None
    gray = to_gray(image)
    if blur_px > 0:  # a kernel of 1.5 sigma each side: the cheap 3 x 3 for sigma 1
        size = 2 * int(round(1.5 * blur_px)) + 1
        gray = cv2.GaussianBlur(gray, (size, size), blur_px)
    kind = cv2.THRESH_BINARY_INV if dark else cv2.THRESH_BINARY
    if method == 'otsu':
        # Uneven lighting would make Otsu split the background: threshold the contrast.
        used, mask = cv2.threshold(contrast(gray, max_width_px, dark), 0, 255,
                                   cv2.THRESH_BINARY | cv2.THRESH_OTSU)
        return mask > 0, float(used)
    if method == 'adaptive':
        block = int(block_px) | 1
        mask = cv2.adaptiveThreshold(gray, 255, cv2.ADAPTIVE_THRESH_MEAN_C, kind, block,
                                     offset if dark else -offset)
        return mask > 0, None
    used, mask = cv2.threshold(gray, threshold, 255, kind)
    return mask > 0, float(used)


def contrast(gray, max_width_px=40.0, dark=True, shrink=4):
    """
    Return how much darker (or lighter) than the local background each pixel is, uint8.

    The background is the frame closed (dark body) or opened (light body) with a disc wider
    than the body, which removes the body and keeps the lighting; it is estimated on a frame
    ``shrink`` times smaller and scaled back up (the lighting is smooth).
    """
    h, w = gray.shape
    # Linear, not area, sampling down: 20 times cheaper, and the frame is already smoothed.
    small = cv2.resize(gray, (max(w // shrink, 1), max(h // shrink, 1)),
                       interpolation=cv2.INTER_LINEAR)
    k = 2 * int(np.ceil(max_width_px / shrink)) + 3
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k))
    small = cv2.morphologyEx(small, cv2.MORPH_CLOSE if dark else cv2.MORPH_OPEN, disc)
    background = cv2.resize(small, (w, h), interpolation=cv2.INTER_LINEAR)
    return cv2.subtract(background, gray) if dark else cv2.subtract(gray, background)


MIN_CHANGE = 12  # grey levels: sensor noise (about 3 sigma of a typical camera) stays out


def changed(image, background, blur_px=1.0, min_change=MIN_CHANGE):
    """
    Return (mask, threshold used) of what differs from a frame of the empty scene.

    Otsu's threshold of the difference (the largest over the colour channels, so a body of
    the background's grey but another colour still differs), at least ``min_change`` grey
    levels, so that a frame with nothing new in it stays empty; then opened with a 3 x 3
    square, so that the one- or two-pixel lines a camera nudged since the background left
    along every edge do not join the body to the scene.

    :param image: mono8 or bgr8, the frame (or a crop of it)
    :param background: the same size and channels, the empty scene (or the same crop)
    :raises ValueError: the two differ in size or channels
    """
    if image.shape != background.shape:
        raise ValueError(f'the frame is {image.shape[1::-1]} px x {image.shape[2:] or 1} '
                         f'channel(s), the background {background.shape[1::-1]} x '
                         f'{background.shape[2:] or 1}: they must match')
    difference = cv2.absdiff(image, background)
    if difference.ndim == 3:
        difference = difference.max(axis=2)
    if blur_px > 0:
        size = 2 * int(round(1.5 * blur_px)) + 1
        difference = cv2.GaussianBlur(difference, (size, size), blur_px)
    otsu, _ = cv2.threshold(difference, 0, 255, cv2.THRESH_BINARY | cv2.THRESH_OTSU)
    used = max(float(otsu), float(min_change))
    mask = cv2.morphologyEx((difference > used).astype(np.uint8), cv2.MORPH_OPEN,
                            np.ones((3, 3), np.uint8))
    return mask > 0, used
