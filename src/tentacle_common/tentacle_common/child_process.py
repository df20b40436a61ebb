"""
A driver in a process of its own, driven by its node over pipes, safe when either one dies.

The coil bank (tentacle_coils.bank_process) and a linear axis (tentacle_inserter.axis_process)
run this way. When the node dies (even SIGKILL) the child sees its input close and makes its
device safe. When the child dies the node sees its output close: a spare child, started and
imported beforehand, takes over the port at once and makes the device safe by itself (a
fresh driver always starts from a safe state, read back). Nothing here imports rclpy.

Protocol, JSON lines. The node writes to the child's stdin::

    {"op": "config", "config": {...}}   (first line: what the driver is built from)
    {"op": <anything the driver handles>, ..., "id": 7}   (an "id" asks for a reply)
    {"op": "shutdown", "reason": "node exit"}

and reads from its stdout ``{"ev": "ready"}``, ``state`` snapshots every ``state_period_s``,
``reply`` (by id), ``log`` records, whatever other events the driver emits and, last,
``stopped`` with whether the device was left safe (``safe``). End of input is a shutdown.
The child ignores SIGINT (a Ctrl-C reaches the whole process group: the node decides) and
treats SIGTERM as a shutdown; signals during the shutdown change nothing.

Neither side lets the other hold it up or end it: the child's events go through a queue and
a writer thread (a node that stops reading never blocks the driver; stale states are dropped,
and info lines only when the queue is full), and a malformed line on either pipe is refused
and logged, never the end of its reader. The spare is watched too: one that dies is replaced
at once, and a child that dies with no spare ready is replaced by a fresh process.
"""

import collections
import faulthandler
import importlib.util
import json
import logging
import os
import signal
import subprocess
import sys
import threading
import time

from tentacle_common.errors import ConfigError, DriverError

FLUSH_TIMEOUT_S = 5.0  # how long a child's last events may wait for a reader at exit (s)


# -- the child's side ------------------------------------------------------------------------
class Emitter:
    """
    Send events to stdout, one JSON line each, from any thread, without ever blocking.

    A writer thread does the writing. Only the latest ``state`` is kept (a newer one makes
    an unwritten one stale); other events queue in order. When QUEUE_MAX events wait (the
    node stopped reading), the oldest info or debug log line is dropped, and the count is
    said once the pipe moves again; warnings, errors, replies and ``stopped`` never are.
    """

    QUEUE_MAX = 1000
    DROPPABLE_LEVELS = ('debug', 'info')

    def __init__(self, stream):
        """Write to ``stream`` (the child's stdout); starts the writer thread."""
        self.stream = stream
        self._cond = threading.Condition()
        self._state = None
        self._queue = collections.deque()  # (droppable, line)
        self._writing = False
        self._broken = False  # the reader has gone: nothing more is written
        self.dropped = 0
        threading.Thread(target=self._write_forever, name='child-emitter', daemon=True).start()

    def __call__(self, **event):
        """Queue one event; returns at once."""
        line = json.dumps(event) + '\n'
        with self._cond:
            if self._broken:
                return
            if event.get('ev') == 'state':
                self._state = line
            else:
                if len(self._queue) >= self.QUEUE_MAX:
                    self._drop_oldest_droppable()
                droppable = event.get('ev') == 'log' and event.get('level') in (
                    self.DROPPABLE_LEVELS)
                self._queue.append((droppable, line))
            self._cond.notify()

    def _drop_oldest_droppable(self):
        for i, (droppable, _) in enumerate(self._queue):
            if droppable:
                del self._queue[i]
                self.dropped += 1
                return

    def flush(self, timeout_s):
        """Wait until everything queued is written (or the reader is gone); False at timeout."""
        with self._cond:
            return self._cond.wait_for(lambda: self._broken or not (
                self._queue or self._state or self._writing), timeout_s)

    def _next_lines(self):
        with self._cond:
            self._writing = False
            self._cond.notify_all()
            self._cond.wait_for(lambda: self._queue or self._state)
            lines = [line for _, line in self._queue]
            if self.dropped:
                lines.insert(0, json.dumps({'ev': 'log', 'level': 'warning', 'message': (
                    f'{self.dropped} info log lines dropped: the node did not read them')})
                    + '\n')
                self.dropped = 0
            if self._state:
                lines.append(self._state)
            self._queue.clear()
            self._state = None
            self._writing = True
            return lines

    def _write_forever(self):
        while True:
            lines = self._next_lines()
            try:
                self.stream.write(''.join(lines))
                self.stream.flush()
            except (OSError, ValueError):  # the reader has gone: the shutdown path still runs
                with self._cond:
                    self._broken = True
                    self._writing = False
                    self._cond.notify_all()
                return


class _ForwardLogs(logging.Handler):
    def __init__(self, emit):
        super().__init__()
        self.emit_event = emit

    def emit(self, record):
        self.emit_event(ev='log', level=record.levelname.lower(), message=record.getMessage())


def serve(build, logger_name, *, stdin=sys.stdin, stdout=sys.stdout, terminate=None,
          state_period_s=0.02):
    """
    Run one driver until shutdown, end of input or ``terminate`` is set; return the exit code.

    ``build(config, emit)`` returns the driver, started, with ``handle(request)`` (a dict to
    reply with, or None: no reply, or one the driver emits later itself with the request's
    id, so a long request does not hold up the next), ``state()`` (a dict) and
    ``shutdown(reason)`` (a dict with ``safe``, for the ``stopped`` event). Requests are read
    on a thread of their own and the caller's thread only waits, so a signal never interrupts
    the safe stop: it only sets ``terminate``.
    """
    emit = Emitter(stdout)
    terminate = terminate or threading.Event()
    first = json.loads(stdin.readline() or '{}')
    if first.get('op') != 'config':
        emit(ev='stopped', safe=False, error='first line must be {"op": "config", ...}')
        emit.flush(FLUSH_TIMEOUT_S)
        return 2
    logger = logging.getLogger(logger_name)  # before the driver starts: it logs its connect
    logger.addHandler(_ForwardLogs(emit))
    logger.setLevel(logging.INFO)
    try:
        driver = build(first['config'], emit)
    except (DriverError, TypeError, KeyError) as exc:
        emit(ev='stopped', safe=False, error=f'config: {exc}')
        emit.flush(FLUSH_TIMEOUT_S)
        return 2
    emit(ev='ready')
    done = threading.Event()
    reason = ['node gone (input closed)']

    def publish_state():
        while not done.wait(state_period_s):
            emit(ev='state', **driver.state())

    def read_requests():
        # One bad line must not end this loop: its end is how the node's death is noticed.
        for line in stdin:
            try:
                request = json.loads(line)
                if not isinstance(request, dict):
                    raise ValueError(f'a JSON {type(request).__name__}, not an object')
            except ValueError as exc:
                emit(ev='log', level='error', message=f'request refused ({exc}): {line[:200]!r}')
                continue
            if request.get('op') == 'shutdown':
                reason[0] = request.get('reason', 'shutdown')
                break
            try:
                reply = driver.handle(request)
            except Exception as exc:  # noqa: B902 (whatever the driver raises, keep serving)
                emit(ev='log', level='error',
                     message=f'request {request.get("op")!r} failed: {exc!r}')
                reply = {'ok': False, 'message': f'request failed: {exc}'} if (
                    'id' in request) else None
            if reply is not None:
                emit(ev='reply', id=request.get('id'), **reply)
        terminate.set()

    threading.Thread(target=publish_state, name='child-state', daemon=True).start()
    threading.Thread(target=read_requests, name='child-requests', daemon=True).start()
    terminate.wait()
    stopped = driver.shutdown(reason[0])
    done.set()
    emit(ev='stopped', **stopped)
    emit.flush(FLUSH_TIMEOUT_S)
    return 0


def child_main(build, logger_name, state_period_s=0.02):
    """Run ``serve`` as a child process's main: SIGINT ignored, SIGTERM a shutdown."""
    terminate = threading.Event()
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, lambda *_: terminate.set())
    # `kill -USR1 <pid>` prints every thread's stack to the node's stderr: where a driver
    # that stopped talking is waiting, without stopping it.
    faulthandler.register(signal.SIGUSR1, all_threads=True)
    # Worker threads wake every few milliseconds; don't let them wait 5 ms for each other.
    sys.setswitchinterval(2e-4)
    code = serve(build, logger_name, terminate=terminate, state_period_s=state_period_s)
    # Stopped and reported: a SIGTERM while the interpreter finalises (Python then restores
    # the default disposition for its handlers) must not turn that into a kill.
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    sys.exit(code)


# -- the node's side -------------------------------------------------------------------------
def _package_root(module):
    """Return the directory that holds ``module``'s top-level package."""
    spec = importlib.util.find_spec(module.split('.')[0])
    return os.path.dirname(os.path.dirname(os.path.abspath(spec.origin)))


def spawn(module):
    """Start ``python -m module``; it imports everything, then waits for its config line."""
    # Find these very packages in the child, whatever layout they were imported from
    # (colcon installs each package under a prefix of its own).
    roots = dict.fromkeys([_package_root(module), _package_root(__name__)])
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [*roots, *filter(None, [os.environ.get('PYTHONPATH')])]))
    return subprocess.Popen([sys.executable, '-m', module], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True, bufsize=1, env=env)


def child_pids(pid):
    """Return the pids of the processes ``pid`` started (from any of its threads), from /proc."""
    pids = []
    for task in os.listdir(f'/proc/{pid}/task'):
        with open(f'/proc/{pid}/task/{task}/children') as handle:
            pids += [int(p) for p in handle.read().split()]
    return pids


def end(popen):
    """Close a child's input (it stops safely) and wait; kill it if it hangs."""
    try:
        popen.stdin.close()
    except OSError:
        pass
    try:
        popen.wait(5.0)
    except subprocess.TimeoutExpired:
        popen.kill()
        popen.wait()


class ChildGone(DriverError):
    """The child process is not running (starting, replaced, or given up on)."""


class ChildClient:
    """
    The node's handle on a driver child, with a spare started beforehand to replace it.

    Subclasses name the child's ``MODULE``, its ``STARTING`` state (until the first
    snapshot), and say what a death means (``death_note``); ``on_event`` gets the events
    this class does not handle and ``on_started`` runs after each child got its config.
    After RESTARTS_MAX deaths within RESTART_WINDOW_S no more are started. A spare that dies
    is replaced at once (it holds no device), unless spares die that often too.
    """

    MODULE = ''
    WHAT = 'child'             # in messages: 'coil bank', 'inserter axis'
    STARTING = {'status': ['error', 'starting']}
    GONE = ChildGone           # raised by send() when the child is not running
    REPLY_TIMEOUT_S = 2.0
    START_TIMEOUT_S = 20.0
    RESTARTS_MAX = 3
    RESTART_WINDOW_S = 30.0

    def __init__(self, config, logger_name):
        """
        Start the child with ``config`` and wait until it runs.

        :raises ConfigError: the child refused the configuration, or did not start
        """
        self._config = config
        self.log = logging.getLogger(logger_name)
        self._write_lock = threading.Lock()
        self._cond = threading.Condition()
        self._replies = {}
        self._next_id = 0
        self._closing = False
        self._lifecycle = threading.RLock()  # one start or replacement at a time
        self.deaths = []     # (time.monotonic(), exit code) of each child that died
        self.spare_deaths = []  # the same for spares, which held no device
        self.death_note = ''  # what the status says after a death, until cleared
        self._spare = None
        self._spawn_spare()
        self._start_child()
        with self._cond:
            self._cond.wait_for(lambda: self._ready or self._stopped is not None,
                                self.START_TIMEOUT_S)
            if not self._ready:
                error = (self._stopped or {}).get('error', 'did not start in time')
                self._close_all()
                raise ConfigError(f'{self.WHAT} process: {error}')

    # -- hooks ------------------------------------------------------------------------------
    def on_started(self):
        """Run after a child got its config (e.g. carry an estop over to it)."""

    def on_event(self, kind, event):
        """Take an event other than state, log, reply, ready and stopped."""

    def death_note_for(self, code, gave_up):
        """Return what the status says after a death (exit ``code``)."""
        if gave_up:
            return (f'{self.WHAT} process died {len(self.deaths)} times (last exit {code}): '
                    'not restarted')
        return f'{self.WHAT} process died (exit {code}); a fresh one took over'

    # -- plumbing ---------------------------------------------------------------------------
    @property
    def state(self):
        """Return the latest state snapshot (a dict)."""
        return self._state

    @property
    def spare_pid(self):
        """Return the spare process's pid, or None when no spare is alive."""
        spare = self._spare
        return spare.pid if spare is not None and spare.poll() is None else None

    @property
    def running(self):
        """Return True while a child is up and has not stopped."""
        return self._ready and self._stopped is None

    def _start_child(self):
        """Hand the config to the spare (a fresh process if none is alive), start the next."""
        with self._lifecycle:
            child, self._spare = self._spare, None
            if child is None or child.poll() is not None:
                child = spawn(self.MODULE)  # no spare ready: a fresh one, slower to import
            with self._cond:
                self.popen = child
                self._state = dict(self.STARTING)
                self._ready = False
                self._stopped = None
            threading.Thread(target=self._read, args=(child,), name='child-reader',
                             daemon=True).start()
            try:
                self.send(op='config', config=self._config)
                self.on_started()
            except self.GONE:
                pass  # it died already: its reader sees that
            self._spawn_spare()

    def _spawn_spare(self):
        """Start a spare and a thread that replaces it if it dies while still a spare."""
        spare = self._spare = spawn(self.MODULE)
        threading.Thread(target=self._watch_spare, args=(spare,), name='spare-watch',
                         daemon=True).start()

    def _watch_spare(self, spare):
        code = spare.wait()
        with self._lifecycle:
            if spare is not self._spare or self._closing:
                return  # it became the child (its reader watches it) or we are closing
            now = time.monotonic()
            self.spare_deaths.append((now, code))
            recent = [t for t, _ in self.spare_deaths if now - t < self.RESTART_WINDOW_S]
            if len(recent) > self.RESTARTS_MAX:
                self._spare = None
                self.log.error('%s spare process died %d times in %g s (last exit %s): no '
                               'spare kept; a death would start a fresh process', self.WHAT,
                               len(recent), self.RESTART_WINDOW_S, code)
                return
            self.log.error('%s spare process died (exit %s); a new spare started', self.WHAT,
                           code)
            self._spawn_spare()

    def send(self, **request):
        """
        Write one request to the child.

        :raises GONE: the child's input is closed
        """
        line = json.dumps(request) + '\n'
        with self._write_lock:
            try:
                self.popen.stdin.write(line)
                self.popen.stdin.flush()
            except (OSError, ValueError):
                raise self.GONE(f'{self.WHAT} process is not running') from None

    def ask(self, timeout_s=None, **request):
        """Send a request with an id; return its reply (a dict), or None if none came."""
        with self._cond:
            self._next_id += 1
            request_id = self._next_id
        self.send(id=request_id, **request)
        with self._cond:
            if not self._cond.wait_for(lambda: request_id in self._replies,
                                       timeout_s or self.REPLY_TIMEOUT_S):
                return None
            return self._replies.pop(request_id)

    def _read(self, popen):
        for line in popen.stdout:
            try:
                self._take(json.loads(line))
            except Exception as exc:  # noqa: B902 (one bad event must not end the reader)
                self.log.error('%s process: event refused (%r): %.200s', self.WHAT, exc, line)
        with self._cond:
            if popen is not self.popen or self._stopped is not None:
                return
            self._stopped = {'safe': False, 'error': 'exited unexpectedly'}
            self._cond.notify_all()
            closing = self._closing
        if not closing:
            self._replace(popen)

    def _take(self, event):
        """Act on one event from the child."""
        kind = event.pop('ev', None)
        if kind == 'state':
            with self._cond:
                self._state = event
        elif kind == 'log':
            self.log.log(getattr(logging, event['level'].upper(), logging.INFO),
                         event['message'])
        elif kind in ('reply', 'ready', 'stopped'):
            with self._cond:
                if kind == 'reply':
                    self._replies[event['id']] = event
                elif kind == 'ready':
                    self._ready = True
                else:
                    self._stopped = event
                self._cond.notify_all()
        else:
            self.on_event(kind, event)

    def _replace(self, dead):
        """Note the death, and let the spare take over (unless deaths come too often)."""
        code = dead.wait()
        with self._lifecycle:
            if self._closing:
                return
            now = time.monotonic()
            self.deaths.append((now, code))
            recent = [t for t, _ in self.deaths if now - t < self.RESTART_WINDOW_S]
            gave_up = len(recent) > self.RESTARTS_MAX
            self.death_note = self.death_note_for(code, gave_up)
            self.log.error('%s', self.death_note)
            if gave_up:
                with self._cond:
                    self._state = {**self.STARTING, 'status': ['error', self.death_note]}
                return
            self._start_child()

    def shutdown(self, reason='shutdown', timeout_s=30.0):
        """Ask the child to stop safely and end the processes; return its ``stopped`` event."""
        with self._cond:
            self._closing = True
        try:
            self.send(op='shutdown', reason=reason)
        except self.GONE:
            pass
        with self._cond:
            self._cond.wait_for(lambda: self._stopped is not None, timeout_s)
            stopped = self._stopped or {'safe': False, 'error': 'no answer'}
        self._close_all()
        return stopped

    def _close_all(self):
        with self._lifecycle, self._cond:
            self._closing = True
        for popen in (self.popen, self._spare):
            if popen is not None:
                end(popen)
