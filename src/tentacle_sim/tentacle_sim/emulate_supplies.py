"""
Run emulated coil supplies on pseudo-terminals, controlled by JSON lines on stdin.

Start::

    supply_emulator --dialect dxkdp --baud 9600 --link-dir /tmp/rig

prints one JSON line ``{"ready": true, "ports": {"x": "/tmp/rig/coil_x", ...}}`` and then
answers each JSON line on stdin with one on stdout:

- ``{"op": "state"}`` -> every supply's state (setpoint, measured current, output, ...)
- ``{"op": "fault", "port": "y", "kind": "no_reply", "count": 3}`` (kinds: no_reply, nak,
  garble, late [late_s], error [code, text], disconnect [duration_s])
- ``{"op": "log", "port": "x", "since": 0}`` -> the received requests since a time
- ``{"op": "quit"}``; end of stdin or SIGTERM also stop it and remove the ports.
"""

import argparse
import json
import os
import signal
import sys

from tentacle_sim.coil_load import CoilLoad
from tentacle_sim.supply_emulator import EmulatedSupply


def build_parser():
    """Return the command-line parser."""
    parser = argparse.ArgumentParser(prog='supply_emulator',
                                     description=__doc__.strip().split('\n')[0])
    parser.add_argument('--dialect', choices=('dxkdp', 'scpi'), default='dxkdp')
    parser.add_argument('--baud', type=int, default=9600, help='line rate, bit/s')
    parser.add_argument('--names', nargs='+', default=['x', 'y', 'z'])
    parser.add_argument('--addresses', nargs='+', type=int, default=None,
                        help='dxkdp bus address per supply (default 1 each)')
    parser.add_argument('--polarity-mode', choices=('signed', 'command'), default='signed')
    parser.add_argument('--link-dir', required=True, help='directory for stable port links')
    parser.add_argument('--log-dir', default=None, help='write <name>.jsonl request logs here')
    parser.add_argument('--delay-s', type=float, default=0.0005,
                        help='processing time per command, s')
    parser.add_argument('--max-current-a', type=float, default=50.0)
    parser.add_argument('--resistance-ohm', type=float, default=1.0)
    parser.add_argument('--inductance-h', type=float, default=0.01)
    parser.add_argument('--compliance-v', type=float, default=60.0)
    return parser


def handle(request, supplies):
    """Return the reply to one control request."""
    op = request.get('op')
    if op == 'state':
        return {name: emu.state() for name, emu in supplies.items()}
    if op in ('fault', 'log'):
        emu = supplies.get(request.get('port'))
        if emu is None:
            return {'error': f"no port {request.get('port')!r}; have {sorted(supplies)}"}
        if op == 'log':
            since = float(request.get('since', 0.0))
            return {'log': [e for e in list(emu.log) if e['t'] >= since]}
        options = {k: v for k, v in request.items() if k not in ('op', 'port', 'kind')}
        emu.inject(request.get('kind'), **options)
        return {'ok': True}
    return {'error': f'unknown op {op!r}'}


def main(args=None):
    """Start the supplies and serve control requests until told to stop."""
    opts = build_parser().parse_args(args)
    # Device threads wake for every request; a short GIL switch interval keeps their
    # timing (the modelled line) from waiting on each other.
    sys.setswitchinterval(2e-4)
    os.makedirs(opts.link_dir, exist_ok=True)
    addresses = opts.addresses or [1] * len(opts.names)
    supplies = {}
    for name, address in zip(opts.names, addresses):
        log_path = os.path.join(opts.log_dir, f'{name}.jsonl') if opts.log_dir else None
        supplies[name] = EmulatedSupply(
            name, opts.dialect, baud=opts.baud, address=address,
            link_path=os.path.join(opts.link_dir, f'coil_{name}'),
            polarity_mode=opts.polarity_mode, delay_s=opts.delay_s,
            max_current_a=opts.max_current_a, log_path=log_path,
            load=CoilLoad(opts.resistance_ohm, opts.inductance_h, opts.compliance_v)).start()
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    print(json.dumps({'ready': True, 'ports': {n: e.port for n, e in supplies.items()}}),
          flush=True)
    try:
        for line in sys.stdin:
            if not line.strip():
                continue
            try:
                request = json.loads(line)
                if request.get('op') == 'quit':
                    break
                reply = handle(request, supplies)
            except (ValueError, TypeError) as exc:
                reply = {'error': str(exc)}
            print(json.dumps(reply), flush=True)
    except KeyboardInterrupt:
        pass
    finally:
        for emu in supplies.values():
            emu.stop()


if __name__ == '__main__':
    main()
