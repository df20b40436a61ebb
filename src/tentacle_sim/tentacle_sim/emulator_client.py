"""
Start an emulator process (supply_emulator, stage_emulator) and talk to it over JSON lines.

Used by the demo, the benchmarks, the lab scripts and the cross-process tests; see
emulator_control.py for the control requests.
"""

import json
import os
import signal
import subprocess
import sys
import threading


class _ControlledProcess:
    """An emulator process (emulator_control's requests) with stable port links."""

    def __init__(self, argv, cwd=None, what='emulator'):
        """
        Start the process and wait for its ports.

        :raises RuntimeError: the emulator did not come up
        """
        self.popen = subprocess.Popen(argv, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                      text=True, cwd=cwd, start_new_session=True)
        self._lock = threading.Lock()
        first = self.popen.stdout.readline()
        if not first:
            raise RuntimeError(f'{what} exited with {self.popen.wait()}')
        self.ports = json.loads(first)['ports']

    def ask(self, **request):
        """Send one control request; return the reply."""
        with self._lock:
            self.popen.stdin.write(json.dumps(request) + '\n')
            self.popen.stdin.flush()
            return json.loads(self.popen.stdout.readline())

    def state(self):
        """Return every device's state, by name."""
        return self.ask(op='state')

    def log(self, port, since=0.0):
        """Return the requests one device received after a time (time.monotonic() s)."""
        return self.ask(op='log', port=port, since=since)['log']

    def fault(self, port, kind, **options):
        """
        Arm a fault on one device.

        :raises RuntimeError: the emulator refused it
        """
        reply = self.ask(op='fault', port=port, kind=kind, **options)
        if reply != {'ok': True}:
            raise RuntimeError(f'fault {kind} on {port}: {reply}')

    def stop(self):
        """Quit and wait (kill the process group if it hangs)."""
        if self.popen.poll() is None:
            try:
                self.popen.stdin.write('{"op": "quit"}\n')
                self.popen.stdin.flush()
                self.popen.wait(5)
            except (OSError, subprocess.TimeoutExpired):
                os.killpg(self.popen.pid, signal.SIGKILL)
                self.popen.wait()


class EmulatorProcess(_ControlledProcess):
    """Three emulated supplies (supply_emulator) in their own process."""

    def __init__(self, link_dir, dialect='dxkdp', baud=9600, extra_args=(), cwd=None):
        """
        Start the process and wait for its ports.

        :param link_dir: directory for the port links coil_x, coil_y, coil_z
        :param extra_args: more supply_emulator options (e.g. ['--delay-s', '0'])
        :raises RuntimeError: the emulator did not come up
        """
        super().__init__([sys.executable, '-m', 'tentacle_sim.emulate_supplies', '--dialect',
                          dialect, '--baud', str(baud), '--link-dir', str(link_dir),
                          *extra_args], cwd, 'supply_emulator')

    def setpoints(self):
        """Return the setpoint of each axis (A), x, y, z."""
        state = self.state()
        return [state[n]['setpoint_a'] for n in 'xyz']

    def outputs(self):
        """Return the output states of x, y, z."""
        state = self.state()
        return [state[n]['output_on'] for n in 'xyz']

    def sets_since(self, t):
        """Return the currents (A) of the set requests each axis received after time t."""
        return {n: [e['current_a'] for e in self.log(n, t) if 'current_a' in e] for n in 'xyz'}


class StageEmulatorProcess(_ControlledProcess):
    """Emulated linear stages (stage_emulator) in their own process, a port per axis."""

    def __init__(self, link_dir, axes=('inserter',), dialects=('gcode',), extra_args=(),
                 cwd=None):
        """
        Start the process and wait for its ports (link_dir/<axis>).

        :param extra_args: more stage_emulator options (e.g. ['--reset-after-halt-s', '1'])
        :raises RuntimeError: the emulator did not come up
        """
        super().__init__([sys.executable, '-m', 'tentacle_sim.emulate_stages', '--link-dir',
                          str(link_dir), '--axes', *axes, '--dialects', *dialects,
                          *extra_args], cwd, 'stage_emulator')

    def axis(self, name):
        """Return one axis's true state (position_m, velocity_m_s, moving, busy, ...)."""
        return self.state()[name]
