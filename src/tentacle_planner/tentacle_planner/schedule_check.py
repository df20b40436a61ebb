"""
Whether a schedule may be played on this rig: the reasons to refuse it, in words.

A schedule is refused when it was planned for another tentacle than the one on the rig
(geometry, stiffness, magnetisation or insertion pose differ beyond a manufacturing
tolerance), or when its fields break the coils' limits: per axis, in total, or in the change
from one step to the next (the run starts and ends at zero field, so the first step's field
and, retracting, the last one's count as changes too). The format is the reader's to
refuse (schedule_file.read_schedule). Pure: no rclpy.
"""

from dataclasses import dataclass
import math

import numpy as np

RELATIVE_TOLERANCE = 0.01    # lengths, sections, moduli, remanence: 1 %
ANGLE_TOLERANCE_DEG = 5.0    # magnetisation and insertion directions
POSITION_TOLERANCE_M = 1e-4  # the insertion point
FIELD_SLACK_T = 1e-9         # a field written to YAML and read back is not bit-exact


@dataclass(frozen=True)
class CoilLimits:
    """What the coils allow; None: no such limit. Tesla."""

    max_field_t: float | None = None         # per axis
    max_total_field_t: float | None = None   # |B|
    max_field_change_t: float | None = None  # per axis, from one step to the next

    def tightest(self, other):
        """Return the limits both allow (the smaller of each)."""
        def least(a, b):
            return b if a is None else a if b is None else min(a, b)
        return CoilLimits(least(self.max_field_t, other.max_field_t),
                          least(self.max_total_field_t, other.max_total_field_t),
                          least(self.max_field_change_t, other.max_field_change_t))


def field_refusals(fields_t, limits, from_zero=True):
    """
    Return why a sequence of fields (k, 3), T, breaks the limits: [] when it does not.

    :param from_zero: the field before the first step and after the last is zero, so the
        first and last fields are changes from zero too
    """
    fields = np.asarray(fields_t, dtype=float).reshape(-1, 3)
    reasons = []
    if not np.all(np.isfinite(fields)):
        bad = int(np.flatnonzero(~np.all(np.isfinite(fields), axis=1))[0])
        return [f'step {bad + 1}: the field is not finite']
    mt = 1e3
    if limits.max_field_t is not None:
        over = np.abs(fields).max(axis=1) > limits.max_field_t + FIELD_SLACK_T
        for k in np.flatnonzero(over)[:3]:
            reasons.append(f'step {k + 1}: a field component of '
                           f"{np.abs(fields[k]).max() * mt:.2f} mT is over the coils' "
                           f'{limits.max_field_t * mt:g} mT per axis')
    if limits.max_total_field_t is not None:
        norms = np.linalg.norm(fields, axis=1)
        for k in np.flatnonzero(norms > limits.max_total_field_t + FIELD_SLACK_T)[:3]:
            reasons.append(f"step {k + 1}: |B| {norms[k] * mt:.2f} mT is over the coils' "
                           f'{limits.max_total_field_t * mt:g} mT in total')
    if limits.max_field_change_t is not None:
        labels = [f'step {k + 1}' for k in range(len(fields))]
        if from_zero:
            fields, labels = np.vstack([np.zeros(3), fields, np.zeros(3)]), \
                ['zero field', *labels, 'zero field']
        changes = np.abs(np.diff(fields, axis=0)).max(axis=1)
        for k in np.flatnonzero(changes > limits.max_field_change_t + FIELD_SLACK_T)[:3]:
            reasons.append(f'{labels[k]} to {labels[k + 1]}: {changes[k] * mt:.2f} mT of change '
                           f"on one axis is over the coils' {limits.max_field_change_t * mt:g} "
                           'mT per step')
    return reasons


def _differs(a, b, tolerance=RELATIVE_TOLERANCE):
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return a.shape != b.shape or bool(np.any(np.abs(a - b) > tolerance * np.maximum(
        np.abs(a), np.abs(b)) + 1e-15))


def _angle_deg(a, b):
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    na, nb = np.linalg.norm(a), np.linalg.norm(b)
    if na == 0 or nb == 0:
        return 0.0 if na == nb else 180.0
    return math.degrees(math.acos(np.clip(a @ b / (na * nb), -1.0, 1.0)))


def tentacle_refusals(planned, rig):
    """
    Return how the planned tentacle differs from the rig's beyond tolerance: [] if it does not.

    :param planned: the schedule's tentacle (a TentacleSpec)
    :param rig: the tentacle on the rig (a TentacleSpec, from its tentacle file)
    """
    if len(planned.segments) != len(rig.segments):
        return [f"{len(planned.segments)} segments planned, the rig's tentacle "
                f'{rig.name!r} has {len(rig.segments)}']
    reasons = []
    for i, (p, r) in enumerate(zip(planned.segments, rig.segments), start=1):
        for what, a, b in (('length', p.length_m, r.length_m),
                           ('section', (p.area_m2, *p.second_moment_m4),
                            (r.area_m2, *r.second_moment_m4)),
                           ('moduli', p.modulus_pa, r.modulus_pa),
                           ('remanence', np.linalg.norm(p.magnetisation_a_per_m),
                            np.linalg.norm(r.magnetisation_a_per_m))):
            if _differs(a, b):
                reasons.append(f'segment {i}: the {what} differs')
        angle = _angle_deg(p.magnetisation_a_per_m, r.magnetisation_a_per_m)
        if angle > ANGLE_TOLERANCE_DEG:
            reasons.append(f'segment {i}: the magnetisation is {angle:.0f} deg from the '
                           "rig's tentacle")
    if np.linalg.norm(planned.base_position_m - rig.base_position_m) > POSITION_TOLERANCE_M:
        reasons.append('the insertion point differs')
    if _angle_deg(planned.base_rotation[:, 0], rig.base_rotation[:, 0]) > ANGLE_TOLERANCE_DEG:
        reasons.append('the insertion direction differs')
    if (planned.backbone is None) != (rig.backbone is None):
        reasons.append('one has a backbone, the other not')
    return reasons
