"""Field <-> current maths and command limits."""

import numpy as np
import pytest

from tentacle_coils.errors import CommandRejected, ConfigError
from tentacle_coils.field_map import ActuationMap, Limits, plan_currents

REFERENCE = np.diag([0.53e-3, 1.07e-3, 0.65e-3])  # T/A, DESIGN.md reference rig


def test_round_trip_with_cross_coupling_and_offset():
    rng = np.random.default_rng(1)
    matrix = REFERENCE + 0.05e-3 * rng.standard_normal((3, 3))
    amap = ActuationMap(matrix.ravel(), offset_t=[1e-5, -2e-5, 4e-5])
    currents = np.array([3.0, -7.5, 12.0])
    field = matrix @ currents + [1e-5, -2e-5, 4e-5]  # B = A I + b0, written out
    np.testing.assert_allclose(amap.field(currents), field, rtol=1e-12)
    np.testing.assert_allclose(amap.currents(field), currents, rtol=1e-9)


@pytest.mark.parametrize('matrix, match', [
    ([1.0] * 8, '9 values'), (np.ones(9), 'singular'), ([np.nan] + [0.0] * 8, 'finite')])
def test_bad_calibration_is_a_config_error(matrix, match):
    with pytest.raises(ConfigError, match=match):
        ActuationMap(matrix)


def test_limits_reject_with_the_axis_named():
    amap = ActuationMap(REFERENCE)
    limits = Limits(max_current_a=40.0, max_field_t=0.022)
    with pytest.raises(CommandRejected, match='field y = 0.03 T exceeds max_field'):
        plan_currents([0.0, 0.03, 0.0], amap, limits)
    with pytest.raises(CommandRejected, match='current x = 41.51 A .* exceeds max_current 40'):
        plan_currents([0.022, 0.0, 0.0], amap, limits)
    for bad in ([np.nan, 0, 0], [0, np.inf, 0], [0, 0]):
        with pytest.raises(CommandRejected, match='not three finite'):
            plan_currents(bad, amap, limits)


def test_clamp_scales_the_whole_command_and_keeps_direction():
    amap = ActuationMap(REFERENCE)
    limits = Limits(max_current_a=40.0, max_field_t=0.022, clamp=True)
    currents, note = plan_currents([0.044, 0.011, 0.0], amap, limits)
    assert np.max(np.abs(currents)) == pytest.approx(40.0)
    field = amap.field(currents)
    assert field[1] / field[0] == pytest.approx(0.25)
    assert 'field scaled by 0.5000' in note and 'currents scaled' in note
