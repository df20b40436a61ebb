"""The R-L coil against its closed-form step response."""

import math

import pytest

from tentacle_sim.coil_load import CoilLoad


class FakeClock:
    """A clock the test advances by hand (time is ours to own, not a mock of our code)."""

    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


def test_step_response_is_first_order_with_tau_l_over_r():
    clock = FakeClock()
    coil = CoilLoad(resistance_ohm=2.0, inductance_h=0.02, compliance_v=100.0, clock=clock)
    coil.drive(setpoint_a=5.0, output_on=True)
    for t in (0.001, 0.01, 0.05):
        clock.t = t
        assert coil.current_a() == pytest.approx(5.0 * (1 - math.exp(-t / 0.01)), rel=1e-12)


def test_compliance_voltage_limits_the_current():
    clock = FakeClock()
    coil = CoilLoad(resistance_ohm=2.0, inductance_h=0.0, compliance_v=10.0, clock=clock)
    coil.drive(setpoint_a=-8.0, output_on=True)
    assert coil.current_a() == pytest.approx(-5.0)
    assert coil.voltage_v() == pytest.approx(-10.0)


def test_output_off_decays_to_zero():
    clock = FakeClock()
    coil = CoilLoad(resistance_ohm=1.0, inductance_h=0.01, compliance_v=50.0, clock=clock)
    coil.drive(setpoint_a=3.0, output_on=True)
    clock.t = 1.0
    assert coil.current_a() == pytest.approx(3.0)
    coil.drive(output_on=False)
    clock.t = 1.02
    assert coil.current_a() == pytest.approx(3.0 * math.exp(-2.0))


@pytest.mark.parametrize('kwargs', [{'resistance_ohm': 0}, {'inductance_h': -1},
                                    {'compliance_v': 0}])
def test_bad_parameters_raise(kwargs):
    with pytest.raises(ValueError):
        CoilLoad(**kwargs)
