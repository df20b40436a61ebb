"""
An R-L coil driven by a constant-current supply with a compliance voltage.

The supply applies V = clip(R * I_set, -V_max, V_max) to the coil, so the current relaxes to
V / R with time constant L / R (exactly, between setpoint changes), and a setpoint beyond
V_max / R is never reached. With the output off V = 0 and the current decays to zero.
"""

import math
import threading
import time


class CoilLoad:
    """Current in one coil (A) as a function of time; thread-safe."""

    def __init__(self, resistance_ohm=1.0, inductance_h=0.01, compliance_v=40.0,
                 clock=time.monotonic):
        """
        Start at rest: zero current, output off.

        :param resistance_ohm: coil resistance, > 0
        :param inductance_h: coil inductance, >= 0 (0: the current follows at once)
        :param compliance_v: largest magnitude of output voltage, > 0
        """
        if resistance_ohm <= 0 or inductance_h < 0 or compliance_v <= 0:
            raise ValueError('coil needs resistance_ohm > 0, inductance_h >= 0, '
                             'compliance_v > 0')
        self.resistance_ohm = resistance_ohm
        self.tau_s = inductance_h / resistance_ohm
        self.compliance_v = compliance_v
        self._clock = clock
        self._lock = threading.Lock()
        self._t = clock()
        self._current_a = 0.0
        self.setpoint_a = 0.0
        self.output_on = False

    def _voltage_v(self):
        if not self.output_on:
            return 0.0
        v = self.resistance_ohm * self.setpoint_a
        return max(-self.compliance_v, min(self.compliance_v, v))

    def _advance(self):
        now = self._clock()
        target = self._voltage_v() / self.resistance_ohm
        if self.tau_s == 0:
            self._current_a = target
        else:
            self._current_a = target + (self._current_a - target) * math.exp(
                -(now - self._t) / self.tau_s)
        self._t = now

    def drive(self, setpoint_a=None, output_on=None):
        """Change the setpoint (A) and/or the output state from now on."""
        with self._lock:
            self._advance()
            if setpoint_a is not None:
                self.setpoint_a = float(setpoint_a)
            if output_on is not None:
                self.output_on = bool(output_on)

    def current_a(self):
        """Return the coil current now (A)."""
        with self._lock:
            self._advance()
            return self._current_a

    def voltage_v(self):
        """Return the terminal voltage now (V): R I + L dI/dt = the applied voltage."""
        with self._lock:
            return self._voltage_v()
