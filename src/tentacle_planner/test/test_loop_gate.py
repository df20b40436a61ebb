"""The closed loop's gate and figures on a virtual clock: which frames may drive a correction."""

import math

import pytest
from tentacle_planner.loop_gate import LoopFigures, LoopGate

SETTLE_S, RATE_HZ = 0.02, 15.0


def test_a_frame_taken_before_a_field_change_settled_is_stale_and_one_after_is_fresh():
    gate = LoopGate()
    gate.field_changed(100.0, SETTLE_S)
    assert not gate.fresh(100.0, 5.0, RATE_HZ)              # the field of before
    assert not gate.fresh(100.0 + SETTLE_S - 1e-6, 5.0, RATE_HZ)   # coils still settling
    assert gate.fresh(100.0 + SETTLE_S, 5.0, RATE_HZ)


def test_the_dwell_moves_the_boundary_forward_never_back():
    gate = LoopGate()
    gate.field_changed(100.0, SETTLE_S)
    gate.dwell_began(100.5)              # the stage moved until then
    assert not gate.fresh(100.4, 5.0, RATE_HZ) and gate.fresh(100.5, 5.0, RATE_HZ)
    gate.dwell_began(99.0)               # a clock read early does not reopen the past
    assert not gate.fresh(100.4, 5.0, RATE_HZ)


def test_corrections_come_at_most_at_the_rate():
    gate = LoopGate()
    gate.corrected(10.0, step=1, latency_s=0.05, converged=False)
    period = 1.0 / RATE_HZ
    assert not gate.fresh(200.0, 10.0 + period - 1e-6, RATE_HZ)
    assert gate.fresh(200.0, 10.0 + period + 1e-9, RATE_HZ)


def test_a_converged_step_rests_until_the_next_step():
    gate = LoopGate()
    gate.corrected(10.0, step=1, latency_s=0.05, converged=True)
    assert not gate.fresh(200.0, 20.0, RATE_HZ)     # within tolerance: no more corrections
    gate.new_step()
    assert gate.fresh(200.0, 20.0, RATE_HZ)


def test_figures_rate_from_one_step_intervals_latency_from_commands_sent():
    figures = LoopFigures()
    # Step 1 at 10 Hz; step 2's first frame is not an interval (the step moved in between).
    for k, now in enumerate([0.0, 0.1, 0.2, 0.3]):
        figures.evaluated(now, 1, 0.040 + 0.010 * k, corrected=True)
    figures.evaluated(5.0, 2, 0.5, corrected=False)     # converged: no command, no latency
    figures.evaluated(5.08, 2, 0.5, corrected=False)
    assert list(figures.intervals_s) == pytest.approx([0.1, 0.1, 0.1, 0.08])
    assert figures.rate_hz() == pytest.approx(10.0)
    values = figures.values()
    assert values['loop_corrections'] == 4
    assert float(values['loop_latency_ms_median']) == pytest.approx(55.0)
    assert float(values['loop_latency_ms_p95']) == pytest.approx(68.5)   # numpy's linear p95


def test_no_frames_no_figures():
    values = LoopFigures().values()
    assert values['loop_corrections'] == 0 and math.isnan(float(values['loop_rate_hz']))
    assert values['loop_latency_ms_median'] == 'nan'
