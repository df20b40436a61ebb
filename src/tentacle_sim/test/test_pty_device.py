"""The pty device base on its own: a device model that is not a supply, seen from the wire."""

import json
import os
import pathlib
import select
import subprocess
import sys
import time
import tty

import pytest
from tentacle_sim.pty_device import PtyDevice
from tentacle_sim.supply_emulator import DxkdpSupply, make_supply, ScpiSupply

SRC = pathlib.Path(__file__).resolve().parents[2]


class ShoutDevice(PtyDevice):
    """Lines in, the same line upper-cased out; refuses lines that start with '!'."""

    FAULT_KINDS = PtyDevice.FAULT_KINDS + ('nak',)

    def frame(self, buf):
        end = buf.find(b'\n')
        return ('wait', 0) if end < 0 else ('request', end + 1)

    def handle(self, request, apply):
        return {'line': request.decode().strip()}, request.upper()

    def refusal(self):
        return b'NO\n'

    def matches(self, request, match):
        return match is None or request.startswith(match)


def read_line(fd, timeout_s=1.0):
    out, deadline = b'', time.monotonic() + timeout_s
    while not out.endswith(b'\n') and time.monotonic() < deadline:
        if select.select([fd], [], [], max(deadline - time.monotonic(), 0))[0]:
            out += os.read(fd, 256)
    return out


@pytest.fixture
def device(on_pty, tmp_path):
    return lambda **kwargs: on_pty(ShoutDevice, 's', log_path=str(tmp_path / 's.log'), **kwargs)


def test_a_request_is_paced_answered_and_logged(device, tmp_path):
    dev, fd = device(baud=2400, delay_s=0.01)
    t0 = time.monotonic()
    os.write(fd, b'hello\n')
    assert read_line(fd) == b'HELLO\n'
    # 6 bytes in and 6 out at 2400 baud (10 bits a byte), and the device's 10 ms.
    assert time.monotonic() - t0 >= 12 * 10 / 2400 + 0.01
    assert dev.log[-1]['line'] == 'hello' and dev.log[-1]['t'] >= t0 + 6 * 10 / 2400
    on_disk = [json.loads(line) for line in (tmp_path / 's.log').read_text().splitlines()]
    assert on_disk == dev.log


def test_request_faults_count_down_and_match(device):
    dev, fd = device(baud=115200)
    dev.inject('no_reply', count=1)
    os.write(fd, b'one\n')
    assert read_line(fd, 0.2) == b''
    dev.inject('nak', count=2, match=b'!')
    os.write(fd, b'two\n')
    assert read_line(fd) == b'TWO\n'                       # does not match: answered
    os.write(fd, b'!three\n')
    assert read_line(fd) == b'NO\n'                        # refused
    assert dev.pending_faults() == {'nak': 1}
    dev.inject('garble')
    os.write(fd, b'four\n')
    assert read_line(fd, 0.3) == b'FOUR\x0b'               # last byte changed
    assert [e.get('fault') for e in dev.log] == ['no_reply', None, 'nak', 'garble']


def test_a_disconnect_removes_the_port_and_it_comes_back(device):
    dev, fd = device(baud=115200)
    dev.inject('disconnect', duration_s=0.3)
    deadline = time.monotonic() + 1.0
    while dev.connected and time.monotonic() < deadline:
        time.sleep(0.01)
    assert not dev.connected and not os.path.lexists(dev.link_path)
    while not dev.connected and time.monotonic() < deadline + 1.0:
        time.sleep(0.01)
    fd2 = os.open(dev.port, os.O_RDWR | os.O_NOCTTY)
    tty.setraw(fd2)
    try:
        os.write(fd2, b'back\n')
        assert read_line(fd2) == b'BACK\n'
    finally:
        os.close(fd2)


def test_one_device_model_per_dialect():
    assert type(make_supply('x', 'dxkdp')) is DxkdpSupply
    assert type(make_supply('x', 'scpi', baud=115200)) is ScpiSupply
    assert make_supply('x', 'scpi').dialect == 'scpi'
    with pytest.raises(ValueError, match="dialect 'modbus' is not dxkdp or scpi"):
        make_supply('x', 'modbus')
    with pytest.raises(ValueError, match='a line rate must be positive'):
        make_supply('x', 'dxkdp', baud=0)
    with pytest.raises(ValueError, match="fault 'nak' is not one of"):
        PtyDevice('p').inject('nak')   # the bare line has no refusal


def test_a_serial_number_is_the_same_in_every_run():
    # Python salts str hashes per process: two processes with two seeds must still agree.
    code = ('from tentacle_sim.supply_emulator import make_supply; '
            "print(make_supply('x', 'scpi').serial)")
    path = os.pathsep.join(str(SRC / p) for p in ('tentacle_sim', 'tentacle_coils',
                                                  'tentacle_common'))
    serials = {subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                              check=True, env={**os.environ, 'PYTHONHASHSEED': seed,
                                               'PYTHONPATH': path}).stdout.strip()
               for seed in ('1', '2')}
    assert len(serials) == 1 and len(serials.pop()) == 5
