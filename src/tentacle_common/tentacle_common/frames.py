"""
Frames and offsets (DESIGN.md "Frames"): the one place that converts between them.

``coils`` (contract.COILS_FRAME) is the rig frame: the coil centre, the frame of every field
and of the model's world. ``workspace`` (contract.WORKSPACE_FRAME) is the image plane of a
camera looking down ``coils`` z: x and y as ``coils`` x and y, origin at the insertion point
(where the tracker's ``base_px`` images), so with the insertion point at the coil centre (every
shipped tentacle) workspace (x, y) are coils (x, y). The inserted length is the inserter
stage's position minus its position with the tip at the insertion point
(``insertion_offset_m``, 0 when homed there). Arrays: points (N, 3) or (N, 2), metre.
"""

import numpy as np


def workspace_from_coils(points_m, insertion_point_m=(0.0, 0.0, 0.0)):
    """Return (N, 2) workspace points, m, of (N, 3) coils points (z is along the view)."""
    points = np.asarray(points_m, dtype=float).reshape(-1, 3)
    return points[:, :2] - np.asarray(insertion_point_m, dtype=float)[:2]


def coils_from_workspace(points_m, insertion_point_m=(0.0, 0.0, 0.0)):
    """Return (N, 3) coils points, m, of (N, 2) workspace points, in the insertion point's z."""
    origin = np.asarray(insertion_point_m, dtype=float)
    points = np.asarray(points_m, dtype=float).reshape(-1, 2) + origin[:2]
    return np.column_stack([points, np.full(len(points), origin[2])])


def inserted_length_m(stage_position_m, insertion_offset_m=0.0):
    """Return the inserted length, m, at an inserter stage position, m (never below 0)."""
    return max(0.0, float(stage_position_m) - float(insertion_offset_m))


def stage_position_m(inserted_m, insertion_offset_m=0.0):
    """Return the inserter stage position, m, that inserts a length, m."""
    return float(inserted_m) + float(insertion_offset_m)
