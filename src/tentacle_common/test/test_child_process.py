"""The pipes between a node and its driver child: a bad line on either side ends nothing."""

import io
import json
import logging
import threading

from tentacle_common.child_process import ChildClient, serve


class Driver:
    """A driver for serve(): answers 'ping', raises on 'boom', records its shutdown."""

    def __init__(self, config, emit):
        self.config, self.handled, self.stopped_with = config, [], None

    def handle(self, request):
        self.handled.append(request['op'])
        if request['op'] == 'boom':
            raise KeyError('currents_a')
        return {'ok': True, 'message': 'pong'} if request['op'] == 'ping' else None

    def state(self):
        return {'status': ['ok', 'fine']}

    def shutdown(self, reason):
        self.stopped_with = reason
        return {'safe': True}


def test_the_child_refuses_a_malformed_request_and_goes_on_serving():
    # One bad line ended the request loop: the child then no longer noticed the node's death.
    lines = ['{"op": "config", "config": {"a": 1}}', 'not json', '[1]',
             '{"op": "boom", "id": 1}', '{"op": "boom"}', '{"op": "ping", "id": 2}']
    stdin, stdout = io.StringIO('\n'.join(lines) + '\n'), io.StringIO()
    built = []
    runner = threading.Thread(target=lambda: built.append(serve(
        lambda config, emit: built.append(Driver(config, emit)) or built[-1], 'test_child',
        stdin=stdin, stdout=stdout, state_period_s=60.0)), daemon=True)
    runner.start()
    runner.join(20.0)
    assert not runner.is_alive(), 'serve() never ended: a bad line ended its request loop'
    driver, code = built
    assert code == 0 and driver.handled == ['boom', 'boom', 'ping']
    assert driver.stopped_with == 'node gone (input closed)'
    events = [json.loads(line) for line in stdout.getvalue().splitlines()]
    errors = [e['message'] for e in events if e.get('level') == 'error']
    assert len(errors) == 4
    assert 'request refused (Expecting value' in errors[0] and "'not json" in errors[0]
    assert 'a JSON list, not an object' in errors[1]
    assert "request 'boom' failed: KeyError('currents_a')" in errors[2]
    replies = {e['id']: e for e in events if e['ev'] == 'reply'}
    assert replies[1]['ok'] is False and 'currents_a' in replies[1]['message']
    assert replies[2] == {'ev': 'reply', 'id': 2, 'ok': True, 'message': 'pong'}
    assert events[-1] == {'ev': 'stopped', 'safe': True}


class Popen:
    """What ChildClient._read needs of a child process: its stdout lines."""

    def __init__(self, lines):
        self.stdout = [line + '\n' for line in lines]


class Client(ChildClient):
    """A ChildClient on canned output, no process; on_event raises on 'odd' events."""

    def __init__(self):  # noqa: D107 (no child: only the reader is under test)
        self.log = logging.getLogger('test_child_client')
        self._cond = threading.Condition()
        self._replies, self._state, self._stopped, self._ready = {}, {}, None, False
        self._closing = True
        self.others = []

    def on_event(self, kind, event):
        if kind == 'odd':
            raise ValueError('odd event')
        self.others.append(kind)


def test_the_node_refuses_a_malformed_event_and_goes_on_reading(caplog):
    # One bad event (only a ValueError was caught) ended the reader: states stopped coming.
    client = Client()
    client.popen = Popen(['garbage', '[1]', '{"ev": "log"}', '{"ev": "reply"}',
                          '{"ev": "odd"}', '{"ev": "ready"}', '{"ev": "state", "n": 7}',
                          '{"ev": "reply", "id": 3, "ok": true}', '{"ev": "rejected"}'])
    with caplog.at_level(logging.ERROR, logger='test_child_client'):
        client._read(client.popen)
    assert client._ready and client.state == {'n': 7}
    assert client._replies == {3: {'id': 3, 'ok': True}} and client.others == ['rejected']
    refused = [r.getMessage() for r in caplog.records if 'event refused' in r.getMessage()]
    assert len(refused) == 5 and "ValueError('odd event')" in refused[-1]
