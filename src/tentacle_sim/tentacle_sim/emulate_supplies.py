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
import os
import sys

from tentacle_sim.coil_load import CoilLoad
from tentacle_sim.emulator_control import line_rate, serve_devices
from tentacle_sim.supply_emulator import make_supply


def build_parser():
    """Return the command-line parser."""
    parser = argparse.ArgumentParser(prog='supply_emulator',
                                     description=__doc__.strip().split('\n')[0])
    parser.add_argument('--dialect', choices=('dxkdp', 'scpi'), default='dxkdp')
    parser.add_argument('--baud', type=line_rate, default=9600, help='line rate, bit/s')
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
        supplies[name] = make_supply(
            name, opts.dialect, baud=opts.baud, address=address,
            link_path=os.path.join(opts.link_dir, f'coil_{name}'),
            polarity_mode=opts.polarity_mode, delay_s=opts.delay_s,
            max_current_a=opts.max_current_a, log_path=log_path,
            load=CoilLoad(opts.resistance_ohm, opts.inductance_h, opts.compliance_v)).start()
    serve_devices(supplies)


if __name__ == '__main__':
    main()
