"""
The simulated rig's devices: emulated supplies and stages, linked where drivers look for them.

``SimDevices(device_dir, ...)`` starts three supplies and the inserter stage (and a backbone
stage for scenes with a backbone) on pseudo-terminals and links them into ``device_dir`` under
DESIGN.md's names: ``coil_x``, ``coil_y``, ``coil_z`` (``dxkdp`` at 9600 baud, bus address 1;
or ``scpi`` at 115200), ``inserter`` and ``backbone`` (``gcode`` at 115200). The drivers open
the links as they would open /dev/ttyUSB*. The world reads the truth from the same objects:
each coil's current now (``currents_a``), each stage's physical position (``travel_m``).

Faults come from outside through ``control``, the emulators' JSON requests by device name
(emulator_control.handle: ``{"op": "fault", "port": "coil_y", "kind": "disconnect",
"duration_s": 5}``), which ``ControlSocket`` serves on ``device_dir/control``, one JSON line
in and one out per request. A lock file keeps a second simulator out of the same folder.
"""

import fcntl
import json
import os
import pathlib
import socket
import threading

import numpy as np
from tentacle_sim.coil_load import CoilLoad
from tentacle_sim.emulator_control import handle
from tentacle_sim.stage_emulator import GcodeStage
from tentacle_sim.supply_emulator import make_supply

COIL_BAUD = {'dxkdp': 9600, 'scpi': 115200}
STAGE_BAUD = 115200
CONTROL = 'control'
LOCK = '.lock'


class DeviceDirBusy(RuntimeError):
    """Another simulator holds the device folder."""


class SimDevices:
    """The emulated devices of one simulated rig, started, their links in one folder."""

    def __init__(self, device_dir, coil_dialect='dxkdp', backbone=False, *,
                 resistance_ohm=1.0, inductance_h=0.01, compliance_v=60.0,
                 max_current_a=50.0):
        """
        Start the devices and link them.

        :param device_dir: the folder for the links (created)
        :param coil_dialect: 'dxkdp' or 'scpi'
        :param backbone: start a backbone stage too
        :param resistance_ohm, inductance_h, compliance_v: each coil's R-L load and its
            supply's compliance (coil_load.CoilLoad)
        :raises DeviceDirBusy: another simulator runs on the folder
        :raises ValueError: another dialect
        """
        if coil_dialect not in COIL_BAUD:
            raise ValueError(f"coil_dialect '{coil_dialect}' is not dxkdp or scpi")
        self.dir = pathlib.Path(device_dir)
        self.dir.mkdir(parents=True, exist_ok=True)
        self._lock = open(self.dir / LOCK, 'w')
        try:
            fcntl.flock(self._lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            self._lock.close()
            raise DeviceDirBusy(f'{self.dir} is in use by another simulator (its {LOCK} is '
                                'locked): give another device_dir') from None
        self.dialect = coil_dialect
        self.supplies = {axis: make_supply(
            axis, coil_dialect, baud=COIL_BAUD[coil_dialect], address=1,
            link_path=str(self.dir / f'coil_{axis}'), max_current_a=max_current_a,
            load=CoilLoad(resistance_ohm, inductance_h, compliance_v)) for axis in 'xyz'}
        self.stages = {name: GcodeStage(name, baud=STAGE_BAUD, link_path=str(self.dir / name))
                       for name in (('inserter', 'backbone') if backbone else ('inserter',))}
        self.devices = {**{f'coil_{a}': s for a, s in self.supplies.items()}, **self.stages}
        started = []
        try:
            for device in self.devices.values():
                started.append(device.start())
        except BaseException:
            for device in started:
                device.stop()
            self._release()
            raise

    def currents_a(self):
        """Return the current in each coil now (3,), A: what the supplies really output."""
        return np.array([s.load.current_a() for s in self.supplies.values()])

    def travel_m(self, stage):
        """Return a stage's physical position now, m ('inserter' or 'backbone')."""
        return self.stages[stage].travel_m()

    def control(self, request):
        """Answer one control request (emulator_control.handle), devices by link name."""
        return handle(request, self.devices)

    def stop(self):
        """Stop every device and remove its link."""
        for device in self.devices.values():
            device.stop()
        self._release()

    def _release(self):
        fcntl.flock(self._lock, fcntl.LOCK_UN)
        self._lock.close()


class ControlSocket:
    """A Unix socket answering JSON-line requests with a handler, each connection in turn."""

    def __init__(self, path, handler):
        """Listen at path (replacing a stale socket) and serve in a thread."""
        self.path = str(path)
        if os.path.lexists(self.path):
            os.unlink(self.path)
        self._server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self._server.bind(self.path)
        self._server.listen(4)
        self._server.settimeout(0.2)
        self._handler = handler
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, name='sim-control', daemon=True)
        self._thread.start()

    def _serve(self):
        while not self._stop.is_set():
            try:
                connection, _ = self._server.accept()
            except socket.timeout:
                continue
            except OSError:
                return
            connection.settimeout(5.0)
            with connection, connection.makefile('rw', encoding='utf-8') as stream:
                try:
                    for line in stream:
                        if line.strip():
                            stream.write(json.dumps(self._answer(line)) + '\n')
                            stream.flush()
                except (OSError, ValueError):
                    pass  # the client went away or stalled: serve the next one

    def _answer(self, line):
        try:
            return self._handler(json.loads(line))
        except (ValueError, TypeError, KeyError, AttributeError) as exc:
            return {'error': f'{type(exc).__name__}: {exc}'}

    def close(self):
        """Stop serving and remove the socket."""
        self._stop.set()
        self._server.close()
        self._thread.join(timeout=2.0)
        if os.path.lexists(self.path):
            os.unlink(self.path)


def ask(device_dir, request, timeout_s=5.0):
    """Send one control request to a running simulator; return its reply (a dict)."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as client:
        client.settimeout(timeout_s)
        client.connect(str(pathlib.Path(device_dir) / CONTROL))
        client.sendall((json.dumps(request) + '\n').encode())
        with client.makefile('r', encoding='utf-8') as stream:
            line = stream.readline()
    if not line:
        raise ConnectionError(f'{device_dir}/{CONTROL}: no reply')
    return json.loads(line)
