"""
Protocol tests: the stage drivers against scripted exchanges on a virtual clock.

Each test lists the exact lines the driver must send and what the firmware answers, and
when (DESIGN.md's gcode, the lab's step1mm); the line fails on any other request and on
anything left over. The emulator shares the codec; these tests hold the driver to the wire.
"""

import pytest
from tentacle_common.scripted_line import Exchange, ScriptedLine, ScriptError
from tentacle_inserter import stage, step1mm
from tentacle_inserter.trapezoid import move_time_s

SPEED, ACCEL = 0.005, 0.5
OK = b'ok\n'
CONNECT = [Exchange(b'G90\n', OK),                        # the probe: a gcode firmware
           Exchange(b'M400\n', OK),                       # nothing moves: no halt
           Exchange(b'G90\n', OK),
           Exchange(b'M92 E100.00000\n', OK),
           Exchange(b'M114\n', b'X:0.00 Y:0.00 Z:0.00 E:3.2100 Count X:0 Y:0 Z:0\n' + OK)]
HOME = [Exchange(b'G92 E0.0000\n', OK),
        Exchange(b'M114\n', b'X:0.00 Y:0.00 Z:0.00 E:0.0000\n' + OK)]


def gcode_axis(script, **kwargs):
    line = ScriptedLine(script, baud=115200)
    options = {'max_length_m': 0.05, 'max_speed_m_s': SPEED, 'accel_m_s2': ACCEL,
               'steps_per_mm': 100.0, 'reply_timeout_s': 0.2, 'time_margin': 1.5,
               'slack_s': 0.5, **kwargs}
    return stage.GcodeStage(line, **options), line


def test_connect_reads_the_position_back_unhomed():
    axis, line = gcode_axis(CONNECT)
    assert axis.connect() == pytest.approx(0.00321)
    line.finish()
    assert not axis.homed
    with pytest.raises(stage.NotHomed):
        axis.move_to(0.01)          # nothing more on the wire: the script has ended


def test_connect_to_a_firmware_still_moving_halts_it_first():
    axis, line = gcode_axis(CONNECT[:1] + [
        Exchange(b'M400\n'),                                # busy: no ok in reply_timeout
        Exchange(b'M112\n'), Exchange(b'M999\n', OK)] + CONNECT[2:])
    assert axis.connect() == pytest.approx(0.00321)
    line.finish()
    assert not axis.homed


def test_a_firmware_that_must_restart_after_m112_is_waited_for_and_set_up_again():
    halted = b'Error:Printer halted. kill() called!\n'
    back = b'X:0.00 Y:0.00 Z:0.00 E:0.0000\n' + OK
    axis, line = gcode_axis(CONNECT + HOME + [
        Exchange(b'M112\n')] + [Exchange(b'M999\n', halted)] * 3 + [
        Exchange(b'M114\n', halted), Exchange(b'M114\n', halted),   # still down
        Exchange(b'M114\n', back),                                    # restarted: count 0
        Exchange(b'G90\n', OK), Exchange(b'M92 E100.00000\n', OK),    # settings again
        Exchange(b'M114\n', back)], restart_timeout_s=2.0)
    axis.connect()
    axis.home()
    t0 = line.now()
    assert axis.stop() == 0.0
    line.finish()
    # One drain of the halted line (its reply timeout), then a poll each RESTART_POLL_S.
    assert 2 * stage.RESTART_POLL_S <= line.now() - t0 < 0.2 + 2 * stage.RESTART_POLL_S + 0.05
    assert not axis.homed


def test_a_firmware_that_stays_halted_is_reported_in_its_time():
    halted = b'Error:Printer halted. kill() called!\n'
    axis, line = gcode_axis(CONNECT + [Exchange(b'M112\n')]
                            + [Exchange(b'M999\n', halted)] * 3
                            + [Exchange(b'M114\n', halted)] * 6, restart_timeout_s=0.5)
    axis.connect()
    with pytest.raises(stage.StillHalted, match='reset the board'):
        axis.stop()
    line.finish()


def test_a_move_is_one_absolute_line_waited_for_and_read_back():
    t_move = move_time_s(0.01, SPEED, ACCEL)
    axis, line = gcode_axis(CONNECT + HOME + [
        Exchange(b'G1 E10.0000 F300.00\n', OK),
        Exchange(b'M400\n', OK, after_s=t_move),
        Exchange(b'M114\n', b'X:0.00 Y:0.00 Z:0.00 E:10.0000\n' + OK)])
    axis.connect()
    axis.home()
    t0 = line.now()
    assert axis.move_to(0.01) == pytest.approx(0.01)
    line.finish()
    assert line.now() - t0 == pytest.approx(t_move, abs=0.01)


def test_an_ok_that_never_comes_to_m400_stops_the_axis_in_its_allowed_time():
    t_move = move_time_s(0.01, SPEED, ACCEL)
    allowed = t_move * 1.5 + 0.5
    axis, line = gcode_axis(CONNECT + HOME + [
        Exchange(b'G1 E10.0000 F300.00\n', OK),
        Exchange(b'M400\n'),                              # the axis stalled: never an ok
        Exchange(b'M112\n'), Exchange(b'M999\n', OK),
        Exchange(b'M114\n', b'X:0.00 Y:0.00 Z:0.00 E:4.2000\n' + OK)])
    axis.connect()
    axis.home()
    t0 = line.now()
    with pytest.raises(stage.MoveFailed, match='did not finish'):
        axis.move_to(0.01)
    line.finish()
    assert allowed <= line.now() - t0 < allowed + 0.5     # waited its time, then stopped
    assert axis.position_m == pytest.approx(0.0042) and not axis.homed


def test_a_lost_ok_to_a_move_resends_the_same_absolute_line():
    t_move = move_time_s(0.002, SPEED, ACCEL)
    move = b'G1 E2.0000 F300.00\n'
    axis, line = gcode_axis(CONNECT + HOME + [
        Exchange(move), Exchange(move, OK),               # the first ok was lost
        Exchange(b'M400\n', OK, after_s=t_move),
        Exchange(b'M114\n', b'X:0.00 Y:0.00 Z:0.00 E:2.0000\n' + OK)])
    axis.connect()
    axis.home()
    assert axis.move_to(0.002) == pytest.approx(0.002)
    line.finish()


def test_a_cancelled_move_halts_resets_and_unhomes():
    polls = []

    def cancelled():
        polls.append(line.now())
        return len(polls) > 3

    axis, line = gcode_axis(CONNECT + HOME + [
        Exchange(b'G1 E40.0000 F300.00\n', OK),
        Exchange(b'M400\n'),                              # answered at the end: never
        Exchange(b'M112\n'), Exchange(b'M999\n', OK),
        Exchange(b'M114\n', b'X:0.00 Y:0.00 Z:0.00 E:0.1000\n' + OK)])
    axis.connect()
    axis.home()
    with pytest.raises(stage.MoveStopped):
        axis.move_to(0.04, cancelled=cancelled)
    line.finish()
    assert len(polls) == 4 and polls[-1] - polls[0] == pytest.approx(3 * stage.POLL_S)
    assert axis.position_m == pytest.approx(0.0001) and not axis.homed


def test_a_refusal_is_reported_not_retried_for_ever():
    axis, line = gcode_axis(CONNECT + [Exchange(b'G92 E0.0000\n', b'Error:busy\n')] * 3,
                            retries=2)
    axis.connect()
    with pytest.raises(stage.DriverError, match='failed after 3 attempts'):
        axis.home()
    line.finish()
    assert not axis.homed


def test_the_script_fails_on_a_line_the_firmware_was_not_sent():
    axis, line = gcode_axis([Exchange(b'G91\n', OK)])
    line.open()
    with pytest.raises(ScriptError, match='the script expects'):
        axis.connect()


@pytest.mark.parametrize('mapping, extend, retract', [
    (step1mm.Mapping(), b'2', b'1'), (step1mm.EARLIER, b'1', b'2')])
def test_step1mm_sends_a_character_a_millimetre_and_expects_nothing(mapping, extend, retract):
    line = ScriptedLine([Exchange(b'3'), Exchange(extend * 3), Exchange(retract)]
                        + [Exchange(b'3')], baud=step1mm.BAUD)
    axis = stage.Step1mmStage(line, max_length_m=0.05, mapping=mapping)
    axis.connect()                                        # a stop first
    axis.home()                                           # nothing on the wire
    assert axis.move_to(0.003) == pytest.approx(0.003)
    assert axis.move_to(0.002) == pytest.approx(0.002)
    assert axis.stop() == pytest.approx(0.002)            # counted: what was sent
    line.finish()
    assert not axis.measured and axis.estimate() == (pytest.approx(0.002), 0.0, False)


def test_step1mm_waits_each_move_its_time_and_a_cancel_counts_where_it_got():
    per_mm = move_time_s(0.001, SPEED, ACCEL)
    line = ScriptedLine([Exchange(b'3'), Exchange(b'2222'), Exchange(b'3')],
                        baud=step1mm.BAUD)
    axis = stage.Step1mmStage(line, max_length_m=0.05, speed_m_s=SPEED, accel_m_s2=ACCEL)
    axis.connect()
    axis.home()
    t0 = line.now()
    with pytest.raises(stage.MoveStopped, match='stopped near 2.0 mm'):
        axis.move_to(0.004, cancelled=lambda: line.now() - t0 >= 2 * per_mm)
    line.finish()
    assert axis.position_m == pytest.approx(0.002, abs=0.0002)   # the profile's, counted


def step1mm_firmware(mapping=step1mm.Mapping()):
    """Return (responder, travel): a step1mm firmware on a scripted line, its travel in mm."""
    travel = [0]

    def responder(data):
        for byte in data:
            travel[0] += {mapping.extend: 1, mapping.retract: -1}.get(chr(byte), 0)
        return b'', 0.0                                   # it never answers
    return responder, travel


@pytest.mark.parametrize('mapping', [step1mm.Mapping(), step1mm.EARLIER])
def test_a_gcode_driver_on_a_step1mm_stage_sends_one_probe_and_nothing_more(mapping):
    responder, travel = step1mm_firmware(mapping)
    line = ScriptedLine(responder=responder, baud=115200)
    axis = stage.GcodeStage(line, max_length_m=0.05, max_speed_m_s=SPEED, accel_m_s2=ACCEL,
                            steps_per_mm=100.0, reply_timeout_s=0.2, restart_timeout_s=1.0)
    with pytest.raises(stage.NeverAnswered, match='no gcode reply in 1 s to one probe'):
        axis.connect()
    assert line.now() == pytest.approx(1.0, abs=0.01)    # listened its time, at most
    with pytest.raises(stage.NeverAnswered, match='M112 not sent; its state is unknown'):
        axis.stop()                                       # a stop into the unknown: none
    with pytest.raises(stage.NotHomed):
        axis.move_to(0.001)
    assert [data for _, data in line.sent] == [b'G90\n'] and travel == [0]


def test_noise_is_no_answer_and_a_booting_board_is_waited_for():
    axis, line = gcode_axis([Exchange(b'G90\n', b'\xfe\xfa\x00\x13\n')],
                            restart_timeout_s=0.5)   # another baud: bytes, never a reply
    with pytest.raises(stage.NeverAnswered):
        axis.connect()
    line.finish()
    # A board that resets as its port opens loses the probe and says 'start' when it is up:
    # that is an answer; its chatter is drained before the connect goes on.
    axis, line = gcode_axis([Exchange(b'G90\n', b'start\necho:Marlin 2.1\n', after_s=0.8)]
                            + CONNECT[1:], restart_timeout_s=2.0)
    assert axis.connect() == pytest.approx(0.00321)
    line.finish()


def test_step1mm_moves_only_homed_and_in_whole_millimetres():
    line = ScriptedLine([Exchange(b'3')], baud=step1mm.BAUD)
    axis = stage.Step1mmStage(line, max_length_m=0.05)
    axis.connect()
    with pytest.raises(stage.NotHomed):
        axis.move_to(0.002)                               # nothing sent: the script ended
    axis.home()
    for target in (0.0004, 0.0031):
        with pytest.raises(stage.TargetRefused, match='steps of 1 mm .its resolution'):
            axis.move_to(target)
    assert axis.check(0.003 + 1e-12) == pytest.approx(0.003)   # float noise is on the mm
    line.script += [Exchange(b'22'), Exchange(b'3')]
    assert axis.move_to(0.002) == pytest.approx(0.002)
    axis.stop()                                           # a stop unhomes, as gcode's does
    with pytest.raises(stage.NotHomed):
        axis.move_to(0.003)
    line.finish()
