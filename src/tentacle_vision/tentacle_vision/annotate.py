"""
The tracker's debug picture: the frame with what was found drawn on it (no ROS).

The search window (grey), the centreline (green), the tip and its heading (red), or a loop
(orange circle); a line of text says what the track says. Scaled down first: the picture
is for people, and a full frame at camera rate is bandwidth nobody needs.
"""

import cv2
import numpy as np


def annotate(image, track, scale=0.5):
    """Return a bgr8 picture of a frame (mono8 or bgr8) and its Track, ``scale`` times."""
    small = cv2.resize(image, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    picture = small if small.ndim == 3 else cv2.cvtColor(small, cv2.COLOR_GRAY2BGR)
    x, y, w, h = (np.asarray(track.window, float) * scale).astype(int)
    cv2.rectangle(picture, (x, y), (x + w - 1, y + h - 1), (128, 128, 128), 1)
    if track.centreline_px is not None:
        points = np.round(track.centreline_px * scale).astype(np.int32)
        cv2.polylines(picture, [points], False, (0, 200, 0), 1, cv2.LINE_AA)
    if track.found:
        tip = track.tip_px * scale
        end = tip + 30 * np.array([np.cos(track.heading_rad), -np.sin(track.heading_rad)])
        cv2.circle(picture, tuple(np.round(tip).astype(int)), 4, (0, 0, 255), 1, cv2.LINE_AA)
        cv2.arrowedLine(picture, tuple(np.round(tip).astype(int)),
                        tuple(np.round(end).astype(int)), (0, 0, 255), 1, cv2.LINE_AA)
        text = (f'tip {track.tip_m[0] * 1e3:.2f}, {track.tip_m[1] * 1e3:.2f} mm, '
                f'{np.degrees(track.heading_rad):.1f} deg, {track.seconds * 1e3:.1f} ms')
    elif track.loop is not None:
        centre = tuple(np.round(track.loop.centre_px * scale).astype(int))
        cv2.circle(picture, centre, int(round(track.loop.radius_px * scale)), (0, 140, 255), 1,
                   cv2.LINE_AA)
        cv2.drawMarker(picture, centre, (0, 140, 255), cv2.MARKER_CROSS, 12)
        text = (f'loop: radius {track.loop.radius_m * 1e3:.2f} mm, turned '
                f'{np.degrees(track.loop.turned_rad):.0f} deg')
    else:
        text = f'lost: {track.reason}'
    cv2.putText(picture, text, (8, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 255), 1,
                cv2.LINE_AA)
    return picture
