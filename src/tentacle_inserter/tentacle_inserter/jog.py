"""
Jog one linear axis from the terminal: by +/- mm or to a position, home, position shown live.

    scripts/jog --port /dev/ttyACM0 home +5 -2.5 =10     (one after the other, then exit)
    scripts/jog --params config/inserter.yaml            (interactive: +1, -0.5, =10, h, s, q)

It talks to the stage itself, over its serial line, with inserter_node's driver and worker
(stage.py, axis_worker.py) and parameters (a params file's inserter_node section, then the
options), so inserter_node must not hold the port meanwhile. Positions are mm on the command
line and metres inside. A gcode axis starts unhomed: ``home`` makes where it stands zero.
Ctrl-C stops the axis, and the script says whether the stage confirmed it (read back)
before it exits; a second Ctrl-C does not cut that short.
"""

import argparse
import signal
import sys
import time

from tentacle_common.errors import ConfigError
from tentacle_common.params import resolve
from tentacle_inserter.axis_process import make_stage
from tentacle_inserter.axis_worker import AxisWorker
from tentacle_inserter.params import INSERTER_PARAMS, NODE_NAME
from tentacle_inserter.stage import TargetRefused

CONNECT_TIMEOUT_S = 5.0
SHOW_PERIOD_S = 0.1
HELP = 'actions: +N / -N (mm, relative), =N (mm, absolute), h(ome), s(top), p(osition), q(uit)'


def parse_action(text):
    """
    Return (kind, value) for one action: ('by' | 'to', metres) or (name, None).

    :raises ValueError: not an action, or a number that is not finite; the text named
    """
    word = text.strip().lower()
    names = {'h': 'home', 'home': 'home', 's': 'stop', 'stop': 'stop', 'p': 'position',
             'position': 'position', 'q': 'quit', 'quit': 'quit'}
    if word in names:
        return names[word], None
    kind, number = ('by', word) if word[:1] in '+-' else ('to', word.lstrip('='))
    try:
        mm = float(number)
    except ValueError:
        raise ValueError(f'{text!r} is not an action ({HELP})') from None
    if mm != mm or mm in (float('inf'), float('-inf')):
        raise ValueError(f'{text!r}: not a finite number of mm')
    return kind, mm * 1e-3


def describe(snap):
    """Return one line about the axis: position (mm), measured or not, state."""
    if snap['position_m'] is None:
        where = 'position unknown'
    else:
        how = 'estimated' if snap['estimated'] else 'read back'
        where = f"{snap['position_m'] * 1e3:9.3f} mm ({how})"
    flags = [flag for flag, on in (('moving', snap['moving']),
                                   ('not homed', not snap['homed']),
                                   ('NOT CONNECTED', not snap['connected'])) if on]
    return where + (f"  [{', '.join(flags)}]" if flags else '') + (
        f"  {snap['error']}" if snap['error'] else '')


class Jog:
    """Actions on one AxisWorker, with the position shown while it moves."""

    def __init__(self, worker, out=sys.stdout):
        """Drive ``worker`` (started); write to ``out``."""
        self.worker, self.out = worker, out
        self.failures = 0  # actions that were refused or failed

    def show(self, end='\n'):
        """Write the axis line (a carriage return for ``end`` redraws it in place)."""
        self.out.write(f'\r{describe(self.worker.snapshot())}\033[K{end}')
        self.out.flush()

    def do(self, text):
        """Carry out one action; return False for quit. Failures are written and counted."""
        try:
            kind, value = parse_action(text)
            if kind == 'quit':
                return False
            if kind == 'home':
                ok, message = self.worker.home()
                if not ok:
                    raise ValueError(f'home failed: {message}')
            elif kind == 'stop':
                self.worker.stop()
                self.wait()
            elif kind in ('by', 'to'):
                self.move(value if kind == 'to' else self._here() + value)
        except (ValueError, TargetRefused) as exc:
            self.failures += 1
            self.out.write(f'jog: {exc}\n')
        self.show()
        return True

    def _here(self):
        position = self.worker.snapshot()['position_m']
        if position is None:
            raise ValueError('the position is unknown: no relative move')
        return position

    def move(self, target_m):
        """
        Move to target_m (m) and wait, showing the position.

        :raises TargetRefused: refused before the wire (range, not homed, ...)
        :raises ValueError: the move failed or was stopped (the worker's error)
        """
        moves = self.worker.moves
        self.worker.set_target(target_m)
        self.wait()
        if self.worker.moves == moves:
            raise ValueError(f'move to {target_m * 1e3:.3f} mm: {self.worker.error}')

    def wait(self):
        """Wait until the worker is idle, redrawing the axis line."""
        while not self.worker.idle():
            self.show(end='\r')
            time.sleep(SHOW_PERIOD_S)

    def interact(self, stdin=sys.stdin):
        """Read actions line by line until quit or end of input."""
        self.out.write(HELP + '\n')
        self.show()
        while True:
            self.out.write('jog> ')
            self.out.flush()
            line = stdin.readline()
            if not line or not self.do(line):
                return
            if not line.strip():
                self.show()


def build_parser():
    """Return the command-line parser: the actions and inserter_node's parameters."""
    parser = argparse.ArgumentParser(prog='jog', description=__doc__.strip().split('\n')[0],
                                     epilog=HELP)
    parser.add_argument('actions', nargs='*', help='carried out in turn (none: interactive)')
    parser.add_argument('--params', help='a ROS params file (its inserter_node section)')
    for p in INSERTER_PARAMS:
        if p.name not in ('axis', 'state_rate'):
            parser.add_argument('--' + p.name.replace('_', '-'), dest=p.name,
                                type=type(p.default), help=p.description)
    return parser


def main(args=None):
    """Run the actions (or interactively); stop the axis on exit, however it comes."""
    opts = build_parser().parse_args(args)
    overrides = {p.name: getattr(opts, p.name) for p in INSERTER_PARAMS
                 if getattr(opts, p.name, None) is not None}
    try:
        params = resolve(INSERTER_PARAMS, NODE_NAME, opts.params, overrides)
        worker = AxisWorker(make_stage(params)).start()
    except ConfigError as exc:
        sys.exit(f'jog: {exc}')
    jog = Jog(worker)
    try:
        deadline = time.monotonic() + CONNECT_TIMEOUT_S
        while not worker.connected and time.monotonic() < deadline:
            time.sleep(0.02)
        if not worker.connected:
            raise ConfigError(f"{params['port']}: {worker.error or 'no connection'}")
        jog.show()
        if not opts.actions:
            jog.interact()
        for action in opts.actions:
            if not jog.do(action):
                break
    except KeyboardInterrupt:
        sys.stdout.write('\nCtrl-C: stopping the axis\n')
    except ConfigError as exc:
        sys.stdout.write(f'jog: {exc}\n')
        jog.failures += 1
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # the stop below is not cut short
        confirmed = worker.shutdown()
        position = worker.snapshot()['position_m']
        where = f' at {position * 1e3:.3f} mm' if position is not None else ''
        sys.stdout.write(f'axis stopped{where} (read back)\n' if confirmed else
                         f'stop sent{where}, NOT confirmed by the stage'
                         f"{' (step1mm has no readback)' if not worker.stage.measured else ''}"
                         '\n')
    sys.exit(1 if jog.failures else 0)


if __name__ == '__main__':
    main()
