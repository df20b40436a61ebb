"""
The coil bank's fault paths under forced interleavings: no worker threads, a virtual clock.

Each test drives the channels' ``_serve`` by hand on scripted lines and lands a zeroing
request (estop, another axis' fault) at an exact point of an exchange, from inside the
device's answer, or drops a supply at an exact lock boundary of the supervisor. What the
device was sent is then checked byte for byte: no value from before the request may follow
it.
"""

import logging
import os
import re
import threading

import pytest

from tentacle_coils import dxkdp, scpi
from tentacle_coils.coil_bank import Channel, CoilBank
from tentacle_coils.supply import make_supply
from tentacle_common.child_process import _ForwardLogs, Emitter
from tentacle_common.scripted_line import ScriptedLine

BAUD = 9600
ACK = bytes((dxkdp.ACK,))


class ScpiDevice:
    """A protocol-level SCPI supply; ``on_request(request)`` runs as each request arrives."""

    def __init__(self, on_request=None):
        self.setpoint_a, self.output_on = 0.0, False
        self.on_request = on_request or (lambda request: None)

    def __call__(self, request):
        self.on_request(request)
        header, argument, _ = scpi.parse_command(request)
        if header == 'CURR':
            self.setpoint_a = float(argument)
        elif header == 'OUTP':
            self.output_on = argument == 'ON'
        else:
            return {'CURR?': scpi.format_value(self.setpoint_a),
                    'MEAS:CURR?': scpi.format_value(self.setpoint_a),
                    'OUTP?': b'1\n' if self.output_on else b'0\n',
                    'SYST:ERR?': scpi.format_error(*scpi.NO_ERROR)}[header], 0.0005
        return b'', 0.0


class DxkdpDevice:
    """
    A protocol-level DXKDP supply (signed currents).

    ``on_request(request)`` runs as each request arrives and may return False: that request
    then gets no reply (whether it was applied is ``apply_unanswered``).
    """

    def __init__(self, on_request=None, apply_unanswered=True):
        self.setpoint_a, self.output_on = 0.0, True
        self.on_request = on_request or (lambda request: True)
        self.apply_unanswered = apply_unanswered

    def __call__(self, request):
        answer = self.on_request(request) is not False
        code = request[2]
        if code in (dxkdp.Code.CURRENT, dxkdp.Code.OUTPUT):
            if answer or self.apply_unanswered:
                if code == dxkdp.Code.CURRENT:
                    self.setpoint_a = dxkdp.count_to_current(request[4] | request[5] << 8, True)
                else:
                    self.output_on = bool(request[4])
            return (ACK if answer else b''), 0.0005
        reading = dxkdp.Reading(voltage_v=30.0, current_a=self.setpoint_a,
                                output_on=self.output_on, constant_current=True)
        return dxkdp.encode_reading(1, code, reading, signed=True), 0.0005


def bank_on(devices, dialect, slew_a_per_s=200.0):
    """Return a CoilBank (not started: no threads) on scripted lines, enabled, outputs as held."""
    channels = []
    for name, device in zip('xyz', devices):
        line = ScriptedLine(baud=BAUD, responder=device, path=f'coil_{name}')
        line.open()
        supply = make_supply(dialect, line, retries=3, reply_timeout_s=0.1,
                             max_turnaround_s=0.25)
        channel = Channel(name, supply, slew_rate_a_per_s=slew_a_per_s, readback_period_s=0.1)
        channel.connected = channel.confirmed = True
        channel.output_on = device.output_on
        channels.append(channel)
    bank = CoilBank(channels, max_current_a=10.0, watchdog_s=5.0)
    assert bank.enable(True)[0]
    return bank


def serve_until(channel, t_end_s):
    """Serve a channel until its virtual clock reaches t_end_s, skipping idle time."""
    line = channel.supply.line
    while line.now() < t_end_s:
        with channel._cond:
            wait = channel._due_in(line.now())
        if wait > 0:
            line.advance(min(wait, t_end_s - line.now()) + 1e-6)
        else:
            channel._serve()


def scpi_sets(line, since_s=0.0):
    """Return the CURR values sent (A) whose bytes left the line at or after since_s."""
    return [scpi.parse_float(data[5:]) for t, data in line.sent
            if data.startswith(b'CURR ') and t >= since_s]


def dxkdp_sets(line, since_s=0.0):
    return [(t, dxkdp.count_to_current(data[4] | data[5] << 8, True)) for t, data in line.sent
            if data[2] == dxkdp.Code.CURRENT and t >= since_s]


def test_an_estop_during_output_on_is_not_followed_by_a_step_towards_the_old_target():
    # y's output is off when a command comes; while y's OUTP ON is on the wire the estop
    # lands. Planned before the switch, the step went on towards the old 1 A target.
    landed = {}
    bank = None

    def estop_during_outp_on(request):
        if request.startswith(b'OUTP ON') and not landed:
            landed['t'] = bank.channels[1].supply.line.now()
            bank.set_estop(True)

    devices = [ScpiDevice(), ScpiDevice(estop_during_outp_on), ScpiDevice()]
    bank = bank_on(devices, 'scpi')
    y = bank.channels[1]
    bank.command([0.0, 1.0, 0.0])
    serve_until(y, 0.5)
    assert landed, 'the script never switched y on'
    assert [v for v in scpi_sets(y.supply.line, landed['t']) if v != 0.0] == []
    assert devices[1].setpoint_a == 0.0 and y.settled_zero()


@pytest.mark.parametrize('applied', [True, False], ids=['set-landed', 'set-lost'])
def test_a_retry_never_resends_a_value_zeroed_by_another_axis_fault(applied):
    # x's +2 A set is not answered; y faults meanwhile and the bank zeroes every target.
    # The retry must not send +2 A again: it reads back what x holds and ramps from there.
    fault, armed = {}, []
    bank = None

    def fault_y_on_first_set(request):
        if request[2] == dxkdp.Code.CURRENT and armed and not fault:
            fault['t'] = bank.channels[0].supply.line.now()
            y = bank.channels[1]
            y.on_fault(y, 'link lost: test')
            return False  # no reply to this set
        return True

    x_device = DxkdpDevice(fault_y_on_first_set, apply_unanswered=applied)
    slew = 100.0
    bank = bank_on([x_device, DxkdpDevice(), DxkdpDevice()], 'dxkdp', slew_a_per_s=slew)
    x = bank.channels[0]
    bank.command([1.5, 0.0, 0.0])
    serve_until(x, 0.2)
    assert x_device.setpoint_a == 1.5 and not fault
    t_armed = x.supply.line.now()
    armed.append(t_armed)
    bank.command([2.0, 0.0, 0.0])  # one step: 1.5 A to 2 A, not answered
    serve_until(x, t_armed + 1.5)
    assert fault, 'the script never faulted y'
    assert bank.fault.startswith('y: link lost')
    sets = dxkdp_sets(x.supply.line, t_armed)
    assert sets[0][1] == 2.0  # the unanswered one
    after = [v for t, v in sets[1:]]
    assert 2.0 not in after, f'a retry re-sent the zeroed value: {after}'
    # From what the device held (2 A or 1.5 A), down to zero at the slew limit, never up.
    assert after == sorted(after, reverse=True) and after[-1] == 0.0 and len(after) > 1
    steps = [v0 - v1 for v0, v1 in zip([2.0 if applied else 1.5] + after, after)]
    gaps = [t1 - t0 for (t0, _), (t1, _) in zip(sets[1:], sets[2:])]
    assert steps[0] <= slew * 0.05 + 1e-9  # the first step down: one capped interval
    assert all(s <= slew * g + dxkdp.AMPS_PER_COUNT for s, g in zip(steps[1:], gaps))
    assert x_device.setpoint_a == 0.0 and x.settled_zero()


class Interleaving:
    """
    Wrap every channel's lock to drop one supply's link at a chosen lock acquisition.

    Before acquisition number ``drop_at`` (of any channel's lock) the victim's link drops as
    its worker does on LinkLost, which needs the victim's lock: so only while that lock is
    free. ``dropped`` says whether and where the drop happened.
    """

    def __init__(self, channels, victim, drop_at):
        self.victim, self.drop_at, self.count, self.dropped = victim, drop_at, 0, None
        self.victim_held = 0
        for channel in channels:
            channel._cond = _Wrapped(channel._cond, self, channel is victim)

    def before_acquire(self):
        if self.count == self.drop_at and not self.victim_held:
            self.victim.connected = self.victim.confirmed = False
            self.dropped = self.count
        self.count += 1


class _Wrapped:
    def __init__(self, cond, interleaving, is_victim):
        self.cond, self.interleaving, self.is_victim = cond, interleaving, is_victim

    def __enter__(self):
        self.interleaving.before_acquire()
        entered = self.cond.__enter__()
        self.interleaving.victim_held += self.is_victim
        return entered

    def __exit__(self, *exc):
        self.interleaving.victim_held -= self.is_victim
        return self.cond.__exit__(*exc)

    def __getattr__(self, name):
        return getattr(self.cond, name)


@pytest.mark.parametrize('drop_at', range(8))
def test_a_fault_never_clears_while_a_supply_is_down(drop_at):
    # A fault is active and every supply read back zero; y drops just before the
    # supervisor's drop_at-th lock acquisition, whenever y's lock is free then. Separate
    # looks (connected, then zero; or one channel after another) let the fault clear.
    bank = bank_on([DxkdpDevice() for _ in 'xyz'], 'dxkdp')
    y = bank.channels[1]
    y.on_fault(y, 'reply timeout: test')
    interleaving = Interleaving(bank.channels, y, drop_at)
    bank.supervise_once()
    if interleaving.dropped is not None:
        assert bank.fault, f'the fault cleared with y down (dropped before lock {drop_at})'
    else:
        assert not bank.fault  # nothing dropped: every supply was up and at zero


def full_pipe():
    """Return (read fd, a text stream on a pipe whose buffer is full and nobody reads)."""
    read_end, write_end = os.pipe()
    os.set_blocking(write_end, False)
    try:
        while True:
            os.write(write_end, b'x' * 4096)
    except BlockingIOError:
        pass
    os.set_blocking(write_end, True)  # as a child's stdout is: a write now blocks
    return read_end, os.fdopen(write_end, 'w')


def test_a_stalled_event_pipe_never_holds_up_an_estop_or_a_fault():
    # The node stopped reading the bank process's stdout and the pipe is full. The bank logs
    # on estop and fault: neither may block, nor hold the bank's lock while it waits.
    read_end, stream = full_pipe()
    emit = Emitter(stream)
    handler = _ForwardLogs(emit)
    logger = logging.getLogger('tentacle_coils')
    logger.addHandler(handler)
    level = logger.level
    logger.setLevel(logging.INFO)
    try:
        bank = bank_on([DxkdpDevice() for _ in 'xyz'], 'dxkdp')
        bank.command([1.0, 1.0, 1.0])
        done = threading.Event()

        def estop_fault_and_chatter():
            bank.set_estop(True)
            y = bank.channels[1]
            y.on_fault(y, 'link lost: test')
            for i in range(2 * Emitter.QUEUE_MAX):
                logger.info('chatter %d', i)
            done.set()

        threading.Thread(target=estop_fault_and_chatter, daemon=True).start()
        assert done.wait(20.0), 'estop or fault blocked on the stalled event pipe'
        assert [ch.target_a for ch in bank.channels] == [0.0] * 3 and bank.fault
        # When the node reads again, what matters arrives: the error, and what was dropped.
        received = []
        reader = threading.Thread(target=lambda: received.append(_read_all(read_end)))
        reader.start()
        assert emit.flush(20.0)
        stream.close()
        reader.join(20.0)
        text = received[0].decode()
        assert 'supply y fault, all axes to zero' in text
        assert 'safe stop (estop)' in text
        # What the queue could not hold was info chatter: dropped, counted, and said.
        dropped = sum(int(n) for n in re.findall(r'(\d+) info log lines dropped', text))
        assert dropped and dropped + text.count('chatter') == 2 * Emitter.QUEUE_MAX
    finally:
        logger.removeHandler(handler)
        logger.setLevel(level)
        os.close(read_end)


def _read_all(fd):
    chunks = []
    while chunk := os.read(fd, 1 << 16):
        chunks.append(chunk)
    return b''.join(chunks)
