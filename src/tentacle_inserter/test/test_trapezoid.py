"""Trapezoidal moves against their closed forms and their own integral."""

import numpy as np
import pytest
from tentacle_inserter.trapezoid import move_time_s, position_at


def test_move_times_of_a_trapezoid_and_a_triangle():
    # 10 mm at up to 5 mm/s, 50 mm/s^2: 0.1 s ramps (0.25 mm each), 9.5 mm at 5 mm/s.
    assert move_time_s(0.010, 0.005, 0.05) == pytest.approx(0.1 + 1.9 + 0.1)
    # 0.1 mm never reaches 5 mm/s: a triangle, 2 sqrt(d / a).
    assert move_time_s(-0.0001, 0.005, 0.05) == pytest.approx(2 * np.sqrt(0.0001 / 0.05))
    assert move_time_s(0.0, 0.005, 0.05) == 0.0
    with pytest.raises(ValueError):
        move_time_s(0.01, 0.0, 0.05)


@pytest.mark.parametrize('start, target', [(0.0, 0.010), (0.020, 0.0199), (0.05, 0.01)])
def test_position_is_the_integral_of_velocity_and_ends_at_rest(start, target):
    vmax, accel = 0.005, 0.05
    total = move_time_s(target - start, vmax, accel)
    t = np.linspace(0.0, total, 20001)
    samples = [position_at(x, start, target, vmax, accel) for x in t]
    position, velocity = np.array(samples).T
    assert position[0] == pytest.approx(start) and position[-1] == pytest.approx(target)
    assert velocity[0] == 0.0 and velocity[-1] == 0.0
    assert np.max(np.abs(velocity)) <= vmax * (1 + 1e-12)
    integral = start + np.concatenate([[0.0], np.cumsum(0.5 * (velocity[1:] + velocity[:-1])
                                                        * np.diff(t))])
    np.testing.assert_allclose(position, integral, atol=1e-9)
    assert np.all(np.abs(np.diff(velocity)) <= accel * np.diff(t) * (1 + 1e-6) + 1e-12)
