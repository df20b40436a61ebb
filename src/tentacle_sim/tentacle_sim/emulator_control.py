"""
The control loop of an emulator process: JSON lines on stdin, one reply each on stdout.

supply_emulator and stage_emulator run their devices (pty_device.PtyDevice models) and then
``serve_devices``: it prints ``{"ready": true, "ports": {name: path}}`` and answers

- ``{"op": "state"}`` -> every device's ``state()``, by name
- ``{"op": "fault", "port": <name>, "kind": ..., ...}`` -> ``inject(kind, ...)`` on one
- ``{"op": "log", "port": <name>, "since": t}`` -> its received requests since a time
- ``{"op": "quit"}``; end of stdin or SIGTERM also stop it and remove the ports.

A malformed line (not JSON, not an object, a bad option) is answered ``{"error": ...}`` and
the loop goes on: a test's typo must not take the emulated rig down with it. ``line_rate``
is the command-line check of a baud both emulator processes share.
"""

import argparse
import json
import signal
import sys


# Fault options that are numbers (counts, seconds, metres, amperes, a factor, a code), or
# null where that means 'any' (on_current_a).
NUMBERS = ('count', 'late_s', 'duration_s', 'factor', 'after_m', 'code', 'on_current_a')


def line_rate(text):
    """
    Return a baud (bit/s) from the command line: a positive integer.

    :raises argparse.ArgumentTypeError: anything else (argparse exits 2 with it)
    """
    try:
        baud = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'{text!r} is not a whole number of bit/s') from None
    if baud <= 0:
        raise argparse.ArgumentTypeError(f'{baud} bit/s: a line rate must be positive')
    return baud


def handle(request, devices):
    """Return the reply to one control request (a dict; anything else is an error reply)."""
    if not isinstance(request, dict):
        return {'error': f'a control request is a JSON object, got {type(request).__name__}'}
    op = request.get('op')
    if op == 'state':
        return {name: emu.state() for name, emu in devices.items()}
    if op in ('fault', 'log'):
        emu = devices.get(request.get('port'))
        if emu is None:
            return {'error': f"no port {request.get('port')!r}; have {sorted(devices)}"}
        if op == 'log':
            since = float(request.get('since', 0.0))
            return {'log': [e for e in list(emu.log) if e['t'] >= since]}
        options = {k: v for k, v in request.items() if k not in ('op', 'port', 'kind')}
        for name, value in options.items():
            # A device thread would meet a malformed number later, and die of it.
            if name in NUMBERS and value is not None and (
                    isinstance(value, bool) or not isinstance(value, (int, float))):
                return {'error': f'{name}: {value!r} is not a number'}
        emu.inject(request.get('kind'), **options)
        return {'ok': True}
    return {'error': f'unknown op {op!r}'}


def serve_devices(devices, stdin=sys.stdin):
    """Announce the devices' ports, answer control requests until told to stop, stop them."""
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    print(json.dumps({'ready': True, 'ports': {n: e.port for n, e in devices.items()}}),
          flush=True)
    try:
        for line in stdin:
            if not line.strip():
                continue
            try:
                request = json.loads(line)
                if isinstance(request, dict) and request.get('op') == 'quit':
                    break
                reply = handle(request, devices)
            except (ValueError, TypeError, KeyError, AttributeError) as exc:
                reply = {'error': f'{type(exc).__name__}: {exc}'}
            print(json.dumps(reply), flush=True)
    except KeyboardInterrupt:
        pass
    finally:
        for emu in devices.values():
            emu.stop()
