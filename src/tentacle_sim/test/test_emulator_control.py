"""The emulator processes' command line and control loop: bad input is answered, not fatal."""

import io
import json
import signal

import pytest
from tentacle_sim import emulate_stages, emulate_supplies
from tentacle_sim.emulator_control import serve_devices
from tentacle_sim.stage_emulator import GcodeStage, Step1mmStage


class Device:
    """What serve_devices needs of a device: a port, state, faults, a log, stop."""

    port = '/dev/pts/fake'

    def __init__(self):
        self.log, self.faults, self.stopped = [], [], False

    def state(self):
        return {'faults': list(self.faults)}

    def inject(self, kind, count=1):
        if kind != 'no_reply':
            raise ValueError(f"fault '{kind}' is not one of ('no_reply',)")
        self.faults.append((kind, count))

    def stop(self):
        self.stopped = True


@pytest.fixture
def serve(capsys):
    """Return a runner: control lines in, replies out after the ready line; SIGTERM kept."""
    def run(lines):
        device = Device()
        serve_devices({'e': device}, stdin=io.StringIO(''.join(f'{x}\n' for x in lines)))
        out = [json.loads(x) for x in capsys.readouterr().out.splitlines()]
        assert out[0] == {'ready': True, 'ports': {'e': Device.port}} and device.stopped
        return out[1:], device
    handler = signal.getsignal(signal.SIGTERM)
    yield run
    signal.signal(signal.SIGTERM, handler)


def test_a_malformed_control_line_is_answered_and_the_loop_goes_on(serve):
    replies, device = serve([
        '[1]', '"state"', 'null', 'not json', '{"op": "fault", "port": "e", "kind": "bogus"}',
        '{"op": "fault", "port": "x", "kind": "no_reply"}',
        '{"op": "fault", "port": "e", "kind": "no_reply", "count": [2]}',
        '{"op": "fault", "port": "e", "kind": "no_reply", "colour": 3}',
        '{"op": "log", "port": "e", "since": "soon"}', '{"op": "dance"}',
        '{"op": "fault", "port": "e", "kind": "no_reply", "count": 2}', '{"op": "state"}',
        '{"op": "quit"}', '{"op": "state"}'])
    assert replies[:3] == [{'error': 'a control request is a JSON object, got ' + kind}
                           for kind in ('list', 'str', 'NoneType')]
    assert all('error' in r for r in replies[3:10]), replies
    assert replies[10:] == [{'ok': True}, {'e': {'faults': [['no_reply', 2]]}}]  # then quit


@pytest.mark.parametrize('main', [emulate_stages.build_parser, emulate_supplies.build_parser])
@pytest.mark.parametrize('baud', ['0', '-9600', 'fast'])
def test_a_baud_that_is_not_a_positive_integer_is_a_usage_error(main, baud, capsys, tmp_path):
    with pytest.raises(SystemExit) as exit_:
        main().parse_args(['--link-dir', str(tmp_path), '--baud', baud])
    assert exit_.value.code == 2
    assert '--baud' in capsys.readouterr().err


@pytest.mark.parametrize('model', [GcodeStage, Step1mmStage])
def test_a_stage_model_refuses_a_baud_that_is_not_positive(model):
    with pytest.raises(ValueError, match='a line rate must be positive'):
        model('e', baud=0)
