"""
Bring up the emulated coil rig: supply emulators plus a coils_node process.

For the demo, the benchmarks and the cross-process tests: the node runs as deployed (its own
process, a params file), the supplies are emulators on pseudo-terminals.
"""

import os
import pathlib
import signal
import subprocess
import sys

from tentacle_sim.emulator_client import EmulatorProcess
import yaml


def write_coils_params(base_yaml, out_path, **overrides):
    """Write a coils_node params file: base_yaml with some parameters replaced."""
    document = yaml.safe_load(pathlib.Path(base_yaml).read_text())
    document['coils_node']['ros__parameters'].update(overrides)
    pathlib.Path(out_path).write_text(yaml.safe_dump(document))
    return out_path


class NodeProcess:
    """A node in its own process, its output collected in a file."""

    def __init__(self, argv, log_path, cwd=None, env=None):
        """Start argv (in a session of its own); stdout and stderr go to log_path."""
        self.log_path = log_path
        self._log = open(log_path, 'w')
        self.popen = subprocess.Popen(argv, stdout=self._log, stderr=subprocess.STDOUT,
                                      cwd=cwd, env=env, start_new_session=True)

    def output(self):
        """Return everything the process printed so far."""
        return pathlib.Path(self.log_path).read_text()

    def stop(self, sig=signal.SIGINT, timeout_s=10.0):
        """Signal the process and wait; kill it if it hangs. Return its exit code."""
        if self.popen.poll() is None:
            self.popen.send_signal(sig)
            try:
                self.popen.wait(timeout_s)
            except subprocess.TimeoutExpired:
                os.killpg(self.popen.pid, signal.SIGKILL)
                self.popen.wait()
        self._log.close()
        return self.popen.returncode


class CoilRig:
    """Three emulated supplies and coils_node wired to them; stop() in reverse order."""

    def __init__(self, workdir, base_params, dialect='dxkdp', baud=9600, emulator_args=(),
                 cwd=None, **params):
        """
        Start the emulators, write the node's params, start the node.

        :param workdir: directory for port links, params file and logs
        :param base_params: the coils params file to start from (config/coils.yaml)
        :param params: coils_node parameters to override
        """
        workdir = pathlib.Path(workdir)
        self.emulators = EmulatorProcess(workdir / 'ports', dialect, baud, emulator_args, cwd)
        try:
            overrides = {'dialect': dialect, 'baud': baud,
                         'ports': [self.emulators.ports[n] for n in 'xyz'], **params}
            params_file = write_coils_params(base_params, workdir / 'coils_params.yaml',
                                             **overrides)
            self.node = NodeProcess([sys.executable, '-m', 'tentacle_coils.coils_node',
                                     '--ros-args', '--params-file', str(params_file)],
                                    str(workdir / 'coils_node.log'), cwd)
        except BaseException:
            self.emulators.stop()
            raise

    def stop(self, sig=signal.SIGINT):
        """Stop the node first (it zeroes the supplies), then the emulators."""
        code = self.node.stop(sig)
        self.emulators.stop()
        return code
