"""
Jog one linear axis from the terminal: by +/- mm or to a position, home, position shown live.

    scripts/jog --port /dev/ttyACM0 home +5 -2.5 =10     (one after the other, then exit)
    scripts/jog --params config/inserter.yaml            (interactive: +1, -0.5, =10, h, s, q)

It talks to the stage itself, over its serial line, with inserter_node's driver and worker
(stage.py, axis_worker.py) and parameters (a params file's inserter_node section, then the
options), so inserter_node must not hold the port meanwhile. Positions are mm on the command
line and metres inside. The axis starts unhomed (either dialect): ``home`` makes where it
stands zero; a stop unhomes it again. Every action on the command line is checked before the
port is opened (its syntax; each target against [0, max_length] and, step1mm, the whole mm,
relative moves from the position the actions before them leave, from 0 after ``home``): one
bad action refuses the whole list and nothing is done. The actions then run in turn, up to
the first that fails. Exit status: 0 all done, 1 an action or the connection failed, 2 a
usage error (a bad action, option or parameter; nothing was done).
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

CONNECT_TIMEOUT_S = 5.0  # beyond the driver's own wait for a first answer (s)
SHOW_PERIOD_S = 0.1
USAGE_EXIT = 2  # as argparse's: nothing was done
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


class ActionsRefused(ValueError):
    """An action of the command line is malformed, or refused before the first motion."""


def plan(actions, stage):
    """
    Check every action before the first motion; return them as (text, kind, value).

    The axis starts unhomed (a connect unhomes it), ``home`` makes the position 0, a stop
    unhomes it and loses the position; a move needs a homed axis and its target must be one
    ``stage.check`` takes. A relative move becomes the absolute target it was checked as.

    :param stage: the (not connected) driver: its ``check`` says what targets it takes
    :raises ActionsRefused: the first bad action, named with its place in the list
    """
    planned, homed, position = [], False, None
    for number, text in enumerate(actions, 1):
        try:
            kind, value = parse_action(text)
            if kind == 'home':
                homed, position = True, 0.0
            elif kind == 'stop':
                homed, position = False, None
            elif kind in ('by', 'to'):
                if not homed:
                    raise ValueError('the axis is not homed there (it starts unhomed, and a '
                                     'stop unhomes it): put home before it')
                value = stage.check(value if kind == 'to' else position + value)
                kind, position = 'to', value
        except (ValueError, TargetRefused) as exc:
            raise ActionsRefused(f'action {number} {text!r}: {exc}') from None
        planned.append((text, kind, value))
    return planned


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

    def do(self, text, action=None):
        """
        Carry out one action; return False for quit. Failures are written and counted.

        :param action: (kind, value) as ``plan`` made it; None: parse text
        """
        try:
            kind, value = action or parse_action(text)
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
    parser.add_argument('--params', help='a ROS params file (its --node section)')
    parser.add_argument('--node', default=NODE_NAME,
                        help='the section of --params to read: inserter_node (default) or '
                             'the node name another axis runs under, e.g. backbone_node')
    for p in INSERTER_PARAMS:
        if p.name not in ('axis', 'state_rate'):
            parser.add_argument('--' + p.name.replace('_', '-'), dest=p.name,
                                type=type(p.default), help=p.description)
    return parser


def connect(worker, wait_s):
    """Return True once the worker is connected; False if it gave up or wait_s (s) passed."""
    deadline = time.monotonic() + wait_s
    while time.monotonic() < deadline and not worker.gave_up:
        if worker.connected:
            return True
        time.sleep(0.02)
    return worker.connected  # once more at the deadline


def farewell(worker, confirmed):
    """Return the last line: whether a stop reached the stage, and whether it confirmed it."""
    position = worker.snapshot()['position_m']
    where = f' at {position * 1e3:.3f} mm' if position is not None else ''
    if confirmed:
        return f'axis stopped{where} (read back)'
    if worker.stop_sent:
        return (f'stop sent{where}, NOT confirmed by the stage'
                f"{' (step1mm has no readback)' if not worker.stage.measured else ''}")
    why = ('the device never answered' if worker.gave_up else 'no connection')
    return f'no stop sent ({why}): the state of the axis is unknown: check it'


def main(args=None):
    """Run the actions (or interactively); stop the axis on exit, however it comes."""
    opts = build_parser().parse_args(args)
    overrides = {p.name: getattr(opts, p.name) for p in INSERTER_PARAMS
                 if getattr(opts, p.name, None) is not None}
    try:
        params = resolve(INSERTER_PARAMS, opts.node, opts.params, overrides)
        stage = make_stage(params)
        planned = plan(opts.actions, stage)
    except (ConfigError, ActionsRefused) as exc:
        print(f'jog: {exc}; nothing was done', file=sys.stderr)
        sys.exit(USAGE_EXIT)
    worker = AxisWorker(stage).start()
    jog = Jog(worker)
    try:
        if not connect(worker, params['restart_timeout_s'] + CONNECT_TIMEOUT_S):
            raise ConfigError(f"{params['port']}: {worker.error or 'no connection'}")
        jog.show()
        if not opts.actions:
            jog.interact()
        for number, (text, kind, value) in enumerate(planned, 1):
            if not jog.do(text, (kind, value)):
                break
            if jog.failures:
                rest = len(planned) - number
                if rest:
                    sys.stdout.write(f'jog: stopped at action {number} {text!r}: the {rest} '
                                     'after it were not carried out\n')
                break
    except KeyboardInterrupt:
        sys.stdout.write('\nCtrl-C: stopping the axis\n')
    except ConfigError as exc:
        sys.stdout.write(f'jog: {exc}\n')
        jog.failures += 1
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # the stop below is not cut short
        sys.stdout.write(farewell(worker, worker.shutdown()) + '\n')
    sys.exit(1 if jog.failures else 0)


if __name__ == '__main__':
    main()
