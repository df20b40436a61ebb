"""
Field <-> current maths of a 3-axis coil: B = A @ I + b0, and the limits on a command.

A (3x3, tesla per ampere) is the calibrated actuation matrix, cross-coupling allowed; b0
(tesla) the field with zero current (ambient field, residual magnetisation). Both come from
config and are fitted by calibration.py.
"""

from dataclasses import dataclass

import numpy as np

from tentacle_coils.errors import CommandRejected, ConfigError

AXES = ('x', 'y', 'z')
MAX_CONDITION = 1e6


class ActuationMap:
    """The affine map between coil currents (A) and the uniform field (T)."""

    def __init__(self, matrix_t_per_a, offset_t=(0.0, 0.0, 0.0)):
        """
        Check and store the calibration.

        :param matrix_t_per_a: 9 floats row-major or a (3, 3) array, tesla per ampere
        :param offset_t: (3,) field at zero current, tesla
        :raises ConfigError: wrong shape, not finite, or singular (a field it cannot make)
        """
        matrix = np.asarray(matrix_t_per_a, dtype=float)
        if matrix.size != 9:
            raise ConfigError(f'actuation_matrix needs 9 values (3x3 row-major), '
                              f'got {matrix.size}')
        matrix = matrix.reshape(3, 3)
        offset = np.asarray(offset_t, dtype=float).reshape(-1)
        if offset.size != 3:
            raise ConfigError(f'field_offset needs 3 values, got {offset.size}')
        if not (np.all(np.isfinite(matrix)) and np.all(np.isfinite(offset))):
            raise ConfigError('actuation_matrix and field_offset must be finite')
        if np.linalg.cond(matrix) > MAX_CONDITION:
            raise ConfigError(f'actuation_matrix is singular or nearly so '
                              f'(condition number {np.linalg.cond(matrix):.3g})')
        self.matrix = matrix
        self.offset = offset
        self._inverse = np.linalg.inv(matrix)

    def field(self, currents_a):
        """Return the field in tesla, shape (3,), that currents in ampere, shape (3,), make."""
        return self.matrix @ np.asarray(currents_a, dtype=float) + self.offset

    def currents(self, field_t):
        """Return the currents in ampere, shape (3,), that make a field in tesla, shape (3,)."""
        return self._inverse @ (np.asarray(field_t, dtype=float) - self.offset)


@dataclass(frozen=True)
class Limits:
    """What a command may ask for; clamp: scale a command down instead of rejecting it."""

    max_current_a: float
    max_field_t: float
    clamp: bool = False


def plan_currents(field_t, actuation, limits):
    """
    Return (currents (3,) in A, note) for a field command, or raise.

    Validation order: finite, field limit (per axis), current limit (per axis). With
    ``limits.clamp`` an over-limit command is scaled down as a whole, so the field keeps its
    direction (what steers a tentacle), and the note says by how much.

    :param field_t: (3,) desired field, tesla
    :raises CommandRejected: with the reason, when the command must not reach the wire
    """
    field = np.asarray(field_t, dtype=float).reshape(-1)
    if field.size != 3 or not np.all(np.isfinite(field)):
        raise CommandRejected(f'field {field.tolist()} T is not three finite numbers')
    note = ''
    worst = np.max(np.abs(field))
    if worst > limits.max_field_t:
        axis = AXES[int(np.argmax(np.abs(field)))]
        if not limits.clamp:
            raise CommandRejected(f'field {axis} = {field[AXES.index(axis)]:.6g} T exceeds '
                                  f'max_field {limits.max_field_t:g} T')
        field = field * (limits.max_field_t / worst)
        note = f'field scaled by {limits.max_field_t / worst:.4f} to max_field'
    currents = actuation.currents(field)
    worst = np.max(np.abs(currents))
    if worst > limits.max_current_a:
        i = int(np.argmax(np.abs(currents)))
        if not limits.clamp:
            raise CommandRejected(f'current {AXES[i]} = {currents[i]:.4g} A for this field '
                                  f'exceeds max_current {limits.max_current_a:g} A')
        currents = currents * (limits.max_current_a / worst)
        note = (note + '; ' if note else '') + (
            f'currents scaled by {limits.max_current_a / worst:.4f} to max_current')
    return currents, note
