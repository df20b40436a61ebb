"""
Start the supply_emulator process and talk to it over its stdin/stdout JSON lines.

Used by the demo, the benchmarks and the cross-process tests; see emulate_supplies.py for
the control requests.
"""

import json
import os
import signal
import subprocess
import sys
import threading


class EmulatorProcess:
    """Three emulated supplies in their own process, with stable port links."""

    def __init__(self, link_dir, dialect='dxkdp', baud=9600, extra_args=(), cwd=None):
        """
        Start the process and wait for its ports.

        :param link_dir: directory for the port links coil_x, coil_y, coil_z
        :param extra_args: more supply_emulator options (e.g. ['--delay-s', '0'])
        :raises RuntimeError: the emulator did not come up
        """
        argv = [sys.executable, '-m', 'tentacle_sim.emulate_supplies', '--dialect', dialect,
                '--baud', str(baud), '--link-dir', str(link_dir), *extra_args]
        self.popen = subprocess.Popen(argv, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                      text=True, cwd=cwd, start_new_session=True)
        self._lock = threading.Lock()
        first = self.popen.stdout.readline()
        if not first:
            raise RuntimeError(f'supply_emulator exited with {self.popen.wait()}')
        self.ports = json.loads(first)['ports']

    def ask(self, **request):
        """Send one control request; return the reply."""
        with self._lock:
            self.popen.stdin.write(json.dumps(request) + '\n')
            self.popen.stdin.flush()
            return json.loads(self.popen.stdout.readline())

    def state(self):
        """Return every supply's state, by axis name."""
        return self.ask(op='state')

    def setpoints(self):
        """Return the setpoint of each axis (A), x, y, z."""
        state = self.state()
        return [state[n]['setpoint_a'] for n in 'xyz']

    def outputs(self):
        """Return the output states of x, y, z."""
        state = self.state()
        return [state[n]['output_on'] for n in 'xyz']

    def log(self, port, since=0.0):
        """Return the requests one supply received after a time (time.monotonic() s)."""
        return self.ask(op='log', port=port, since=since)['log']

    def sets_since(self, t):
        """Return the currents (A) of the set requests each axis received after time t."""
        return {n: [e['current_a'] for e in self.log(n, t) if 'current_a' in e] for n in 'xyz'}

    def fault(self, port, kind, **options):
        """
        Arm a fault on one supply.

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
