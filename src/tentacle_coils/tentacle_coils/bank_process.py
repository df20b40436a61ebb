"""
Run the coil bank in a process of its own, driven by the node over pipes.

Why a process: the supplies' worker threads wake every few milliseconds to keep the serial
lines busy, and the rclpy executor takes about half a millisecond of interpreter time per
message. In one process they queue for the same interpreter lock and the line idles (see
bench/coils_rate.py: SCPI at 115200 baud). In two they run on two cores. It also makes the
coils safe when the node dies: the bank sees its input close and ramps to zero, outputs off.
And when the bank dies, the node sees its output close: a spare bank process, started and
imported beforehand, takes over the ports at once and drives every supply to zero and off.
The plumbing is tentacle_common.child_process's; this module says what the bank does.

Requests (after the config line, whose ``config`` is build_bank's arguments)::

    {"op": "command", "currents_a": [x, y, z]}
    {"op": "enable", "on": true, "id": 7}
    {"op": "estop", "active": true}

Events besides the common ones: ``rejected`` (a command the bank refused, with the reason);
``stopped`` says whether zero and off were read back (``safe``) and, if not, what was not
(``unsafe``).
"""

import math

from tentacle_coils.coil_bank import build_bank
from tentacle_coils.errors import CommandRejected
from tentacle_common.child_process import child_main, ChildClient

STATE_PERIOD_S = 0.02
RESTARTS_MAX = ChildClient.RESTARTS_MAX
LOGGER = 'tentacle_coils'


# -- the bank's side -------------------------------------------------------------------------
class _ServedBank:
    """A started CoilBank answering the node's requests (child_process.serve's driver)."""

    def __init__(self, config, emit):
        self.bank, self.emit = build_bank(**config), emit
        self.bank.start()

    def handle(self, request):
        op, bank = request.get('op'), self.bank
        if op == 'command':
            try:
                bank.command(request['currents_a'])
            except CommandRejected as exc:
                self.emit(ev='rejected', reason=str(exc))
        elif op == 'enable':
            ok, message = bank.enable(bool(request['on']))
            return {'ok': ok, 'message': message}
        elif op == 'estop':
            bank.set_estop(bool(request['active']))
        return None

    def state(self):
        bank = self.bank
        level, message = bank.status()
        return {'status': [level, message], 'enabled': bank.enabled,
                'estopped': bank.estopped, 'fault': bank.fault, 'connected': bank.connected(),
                'measured_a': bank.measured_currents().tolist(),
                'measured_at_s': bank.measured_at(),
                'setpoints_a': bank.setpoints().tolist(), 'channels': bank.snapshots()}

    def shutdown(self, reason):
        safe = self.bank.shutdown(reason)
        return {'safe': safe, 'unsafe': self.bank.unsafe}


def main():
    """Entry point of the bank process (started by BankClient, not by hand)."""
    child_main(_ServedBank, LOGGER, STATE_PERIOD_S)


# -- the node's side -------------------------------------------------------------------------
class BankClient(ChildClient):
    """
    The node's handle on a bank process; the same questions as a CoilBank answers.

    If the bank process dies, a spare one (started beforehand, so it is already imported)
    reopens the ports at once: a fresh bank ramps each supply from what it holds to zero and
    switches its output off, both read back. It is not enabled: commands are refused until
    ``enable(True)``. The estop state is carried over. After RESTARTS_MAX deaths within
    RESTART_WINDOW_S no more are started and the status says so.
    """

    MODULE = 'tentacle_coils.bank_process'
    WHAT = 'coil bank'
    GONE = CommandRejected
    STARTING = {'status': ['error', 'starting'], 'enabled': False, 'estopped': False,
                'fault': '', 'connected': False, 'measured_a': [math.nan] * 3,
                'measured_at_s': math.nan,
                'setpoints_a': [0.0] * 3, 'channels': []}

    def __init__(self, on_rejected=None, **bank_kwargs):
        """
        Start the bank process with build_bank(**bank_kwargs) and wait until it runs.

        :param on_rejected: called with the reason of a command the bank refused
        :raises ConfigError: the process did not start, or refused the configuration
        """
        self.on_rejected = on_rejected or (lambda reason: None)
        self._estop = False
        self.unsafe = []  # after shutdown(): what could not be confirmed zero and off
        super().__init__(bank_kwargs, LOGGER)

    def on_started(self):
        """Carry the estop over to a replacement bank."""
        if self._estop:
            self.send(op='estop', active=True)

    def on_event(self, kind, event):
        """Pass a refusal on."""
        if kind == 'rejected':
            self.on_rejected(event['reason'])

    def death_note_for(self, code, gave_up):
        """Return what the status says after the bank process died."""
        if gave_up:
            return (f'coil bank process died {len(self.deaths)} times in '
                    f'{self.RESTART_WINDOW_S:g} s (last exit {code}): not restarted; '
                    'the supplies hold what they last had: restart coils_node')
        return (f'coil bank process died (exit {code}); a fresh one drives every supply to '
                'zero and off: call /coils/enable to resume')

    # -- what the node asks -----------------------------------------------------------------
    @property
    def enabled(self):
        """Return True while outputs are meant to be on."""
        return self.state['enabled']

    @property
    def estopped(self):
        """Return True while an emergency stop is active."""
        return self._estop

    @property
    def fault(self):
        """Return the reason of the active fault, or ''."""
        return self.state['fault']

    def connected(self):
        """Return True when every supply is connected."""
        return self.state['connected'] and self._stopped is None

    def measured_currents(self):
        """Return the measured currents, x, y, z (A); NaN where unknown."""
        return list(self.state['measured_a'])

    def measured_at(self):
        """Return when the oldest of the measured currents was read (s, time.time()); NaN."""
        return self.state['measured_at_s']

    def setpoints(self):
        """Return the setpoints the supplies hold, x, y, z (A)."""
        return list(self.state['setpoints_a'])

    def status(self):
        """Return (level, message) for the bank."""
        level, message = self.state['status']
        if self.death_note:
            return 'error', f'{self.death_note} (now: {message})'
        return level, message

    def snapshots(self):
        """Return one dict per supply (for diagnostics)."""
        return list(self.state['channels'])

    def command(self, currents_a):
        """
        Send target currents (A); a refusal by the bank comes back through on_rejected.

        :raises CommandRejected: what the latest state already says (estop, fault, disabled,
            bank gone or restarting), so the caller can log it at once
        """
        if not self.running:
            raise CommandRejected('coil bank process is not running')
        if self._estop:
            raise CommandRejected('estop active')
        self.send(op='command', currents_a=[float(c) for c in currents_a])

    def enable(self, on):
        """Energise or de-energise; return (success, message)."""
        try:
            reply = self.ask(op='enable', on=bool(on))
        except CommandRejected as exc:
            return False, str(exc)
        if reply is None:
            return False, 'coil bank process did not answer'
        if on and reply['ok']:
            self.death_note = ''
        return reply['ok'], reply['message']

    def set_estop(self, active):
        """Engage or release the emergency stop (carried over to a replacement bank)."""
        self._estop = bool(active)  # refuse commands from now, not from the next state
        self.send(op='estop', active=bool(active))

    def shutdown(self, reason='shutdown', timeout_s=30.0):
        """
        Ramp to zero, outputs off, end the processes; what was not confirmed is in ``unsafe``.

        :return: True when every supply read back zero current and output off
        """
        stopped = super().shutdown(reason, timeout_s)
        self.unsafe = stopped.get('unsafe') or ([] if stopped.get('safe') else [
            f'coil bank process: {stopped.get("error", "not confirmed")}'])
        return bool(stopped.get('safe'))


if __name__ == '__main__':
    main()
