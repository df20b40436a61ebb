"""
How the real rig differs from the model a plan assumed: a scene's ``mismatch`` block.

The thesis puts its remaining navigation error on exactly these: the tentacle stiffer or
softer and more or less magnetised than modelled, the insertion point placed a little off
and turned, and a coil calibration a few percent out. The simulated rig applies a scene's
mismatch (DESIGN.md "The simulated rig"); the planner's robustness report perturbs the same
knobs (``perturbed``).
"""

from dataclasses import dataclass, field, replace
import math

import numpy as np

MISMATCH_KEYS = ('stiffness_factor', 'remanence_factor', 'insertion_offset_m',
                 'insertion_angle_deg', 'actuation_matrix_factor')


def perturbed(spec, stiffness=1.0, remanence=1.0, sideways_m=0.0, turn_rad=0.0,
              offset_m=(0.0, 0.0, 0.0)):
    """
    Return a TentacleSpec with one or more things changed.

    :param stiffness: factor on every modulus (and the backbone's stiffness)
    :param remanence: factor on every magnetisation
    :param sideways_m: the insertion point moved along the base-plane normal, m
    :param turn_rad: the base direction turned in the base plane (about the base z), rad
    :param offset_m: (3,) the insertion point moved by this, rig frame, m
    """
    segments = tuple(replace(s, modulus_pa=tuple(stiffness * m for m in s.modulus_pa),
                             magnetisation_a_per_m=remanence * s.magnetisation_a_per_m)
                     for s in spec.segments)
    backbone = None if spec.backbone is None else replace(
        spec.backbone, stiffness_n_m2=stiffness * spec.backbone.stiffness_n_m2)
    c, s = math.cos(turn_rad), math.sin(turn_rad)
    turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return replace(spec, segments=segments, backbone=backbone,
                   base_position_m=spec.base_position_m + sideways_m * spec.base_rotation[:, 1]
                   + np.asarray(offset_m, dtype=float),
                   base_rotation=spec.base_rotation @ turn)


@dataclass(frozen=True)
class Mismatch:
    """The rig as it is against the model: every factor 1 and offset 0 is no mismatch."""

    stiffness_factor: float = 1.0            # on every modulus
    remanence_factor: float = 1.0            # on every magnetisation
    insertion_offset_m: tuple = (0.0, 0.0, 0.0)   # the insertion point moved, rig frame, m
    insertion_angle_deg: float = 0.0         # the insertion direction turned in the base plane
    actuation_matrix_factor: tuple = field(default=(1.0, 1.0, 1.0))  # per coil (x, y, z)

    def tentacle(self, spec):
        """Return the tentacle as the rig has it (a TentacleSpec)."""
        return perturbed(spec, self.stiffness_factor, self.remanence_factor,
                         turn_rad=math.radians(self.insertion_angle_deg),
                         offset_m=self.insertion_offset_m)

    def actuation_matrix(self, matrix_t_per_a):
        """Return the coils' true B = A I matrix (3, 3), T/A: each coil's column scaled."""
        return np.asarray(matrix_t_per_a, dtype=float).reshape(3, 3) * np.asarray(
            self.actuation_matrix_factor, dtype=float)[None, :]

    def describe(self):
        """Return one line naming what differs, or 'none'."""
        parts = []
        if self.stiffness_factor != 1.0:
            parts.append(f'stiffness x{self.stiffness_factor:g}')
        if self.remanence_factor != 1.0:
            parts.append(f'remanence x{self.remanence_factor:g}')
        if any(self.insertion_offset_m):
            parts.append('insertion point moved by ['
                         + ', '.join(f'{v * 1e3:g}' for v in self.insertion_offset_m) + '] mm')
        if self.insertion_angle_deg:
            parts.append(f'insertion turned {self.insertion_angle_deg:g} deg')
        if any(f != 1.0 for f in self.actuation_matrix_factor):
            parts.append('coils x[' + ', '.join(f'{f:g}' for f in self.actuation_matrix_factor)
                         + ']')
        return ', '.join(parts) or 'none'


def read_mismatch(read, raw):
    """
    Return the Mismatch of a scene's mismatch block (omitted keys: no mismatch).

    :param read: a FieldReader of the scene file (its refusals name the key)
    """
    raw = read.mapping(raw, 'mismatch', MISMATCH_KEYS)

    def factor(key, value):
        value = read.number(value, f'mismatch.{key}')
        if not 0.2 <= value <= 5.0:
            read.fail(f'mismatch.{key}', f'{value:g} is outside [0.2, 5]: a factor, not a '
                      'value')
        return value
    stiffness = factor('stiffness_factor', raw.get('stiffness_factor', 1.0))
    remanence = factor('remanence_factor', raw.get('remanence_factor', 1.0))
    offset = read.vector(raw.get('insertion_offset_m', [0.0, 0.0, 0.0]),
                         'mismatch.insertion_offset_m')
    if np.linalg.norm(offset) > 0.01:
        read.fail('mismatch.insertion_offset_m', f'{np.linalg.norm(offset) * 1e3:.3g} mm is '
                  'more than 10 mm: an offset, not another insertion point')
    angle = read.number(raw.get('insertion_angle_deg', 0.0), 'mismatch.insertion_angle_deg',
                        positive=False)
    if abs(angle) > 30.0:
        read.fail('mismatch.insertion_angle_deg', f'{angle:g} deg is more than 30 deg')
    coils = raw.get('actuation_matrix_factor', [1.0, 1.0, 1.0])
    if not isinstance(coils, list) or len(coils) != 3:
        read.fail('mismatch.actuation_matrix_factor', f'expected [fx, fy, fz], got {coils!r}')
    coils = tuple(factor(f'actuation_matrix_factor[{i}]', v) for i, v in enumerate(coils))
    return Mismatch(stiffness, remanence, tuple(float(v) for v in offset), angle, coils)
