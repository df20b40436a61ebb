"""
The closed loop's correction: its sensitivity and its effect on a rig unlike its model.

The sensitivity is checked by central differences; the effect on a rig whose tentacle and
coils differ from the model as the simulated rig's mismatch makes them differ.
"""

import math
import pathlib

import numpy as np
import pytest
from tentacle_model.model import TentacleModel
from tentacle_model.tentacle_spec import load_tentacle
from tentacle_planner.mismatch import Mismatch
from tentacle_planner.paths import Path, shape_error
from tentacle_planner.schedule_check import CoilLimits
from tentacle_planner.shape_control import (at_arc_lengths, CoilingController, Gains,
                                            in_limits, ShapeController, TipAngleController,
                                            turning_rad)

ROOT = pathlib.Path(__file__).resolve().parents[3]
SPEC = load_tentacle(ROOT / 'config' / 'tentacles' / 'braided_chapter5.yaml')
LIMITS = CoilLimits(max_field_t=0.022, max_total_field_t=0.030)
MISMATCH = Mismatch(stiffness_factor=0.85, remanence_factor=0.9,
                    actuation_matrix_factor=(1.05, 0.95, 1.0))


def nominal():
    return TentacleModel(SPEC, dof=3)


def reachable_path(field, inserted_m):
    """Return a path the nominal body lies on at this field and length (and 5 mm beyond)."""
    body = nominal().solve(inserted_m, field).points_m
    ahead = body[-1] + 0.005 * (body[-1] - body[-2]) / np.linalg.norm(body[-1] - body[-2])
    return Path(np.vstack([body, ahead]))


def test_the_sensitivity_is_the_derivative_of_the_resampled_shape():
    model, field = nominal(), np.array([0.004, 0.009, 0.001])
    control = ShapeController(nominal(), Path(np.array([[0, 0, 0], [0.06, 0, 0.0]])), LIMITS)
    s = np.linspace(0.0, 0.035, 20)
    analytic = control.sensitivity(0.035, field, s)
    step = 1e-6
    numeric = np.zeros_like(analytic)
    for axis in range(3):
        d = np.zeros(3)
        d[axis] = step
        up = at_arc_lengths(model.solve(0.035, field + d).points_m, s)[:, :2]
        down = at_arc_lengths(model.solve(0.035, field - d).points_m, s)[:, :2]
        numeric[:, axis] = ((up - down) / (2 * step)).ravel()
    assert np.abs(analytic - numeric).max() <= 1e-3 * np.abs(numeric).max()


def test_the_loop_cuts_the_shape_error_of_a_mismatched_rig():
    field = np.array([-0.006, 0.012, 0.0])
    path = reachable_path(field, 0.045)
    rig = TentacleModel(MISMATCH.tentacle(SPEC), dof=3)
    coils = np.asarray(MISMATCH.actuation_matrix_factor)

    def seen(b):   # the rig's body, as a camera above it sees it
        return rig.solve(0.045, coils * b).points_m

    open_loop = shape_error(seen(field), path, 0.045)[0]
    control = ShapeController(nominal(), path, LIMITS, Gains(tolerance_m=1e-5))
    held, errors = field, []
    for _ in range(10):
        correction = control.correct(0.045, held, seen(held)[:, :2])
        errors.append(correction.error_m)
        if correction.converged:
            break
        held = correction.field_t
    closed = shape_error(seen(held), path, 0.045)[0]
    assert open_loop > 5e-4   # the mismatch is visible: over half a millimetre
    assert closed < 0.05 * open_loop and correction.converged
    assert errors[0] == pytest.approx(open_loop, rel=0.05)   # 20 samples against DESIGN's RMS


def test_corrections_keep_within_the_limits_and_the_step_size():
    path = Path(np.array([[0.0, 0.0, 0.0], [0.02, 0.02, 0.0]]))   # far off: a large error
    gains = Gains(max_step_t=0.002, stall_ratio=math.inf)  # the body seen stays put
    control = ShapeController(nominal(), path, CoilLimits(max_field_t=0.010), gains)
    held = np.array([0.0, 0.009, 0.0])
    straight = np.column_stack([np.linspace(0, 0.03, 10), np.zeros(10)])
    for _ in range(5):
        correction = control.correct(0.03, held, straight)
        step = correction.field_t - held
        assert np.abs(step).max() <= 0.002 + 1e-12 and np.abs(correction.field_t).max() <= 0.010
        assert correction.field_t[2] == held[2]   # the camera's plane only
        held = correction.field_t
    assert control.iterations == 5


def test_in_limits_clips_each_axis_then_scales_the_total():
    assert in_limits([0.03, 0.0, 0.0], CoilLimits(0.022, 0.030)) == pytest.approx([0.022, 0, 0])
    scaled = in_limits([0.022, 0.022, 0.0], CoilLimits(0.022, 0.030))
    assert np.linalg.norm(scaled) == pytest.approx(0.030)
    assert scaled[0] == pytest.approx(scaled[1])


def test_the_tip_angle_law_turns_the_field_by_kp_times_the_error():
    path = Path(np.array([[0.0, 0.0, 0.0], [0.05, 0.05, 0.0]]))   # heading 45 deg
    control = TipAngleController(path, LIMITS, Gains(tip_gain=0.5))
    field = np.array([0.010, 0.0, 0.002])
    correction = control.correct(0.03, field, tip_heading_rad=0.0)
    assert correction.error_m == pytest.approx(math.pi / 4)
    assert correction.field_t == pytest.approx(
        [0.010 * math.cos(math.pi / 8), 0.010 * math.sin(math.pi / 8), 0.002])
    done = control.correct(0.03, field, tip_heading_rad=math.radians(42.0))
    assert done.converged and np.array_equal(done.field_t, field)   # within 5 deg


def arc(turn_deg, radius_m=0.0075, straight_m=0.01, points=200):
    """Return a straight run then an arc turning by turn_deg (to +y), as chapter 6's coil."""
    phi = np.radians(np.linspace(0.0, turn_deg, points))
    bend = np.column_stack([straight_m + radius_m * np.sin(phi), radius_m * (1 - np.cos(phi))])
    return np.vstack([[[0.0, 0.0]], bend])


@pytest.mark.parametrize('turn_deg', [30.0, 179.0, 181.0, 267.0, 400.0])
def test_turning_is_unwrapped_past_half_and_full_turns(turn_deg):
    half_chord = turn_deg / 199 / 2   # the last chord lags the tangent by half its angle
    assert np.degrees(turning_rad(arc(turn_deg))) == pytest.approx(turn_deg - half_chord)
    mirrored = arc(turn_deg)[:, ::-1]   # x and y swapped: the same coil the other way round
    assert np.degrees(turning_rad(mirrored)) == pytest.approx(-(turn_deg - half_chord))


def test_coiling_closes_the_tip_angle_until_220_deg_then_plays_open_loop():
    control = CoilingController(LIMITS, Gains(tip_gain=0.5))
    field = np.array([0.0, 0.020, 0.0])
    behind = control.correct(arc(200.0), field, seen_m=arc(180.0))
    assert not behind.converged   # 20 deg behind (both over 2.5 mm chords: their lag cancels)
    assert np.degrees(behind.error_m) == pytest.approx(20.0, abs=0.05)
    angle = np.degrees(np.arctan2(behind.field_t[1], behind.field_t[0]))
    assert angle == pytest.approx(90.0 + 0.5 * np.degrees(behind.error_m))   # K_P x error
    assert np.linalg.norm(behind.field_t) == pytest.approx(0.020)
    close = control.correct(arc(200.0), field, seen_m=arc(197.0))
    assert close.converged                                  # within 5 deg
    past = control.correct(arc(267.0), field, seen_m=arc(180.0))   # the tip closes the coil
    assert past.converged and np.array_equal(past.field_t, field)  # open loop: as planned


def test_a_traced_centreline_turns_by_its_noise_unless_taken_in_chords():
    rng = np.random.default_rng(3)
    x = np.append(np.arange(0.0, 0.05, 3e-4), 0.05 + 2e-5)   # 0.3 mm bands, a sliver last
    traced = np.column_stack([x, rng.normal(0.0, 2.5e-5, len(x))])   # half a pixel of jitter
    assert abs(np.degrees(turning_rad(traced, 0.0))) > 10.0          # the sliver's direction
    assert abs(np.degrees(turning_rad(traced, 0.0, 0.0025))) < 3.0   # over 2.5 mm chords
