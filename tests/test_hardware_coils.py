"""
First contact with real supplies: skipped unless the lab names the ports.

    TENTACLE_COILS_PORTS=/dev/ttyUSB0,/dev/ttyUSB1,/dev/ttyUSB2 \
    TENTACLE_COILS_DIALECT=dxkdp TENTACLE_COILS_BAUD=9600 \
    .venv/bin/python -m pytest -q tests/test_hardware_coils.py

With the coils connected (or a dummy load), it asks each supply for its identity, drives a
small current (TENTACLE_COILS_TEST_CURRENT_A, default 0.2 A) on one axis at a time, checks
the readback, and leaves every output at zero and off. It confirms the wire dialect on the
lab's own units before coils_node is trusted with them.
"""

import os
import time

import pytest
from tentacle_coils.coil_bank import build_bank

PORTS = os.environ.get('TENTACLE_COILS_PORTS', '')
pytestmark = pytest.mark.skipif(not PORTS, reason='no TENTACLE_COILS_PORTS: no hardware')


def test_each_supply_follows_a_small_current_and_ends_off():
    current_a = float(os.environ.get('TENTACLE_COILS_TEST_CURRENT_A', '0.2'))
    assert 0 < current_a <= 1.0, 'keep the first-contact current small (<= 1 A)'
    dialect = os.environ.get('TENTACLE_COILS_DIALECT', 'dxkdp')
    bank = build_bank(PORTS.split(','), dialect=dialect,
                      baud=int(os.environ.get('TENTACLE_COILS_BAUD', '9600')),
                      max_current_a=current_a, slew_rate_a_per_s=1.0, watchdog_s=5.0,
                      readback_period_s=0.2)
    bank.start()
    try:
        deadline = time.monotonic() + 10.0
        while not bank.connected() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert bank.connected(), [s['last_error'] for s in bank.snapshots()]
        assert bank.enable(True)[0]
        for axis in range(3):
            target = [0.0, 0.0, 0.0]
            target[axis] = current_a
            bank.command(target)
            time.sleep(current_a / 1.0 + 1.5)  # slew, settle, read back
            measured = bank.measured_currents()
            assert abs(measured[axis] - current_a) < 0.1 * current_a + 0.02, measured
            bank.command([0.0, 0.0, 0.0])
            time.sleep(current_a / 1.0 + 0.5)
    finally:
        assert bank.shutdown('hardware test done'), 'supplies did not confirm zero and off'
