"""
Run one axis (stage driver and AxisWorker) in a process of its own, driven by the node.

Why a process: so that the axis stops whatever happens to the node. When the node dies, even
by SIGKILL, the axis process sees its input close and stops the axis (M112, M999, position
read back; a step1mm axis gets its stop character). When the axis process dies, the node sees
its output close: a spare, started and imported beforehand, reopens the port at once, and a
connect halts whatever the firmware still runs (stage.GcodeStage.connect). The plumbing is
tentacle_common.child_process's; this module says what the axis does.

Requests (after the config line, whose ``config`` is the node's parameters)::

    {"op": "target", "target_m": 0.01}
    {"op": "stop"}
    {"op": "estop", "active": true}
    {"op": "enable", "on": false}
    {"op": "home", "id": 7}            (answered by a reply when done)

Events besides the common ones: ``refused`` (a target the worker refused, with the reason);
``state`` is AxisWorker.snapshot() with ``status`` ([level, message]).
"""

import threading

from tentacle_common.child_process import child_main, ChildClient
from tentacle_common.errors import ConfigError
from tentacle_common.serial_line import SerialLine
from tentacle_inserter import stage, step1mm
from tentacle_inserter.axis_worker import AxisWorker, HOME_TIMEOUT_S
from tentacle_inserter.stage import check_target, TargetRefused

STATE_PERIOD_S = 0.01
LOGGER = 'tentacle_inserter'


def make_stage(p):
    """Return the axis driver the parameters describe (not connected)."""
    line = SerialLine(p['port'], p['baud'])
    if p['dialect'] == 'gcode':
        return stage.GcodeStage(line, max_length_m=p['max_length'], max_speed_m_s=p['max_speed'],
                                accel_m_s2=p['acceleration'], steps_per_mm=p['steps_per_mm'],
                                reply_timeout_s=p['reply_timeout_s'], retries=p['retries'],
                                time_margin=p['time_margin'], slack_s=p['slack_s'],
                                restart_timeout_s=p['restart_timeout_s'])
    if p['dialect'] == 'step1mm':
        mapping = step1mm.Mapping(p['step1mm_extend'], p['step1mm_retract'], p['step1mm_stop'])
        return stage.Step1mmStage(line, max_length_m=p['max_length'], mapping=mapping,
                                  speed_m_s=p['max_speed'], accel_m_s2=p['acceleration'])
    raise ConfigError(f"dialect {p['dialect']!r} is not gcode or step1mm")


# -- the axis's side -------------------------------------------------------------------------
class _ServedAxis:
    """A started AxisWorker answering the node's requests (child_process.serve's driver)."""

    def __init__(self, config, emit):
        self.worker, self.emit = AxisWorker(make_stage(config)).start(), emit

    def handle(self, request):
        op, worker = request.get('op'), self.worker
        if op == 'target':
            try:
                worker.set_target(request['target_m'])
            except TargetRefused as exc:
                self.emit(ev='refused', reason=str(exc))
        elif op == 'stop':
            worker.stop()
        elif op == 'estop':
            worker.set_estop(request['active'])
        elif op == 'enable':
            worker.set_enabled(request['on'])
        elif op == 'home':  # answered from a thread of its own: a stop must not wait for it
            def home():
                ok, message = worker.home()
                self.emit(ev='reply', id=request.get('id'), ok=ok, message=message)
            threading.Thread(target=home, name='axis-home', daemon=True).start()
        return None

    def state(self):
        return {**self.worker.snapshot(), 'status': list(self.worker.status())}

    def shutdown(self, reason):
        stopped = self.worker.shutdown()
        return {'safe': stopped, 'error': self.worker.error}


def main():
    """Entry point of the axis process (started by AxisClient, not by hand)."""
    child_main(_ServedAxis, LOGGER, STATE_PERIOD_S)


# -- the node's side -------------------------------------------------------------------------
class AxisClient(ChildClient):
    """
    The node's handle on an axis process; the same calls as an AxisWorker.

    Targets are checked here too (TargetRefused at once, nothing sent), and the estop and
    the enable state are kept here and carried over to a replacement process, which comes
    up with the axis stopped and unhomed. ``on_refused`` gets the reason of a target the
    axis process refused itself.
    """

    MODULE = 'tentacle_inserter.axis_process'
    GONE = TargetRefused
    STARTING = {'position_m': None, 'velocity_m_s': 0.0, 'estimated': True, 'moving': False,
                'homed': False, 'connected': False, 'measured': False, 'estop': False,
                'enabled': True, 'error': '', 'moves': 0, 'refusals': 0,
                'status': ['error', 'starting']}

    def __init__(self, params, on_refused=None):
        """
        Start the axis process for the node's parameters and wait until it runs.

        :raises ConfigError: the process did not start, or refused the parameters
        """
        self.WHAT = f"{params['axis']} axis"
        self.max_length_m = float(params['max_length'])
        self.on_refused = on_refused or (lambda reason: None)
        self._estop, self._enabled = False, True
        self.refusals = 0
        self.stopped = False  # the stop at shutdown was confirmed by the stage
        super().__init__(dict(params), LOGGER)

    def on_started(self):
        """Carry the estop and a disable over to a replacement process."""
        if self._estop:
            self.send(op='estop', active=True)
        if not self._enabled:
            self.send(op='enable', on=False)

    def on_event(self, kind, event):
        """Count and pass on a refusal by the axis process."""
        if kind == 'refused':
            self.refusals += 1
            self.on_refused(event['reason'])

    def death_note_for(self, code, gave_up):
        """Return what the status says after the axis process died."""
        if gave_up:
            return (f'{self.WHAT} process died {len(self.deaths)} times in '
                    f'{self.RESTART_WINDOW_S:g} s (last exit {code}): not restarted; the '
                    'axis was left halted where it stood: restart inserter_node')
        return (f'{self.WHAT} process died (exit {code}); a fresh one halted the axis: home '
                'it to move again')

    # -- what the node asks -----------------------------------------------------------------
    def set_target(self, target_m):
        """
        Hand a target (m) to the axis; it replaces any not yet started.

        :raises TargetRefused: not finite, out of range, estop, disabled, process not running
        """
        try:
            target = check_target(target_m, self.max_length_m)
            if self._estop:
                raise TargetRefused('estop active: no motion until it is released')
            if not self._enabled:
                raise TargetRefused('axis disabled: enable it first')
            if not self.running:
                raise TargetRefused(f'{self.WHAT} process is not running')
            self.send(op='target', target_m=target)
        except TargetRefused:
            self.refusals += 1
            raise

    def _tell(self, **request):
        """Send a request that a process being replaced needs not get: it starts halted."""
        try:
            self.send(**request)
        except TargetRefused:
            pass  # on_started carries the estop and a disable over to the replacement

    def stop(self):
        """Stop now."""
        self._tell(op='stop')

    def set_estop(self, active):
        """Engage or release the estop (carried over to a replacement process)."""
        self._estop = bool(active)
        self._tell(op='estop', active=self._estop)

    def set_enabled(self, on):
        """Enable, or disable: stop, motor off, targets refused (carried over)."""
        self._enabled = bool(on)
        self._tell(op='enable', on=self._enabled)

    def home(self, timeout_s=HOME_TIMEOUT_S):
        """Make where the axis stands its zero; return (success, message)."""
        if self._estop:
            return False, 'estop active'
        try:
            reply = self.ask(timeout_s + 1.0, op='home')
        except TargetRefused as exc:
            return False, str(exc)
        if reply is None:
            return False, f'{self.WHAT} process did not answer'
        if reply['ok']:
            self.death_note = ''
        return reply['ok'], reply['message']

    def snapshot(self):
        """Return the latest state of the axis process, with the keys of AxisWorker's."""
        snap = {k: v for k, v in self.state.items() if k != 'status'}
        return {**snap, 'estop': self._estop, 'enabled': self._enabled,
                'refusals': self.refusals, 'pid': self.popen.pid, 'deaths': len(self.deaths)}

    def status(self):
        """Return (level, message) for /diagnostics."""
        level, message = self.state['status']
        if self.death_note:
            return 'error', f'{self.death_note} (now: {message})'
        return level, message

    def shutdown(self, reason='node exit', timeout_s=10.0):
        """Stop the axis and end the processes; return whether the stop was confirmed."""
        stopped = super().shutdown(reason, timeout_s)
        self.stopped = bool(stopped.get('safe'))
        return self.stopped


if __name__ == '__main__':
    main()
