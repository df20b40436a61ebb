"""
Closed loop on the tracked shape: the field correction that brings the body onto its path.

``ShapeController.correct`` takes the field held now and the centreline the camera sees
(coils x, y: the camera looks down z), compares it with the reference at equal arc lengths
from the insertion point (the desired path, as the shape error is measured, or the step's
planned centreline) and returns the field that the model's sensitivity of shape to field
says removes that error: a damped Gauss-Newton step, solved as a bounded least-squares
problem so it keeps within the coils' per-axis limits and the largest change per iteration,
then scaled into the total-field limit. The camera sees no depth, so only the in-plane
field components are corrected (the out-of-plane one stays as planned).
``TipAngleController`` is the thesis' simple baseline (eq. 6.10): the field's in-plane
angle moves by K_P times the tip-angle error until it is within a tolerance.
Both are pure (no rclpy); the player calls them at every fresh frame of a dwelling step.
Units: m, T, rad.
"""

from dataclasses import dataclass
import math

import numpy as np
from scipy.optimize import lsq_linear

REFERENCE_SAMPLES = 20  # points along the body where tracked and desired are compared
CHORD_M = 0.0025        # coiling: a body's turn over 2.5 mm chords (pixel noise at the tip)


@dataclass
class Gains:
    """The loop's knobs (a node may change them while it runs)."""

    gain: float = 1.0              # the fraction of the Gauss-Newton step taken, 0..1
    damping: float = 1e-3          # Tikhonov, relative to the sensitivity's scale
    max_step_t: float = 0.003      # largest change of a field component per iteration, T
    tolerance_m: float = 1e-4      # converged: the shape RMS against the reference below this
    max_iterations: int = 8        # per step: then the step goes on regardless
    stall_ratio: float = 0.9       # converged too: an iteration that cut the error by less
    tip_gain: float = 0.5          # eq. 6.10's K_P
    tip_tolerance_rad: float = math.radians(5.0)


@dataclass(frozen=True)
class Correction:
    """One iteration's outcome."""

    field_t: np.ndarray     # (3,) the field to hold now, T
    error_m: float          # the shape RMS (or tip angle error, rad) it corrects
    converged: bool         # within tolerance (or no iterations left): the step may go on
    iterations: int         # this step's iterations so far


def arc_lengths(points):
    """Return the cumulative arc length (N,) of a polyline (N, d), m."""
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])


def interpolation_weights(points, s):
    """Return W (len(s), N): W @ points are the polyline's points at arc lengths s (clipped)."""
    along = arc_lengths(points)
    s = np.clip(s, 0.0, along[-1])
    i = np.clip(np.searchsorted(along, s, side='right') - 1, 0, len(points) - 2)
    span = along[i + 1] - along[i]
    t = np.divide(s - along[i], span, out=np.zeros_like(s), where=span > 0)
    weights = np.zeros((len(s), len(points)))
    rows = np.arange(len(s))
    weights[rows, i] = 1.0 - t
    weights[rows, i + 1] += t
    return weights


def at_arc_lengths(points, s):
    """Return a polyline's points at arc lengths s (clipped to its length)."""
    points = np.asarray(points, dtype=float)
    return interpolation_weights(points, s) @ points


def tracked_at(seen_m, inserted_m, s):
    """
    Return a tracked centreline's points at arc lengths s of a body inserted_m long.

    A centreline traced through pixels is longer than the body (its points jitter sideways
    by a fraction of a pixel): its arc length is scaled to the inserted length, so its tip,
    which the tracker finds to a few micrometres, is where the body ends.
    """
    seen = np.asarray(seen_m, dtype=float)
    length = arc_lengths(seen)[-1]
    return at_arc_lengths(seen, np.asarray(s) * (length / inserted_m if inserted_m > 0 else 0))


def in_limits(field_t, limits):
    """Return a field (3,) T kept within CoilLimits: each axis clipped, then |B| scaled."""
    field = np.asarray(field_t, dtype=float).copy()
    if limits.max_field_t is not None:
        field = np.clip(field, -limits.max_field_t, limits.max_field_t)
    norm = np.linalg.norm(field)
    if limits.max_total_field_t is not None and norm > limits.max_total_field_t:
        field *= limits.max_total_field_t / norm
    return field


class ShapeController:
    """Field corrections from the tracked centreline, by the model's shape sensitivity."""

    def __init__(self, model, path, limits, gains=None):
        """
        Fix the model (the planned tentacle as planned), the desired path and the limits.

        :param model: a TentacleModel of the planned tentacle
        :param path: the desired path (tentacle_planner.paths.Path), frame coils
        :param limits: schedule_check.CoilLimits
        """
        self.model, self.path, self.limits = model, path, limits
        self.gains = gains or Gains()
        self.iterations, self._last_rms = 0, math.inf
        self._state, self._inserted = None, None

    def new_step(self):
        """Count iterations from zero again (a new step begins)."""
        self.iterations, self._last_rms = 0, math.inf

    def reference(self, inserted_m, s, planned_m=None):
        """Return the desired (len(s), 2) x, y: the path, or a planned centreline, at s."""
        if planned_m is not None:
            return at_arc_lengths(planned_m, s)[:, :2]
        return self.path.at(np.clip(s, 0.0, self.path.length_m))[:, :2]

    def sensitivity(self, inserted_m, field_t, s):
        """Return d(x, y at arc lengths s)/dB (2 len(s), 3) of the model's equilibrium."""
        start = None
        if self._state is not None:
            start = self.model.carry(self._state, self._inserted, inserted_m)
        solution = self.model.solve(inserted_m, field_t, start)
        if np.all(np.isfinite(solution.state)):
            self._state, self._inserted = solution.state, inserted_m
        jacobian = self.model.field_sensitivity(solution, field_t).points   # (n+1, 3, 3)
        weights = interpolation_weights(solution.points_m, s)
        return np.einsum('rk,kxp->rxp', weights, jacobian)[:, :2, :].reshape(-1, 3)

    def correct(self, inserted_m, field_t, seen_xy_m, planned_m=None):
        """
        Return the Correction for one tracked centreline.

        :param inserted_m: the inserted length now, m
        :param field_t: (3,) the field held now, T
        :param seen_xy_m: (N, 2) the tracked centreline, base to tip, coils x and y, m
        :param planned_m: (k, 3) the step's planned centreline to follow instead of the path
        """
        g = self.gains
        field = np.asarray(field_t, dtype=float)
        seen = np.asarray(seen_xy_m, dtype=float)
        if len(seen) < 2 or inserted_m <= 0:
            return Correction(field, math.nan, True, self.iterations)
        s = np.linspace(0.0, inserted_m, REFERENCE_SAMPLES)
        error = tracked_at(seen, inserted_m, s) - self.reference(inserted_m, s, planned_m)
        rms = float(np.sqrt(np.mean(np.sum(error ** 2, axis=1))))
        stalled = rms > g.stall_ratio * self._last_rms
        self._last_rms = min(rms, self._last_rms)
        if rms <= g.tolerance_m or stalled or self.iterations >= g.max_iterations:
            return Correction(field, rms, True, self.iterations)
        self.iterations += 1
        jacobian = self.sensitivity(inserted_m, field, s)[:, :2]   # Bx, By: the camera's plane
        scale = np.trace(jacobian.T @ jacobian) / 2 or 1.0
        low = np.full(2, -g.max_step_t)
        high = np.full(2, g.max_step_t)
        if self.limits.max_field_t is not None:
            low = np.maximum(low, -self.limits.max_field_t - field[:2])
            high = np.minimum(high, self.limits.max_field_t - field[:2])
        high = np.maximum(high, low)   # a field already past a limit: only back towards it
        damped = np.vstack([jacobian, math.sqrt(g.damping * scale) * np.eye(2)])
        target = np.concatenate([-g.gain * error.ravel(), np.zeros(2)])
        step = lsq_linear(damped, target, bounds=(low, high + 1e-15)).x
        corrected = in_limits(field + np.array([step[0], step[1], 0.0]), self.limits)
        return Correction(corrected, rms, False, self.iterations)


def heading_rad(points):
    """Return the in-plane direction (rad, about z) of a polyline's last segment."""
    d = np.asarray(points, dtype=float)[-1] - np.asarray(points, dtype=float)[-2]
    return math.atan2(d[1], d[0])


def wrapped(angle_rad):
    """Return an angle in (-pi, pi]."""
    return math.atan2(math.sin(angle_rad), math.cos(angle_rad))


def turning_rad(points, start_heading_rad=None, chord_m=None):
    """
    Return how far a polyline (N, 2+) turns from its first segment to its last, rad.

    About z, unwrapped: each turn between neighbouring segments in (-pi, pi], summed, so a
    coil past a full turn says more than 2 pi.

    :param start_heading_rad: the direction it starts from (the insertion direction), in
        place of its first segment's: a tracked centreline's first pixels may step sideways
    :param chord_m: take the polyline in chords this long, counted back from its end (the
        last a whole chord): a centreline traced through pixels turns by its jitter from
        one short segment to the next, and its last segment may be a fraction of a pixel
    """
    points = np.asarray(points, dtype=float)[:, :2]
    if chord_m is not None:
        length = arc_lengths(points)[-1]
        points = at_arc_lengths(points, np.unique(np.clip(
            length - np.arange(0.0, length + chord_m, chord_m)[::-1], 0.0, length)))
    d = np.diff(points, axis=0)
    headings = np.arctan2(d[:, 1], d[:, 0])[np.hypot(d[:, 0], d[:, 1]) > 0]
    if start_heading_rad is not None:
        headings = np.concatenate([[start_heading_rad], headings])
    return float(np.sum(np.angle(np.exp(1j * np.diff(headings)))))


def turned_field(field_t, turn_rad, limits):
    """Return a field turned in the x-y plane by an angle (rad): |B| in-plane kept, Bz kept."""
    field = np.asarray(field_t, dtype=float)
    magnitude = math.hypot(field[0], field[1])
    angle = math.atan2(field[1], field[0]) + turn_rad
    return in_limits([magnitude * math.cos(angle), magnitude * math.sin(angle), field[2]],
                     limits)


class TipAngleController:
    """Thesis eq. 6.10: theta_act(t) = K_P theta_err(t) + theta_act(t - 1), |B| fixed."""

    def __init__(self, path, limits, gains=None):
        """Fix the desired path (its heading at the tip is the desired tip angle)."""
        self.path, self.limits = path, limits
        self.gains = gains or Gains()
        self.iterations = 0

    def new_step(self):
        """Count iterations from zero again (a new step begins)."""
        self.iterations = 0

    def desired_rad(self, inserted_m):
        """Return the path's heading at an arc length, rad about z."""
        s = np.clip([inserted_m - 1e-4, inserted_m], 0.0, self.path.length_m)
        return heading_rad(self.path.at(s))

    def correct(self, inserted_m, field_t, tip_heading_rad):
        """
        Return the Correction: the in-plane field turned by K_P times the tip angle error.

        :param tip_heading_rad: the tracked tip's heading, rad about z (/vision/tip)
        """
        return self.law(field_t, wrapped(self.desired_rad(inserted_m) - tip_heading_rad))

    def law(self, field_t, error_rad):
        """Return eq. 6.10's Correction for a tip angle error (desired - measured), rad."""
        g = self.gains
        field = np.asarray(field_t, dtype=float)
        if abs(error_rad) <= g.tip_tolerance_rad or self.iterations >= g.max_iterations:
            return Correction(field, error_rad, True, self.iterations)
        self.iterations += 1
        return Correction(turned_field(field, g.tip_gain * error_rad, self.limits), error_rad,
                          False, self.iterations)


class CoilingController(TipAngleController):
    """
    Thesis chapter 6's coiling: eq. 6.10 on how far the body has turned, then open loop.

    The desired angle is how far the step's planned centreline turns from base to tip, the
    measured one how far the tracked centreline does (both unwrapped: a coil passes 180
    deg). Beyond ``feedback_max_rad`` (220 deg in the thesis: past it the tip closes the
    circle and is lost to the camera) the step is played open loop, as planned.
    """

    def __init__(self, limits, gains=None, feedback_max_rad=math.radians(220.0),
                 insertion_heading_rad=0.0):
        """Fix the limits, the gains, where the feedback ends and the insertion direction."""
        super().__init__(None, limits, gains)
        self.feedback_max_rad = feedback_max_rad
        self.start = insertion_heading_rad

    def active(self, planned_m):
        """Return whether a step with this planned centreline is closed by the feedback."""
        return abs(turning_rad(planned_m, self.start, CHORD_M)) <= self.feedback_max_rad

    def correct(self, planned_m, field_t, seen_m):
        """
        Return the Correction of a step: eq. 6.10 while active, else the field as it is.

        :param planned_m: (k, 2+) the step's planned centreline, base to tip
        :param seen_m: (N, 2+) the tracked centreline, base to tip, the same frame
        """
        error = turning_rad(planned_m, self.start, CHORD_M) - turning_rad(seen_m, self.start,
                                                                          CHORD_M)
        if not self.active(planned_m):
            return Correction(np.asarray(field_t, dtype=float), error, True, self.iterations)
        return self.law(field_t, error)
