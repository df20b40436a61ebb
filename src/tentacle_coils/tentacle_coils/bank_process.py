"""
Run the coil bank in a process of its own, driven by the node over pipes.

Why a process: the supplies' worker threads wake every few milliseconds to keep the serial
lines busy, and the rclpy executor takes about half a millisecond of interpreter time per
message. In one process they queue for the same interpreter lock and the line idles (see
bench/coils_rate.py: SCPI at 115200 baud). In two they run on two cores. It also makes the
coils safe when the node dies: the bank sees its input close and ramps to zero, outputs off.
And when the bank dies, the node sees its output close: a spare bank process, started and
imported beforehand, takes over the ports at once and drives every supply to zero and off.

Protocol, JSON lines. The node writes to the bank's stdin::

    {"op": "config", "bank": {...build_bank arguments...}}   (first line)
    {"op": "command", "currents_a": [x, y, z]}
    {"op": "enable", "on": true, "id": 7}
    {"op": "estop", "active": true}
    {"op": "shutdown", "reason": "node exit"}

and reads from its stdout ``{"ev": "ready"}``, then ``state`` snapshots every
STATE_PERIOD_S, ``reply`` (to enable, by id), ``rejected`` (a command the bank refused),
``log`` records and, last, ``stopped`` with whether zero and off were read back (``safe``)
and, if not, what was not (``unsafe``). End of input is a shutdown. The bank ignores SIGINT
(a Ctrl-C reaches the whole process group: the node decides) and treats SIGTERM as a
shutdown; signals during the shutdown change nothing.
"""

import json
import logging
import math
import os
import signal
import subprocess
import sys
import threading
import time

from tentacle_coils.coil_bank import build_bank
from tentacle_coils.errors import CoilsError, CommandRejected, DriverError

STATE_PERIOD_S = 0.02
REPLY_TIMEOUT_S = 2.0
START_TIMEOUT_S = 20.0
RESTARTS_MAX = 3  # bank deaths within RESTART_WINDOW_S before the node stops replacing it
RESTART_WINDOW_S = 30.0
log = logging.getLogger('tentacle_coils')


# -- the bank's side -------------------------------------------------------------------------
class _Emitter:
    """Write events to stdout, one JSON line each, from any thread."""

    def __init__(self, stream):
        self.stream = stream
        self.lock = threading.Lock()

    def __call__(self, **event):
        line = json.dumps(event) + '\n'
        with self.lock:
            try:
                self.stream.write(line)
                self.stream.flush()
            except (OSError, ValueError):
                pass  # the node is gone; the shutdown path still runs


class _ForwardLogs(logging.Handler):
    def __init__(self, emit):
        super().__init__()
        self.emit_event = emit

    def emit(self, record):
        self.emit_event(ev='log', level=record.levelname.lower(), message=record.getMessage())


def _state(bank):
    level, message = bank.status()
    return {'ev': 'state', 'status': [level, message], 'enabled': bank.enabled,
            'estopped': bank.estopped, 'fault': bank.fault, 'connected': bank.connected(),
            'measured_a': bank.measured_currents().tolist(),
            'setpoints_a': bank.setpoints().tolist(), 'channels': bank.snapshots()}


def serve(stdin=sys.stdin, stdout=sys.stdout, terminate=None):
    """
    Run one bank until shutdown, end of input or ``terminate`` is set; return the exit code.

    Requests are read on a thread of their own and the caller's thread only waits, so a
    signal never interrupts the safe stop: it only sets ``terminate``.
    """
    emit = _Emitter(stdout)
    terminate = terminate or threading.Event()
    first = json.loads(stdin.readline() or '{}')
    if first.get('op') != 'config':
        emit(ev='stopped', safe=False, error='first line must be {"op": "config", ...}')
        return 2
    try:
        bank = build_bank(**first['bank'])
    except (DriverError, TypeError, KeyError) as exc:
        emit(ev='stopped', safe=False, error=f'bank config: {exc}')
        return 2
    logger = logging.getLogger('tentacle_coils')
    logger.addHandler(_ForwardLogs(emit))
    logger.setLevel(logging.INFO)
    bank.start()
    emit(ev='ready')
    done = threading.Event()
    reason = ['node gone (input closed)']

    def publish_state():
        while not done.wait(STATE_PERIOD_S):
            emit(**_state(bank))

    def read_requests():
        for line in stdin:
            request = json.loads(line)
            op = request.get('op')
            if op == 'command':
                try:
                    bank.command(request['currents_a'])
                except CommandRejected as exc:
                    emit(ev='rejected', reason=str(exc))
            elif op == 'enable':
                ok, message = bank.enable(bool(request['on']))
                emit(ev='reply', id=request.get('id'), ok=ok, message=message)
            elif op == 'estop':
                bank.set_estop(bool(request['active']))
            elif op == 'shutdown':
                reason[0] = request.get('reason', 'shutdown')
                break
        terminate.set()

    threading.Thread(target=publish_state, name='bank-state', daemon=True).start()
    threading.Thread(target=read_requests, name='bank-requests', daemon=True).start()
    terminate.wait()
    safe = bank.shutdown(reason[0])
    done.set()
    emit(ev='stopped', safe=safe, unsafe=bank.unsafe)
    return 0


def main():
    """Entry point of the bank process (started by BankClient, not by hand)."""
    terminate = threading.Event()
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, lambda *_: terminate.set())
    # Worker threads wake every few milliseconds; don't let them wait 5 ms for each other.
    sys.setswitchinterval(2e-4)
    sys.exit(serve(terminate=terminate))


# -- the node's side -------------------------------------------------------------------------
def _spawn():
    """Start a bank process; it imports everything, then waits for its config line."""
    # Find this very package in the child, whatever layout it was imported from.
    here = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        p for p in (here, os.environ.get('PYTHONPATH')) if p))
    return subprocess.Popen([sys.executable, '-m', 'tentacle_coils.bank_process'],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                            bufsize=1, env=env)


def _end(popen):
    """Close a bank process's input (it stops safely) and wait; kill it if it hangs."""
    try:
        popen.stdin.close()
    except OSError:
        pass
    try:
        popen.wait(5.0)
    except subprocess.TimeoutExpired:
        popen.kill()
        popen.wait()


_STARTING = {'status': ['error', 'starting'], 'enabled': False, 'estopped': False, 'fault': '',
             'connected': False, 'measured_a': [math.nan] * 3, 'setpoints_a': [0.0] * 3,
             'channels': []}


class BankClient:
    """
    The node's handle on a bank process; the same questions as a CoilBank answers.

    If the bank process dies, a spare one (started beforehand, so it is already imported)
    reopens the ports at once: a fresh bank ramps each supply from what it holds to zero and
    switches its output off, both read back. It is not enabled: commands are refused until
    ``enable(True)``. The estop state is carried over. After RESTARTS_MAX deaths within
    RESTART_WINDOW_S no more are started and the status says so.
    """

    def __init__(self, on_rejected=None, **bank_kwargs):
        """
        Start the bank process with build_bank(**bank_kwargs) and wait until it runs.

        :param on_rejected: called with the reason of a command the bank refused
        :raises CoilsError: the process did not start, or refused the configuration
        """
        self.on_rejected = on_rejected or (lambda reason: None)
        self._config = bank_kwargs
        self._write_lock = threading.Lock()
        self._cond = threading.Condition()
        self._replies = {}
        self._next_id = 0
        self._closing = False
        self._estop = False
        self.deaths = []  # (time.monotonic(), exit code) of each bank process that died
        self.death_note = ''  # said in the status until the outputs are enabled again
        self.unsafe = []  # after shutdown(): what could not be confirmed zero and off
        self._spare = _spawn()
        self._start_bank()
        with self._cond:
            self._cond.wait_for(lambda: self._ready or self._stopped is not None,
                                START_TIMEOUT_S)
            if not self._ready:
                error = (self._stopped or {}).get('error', 'did not start in time')
                self._close_all()
                raise CoilsError(f'coil bank process: {error}')

    def _start_bank(self):
        """Hand the config to the spare process, make it the bank, start the next spare."""
        with self._cond:
            self.popen, self._spare = self._spare, None
            self._state = dict(_STARTING)
            self._ready = False
            self._stopped = None
        threading.Thread(target=self._read, args=(self.popen,), name='bank-reader',
                         daemon=True).start()
        try:
            self._send(op='config', bank=self._config)
            if self._estop:
                self._send(op='estop', active=True)
        except CommandRejected:
            pass  # it died already: its reader sees that
        self._spare = _spawn()

    def _send(self, **request):
        line = json.dumps(request) + '\n'
        with self._write_lock:
            try:
                self.popen.stdin.write(line)
                self.popen.stdin.flush()
            except (OSError, ValueError):
                raise CommandRejected('coil bank process is not running') from None

    def _read(self, popen):
        for line in popen.stdout:
            try:
                event = json.loads(line)
            except ValueError:
                continue
            kind = event.pop('ev', None)
            if kind == 'state':
                with self._cond:
                    self._state = event
            elif kind == 'log':
                log.log(getattr(logging, event['level'].upper(), logging.INFO),
                        event['message'])
            elif kind == 'rejected':
                self.on_rejected(event['reason'])
            elif kind in ('reply', 'ready', 'stopped'):
                with self._cond:
                    if kind == 'reply':
                        self._replies[event['id']] = event
                    elif kind == 'ready':
                        self._ready = True
                    else:
                        self._stopped = event
                    self._cond.notify_all()
        with self._cond:
            if popen is not self.popen or self._stopped is not None:
                return
            self._stopped = {'safe': False, 'error': 'exited unexpectedly'}
            self._cond.notify_all()
            closing = self._closing
        if not closing:
            self._replace(popen)

    def _replace(self, dead):
        """Say that the bank process died, and let a fresh one drive everything to zero."""
        code = dead.wait()
        now = time.monotonic()
        self.deaths.append((now, code))
        recent = [t for t, _ in self.deaths if now - t < RESTART_WINDOW_S]
        if len(recent) > RESTARTS_MAX:
            self.death_note = (f'coil bank process died {len(recent)} times in '
                               f'{RESTART_WINDOW_S:g} s (last exit {code}): not restarted; '
                               'the supplies hold what they last had: restart coils_node')
            with self._cond:
                self._state = {**_STARTING, 'status': ['error', self.death_note]}
            log.error('coils: %s', self.death_note)
            return
        self.death_note = (f'coil bank process died (exit {code}); a fresh one drives every '
                           'supply to zero and off: call /coils/enable to resume')
        log.error('coils: coil bank process died (exit %s): a fresh one reopens the ports and '
                  'drives every supply to zero, outputs off; commands are refused until '
                  '/coils/enable', code)
        self._start_bank()

    # -- what the node asks -----------------------------------------------------------------
    @property
    def enabled(self):
        """Return True while outputs are meant to be on."""
        return self._state['enabled']

    @property
    def estopped(self):
        """Return True while an emergency stop is active."""
        return self._estop

    @property
    def fault(self):
        """Return the reason of the active fault, or ''."""
        return self._state['fault']

    def connected(self):
        """Return True when every supply is connected."""
        return self._state['connected'] and self._stopped is None

    def measured_currents(self):
        """Return the measured currents, x, y, z (A); NaN where unknown."""
        return list(self._state['measured_a'])

    def setpoints(self):
        """Return the setpoints the supplies hold, x, y, z (A)."""
        return list(self._state['setpoints_a'])

    def status(self):
        """Return (level, message) for the bank."""
        level, message = self._state['status']
        if self.death_note:
            return 'error', f'{self.death_note} (now: {message})'
        return level, message

    def snapshots(self):
        """Return one dict per supply (for diagnostics)."""
        return list(self._state['channels'])

    def command(self, currents_a):
        """
        Send target currents (A); a refusal by the bank comes back through on_rejected.

        :raises CommandRejected: what the latest state already says (estop, fault, disabled,
            bank gone or restarting), so the caller can log it at once
        """
        if self._stopped is not None or not self._ready:
            raise CommandRejected('coil bank process is not running')
        if self._estop:
            raise CommandRejected('estop active')
        self._send(op='command', currents_a=[float(c) for c in currents_a])

    def enable(self, on):
        """Energise or de-energise; return (success, message)."""
        with self._cond:
            self._next_id += 1
            request_id = self._next_id
        try:
            self._send(op='enable', on=bool(on), id=request_id)
        except CommandRejected as exc:
            return False, str(exc)
        with self._cond:
            if not self._cond.wait_for(lambda: request_id in self._replies, REPLY_TIMEOUT_S):
                return False, 'coil bank process did not answer'
            reply = self._replies.pop(request_id)
        if on and reply['ok']:
            self.death_note = ''
        return reply['ok'], reply['message']

    def set_estop(self, active):
        """Engage or release the emergency stop (carried over to a replacement bank)."""
        self._estop = bool(active)  # refuse commands from now, not from the next state
        self._send(op='estop', active=bool(active))

    def shutdown(self, reason='shutdown', timeout_s=30.0):
        """
        Ramp to zero, outputs off, end the processes; what was not confirmed is in ``unsafe``.

        :return: True when every supply read back zero current and output off
        """
        with self._cond:
            self._closing = True
        try:
            self._send(op='shutdown', reason=reason)
        except CommandRejected:
            pass
        with self._cond:
            self._cond.wait_for(lambda: self._stopped is not None, timeout_s)
            stopped = self._stopped or {'safe': False, 'error': 'no answer'}
        self._close_all()
        self.unsafe = stopped.get('unsafe') or ([] if stopped.get('safe') else [
            f'coil bank process: {stopped.get("error", "not confirmed")}'])
        return bool(stopped.get('safe'))

    def _close_all(self):
        with self._cond:
            self._closing = True
        for popen in (self.popen, self._spare):
            if popen is not None:
                _end(popen)


if __name__ == '__main__':
    main()
