"""
RigCommander: the rig from a lab script, in the manner of nav2_simple_commander.

    from tentacle_rig.commander_node import RigCommander
    with RigCommander() as rig:
        rig.wait_for_rig()
        rig.home('inserter')
        rig.set_field([0.0, 0.010, 0.0])          # held until release_field()
        rig.move_axis('inserter', 0.020)
        rig.play('out/schedule.yaml', mode='closed_loop', on_progress=print)

RigCommander is itself a node, spun on a thread of its own in a private context (a script
may hold several). Every call that waits has a deadline and returns a ``Result``: its
``outcome`` (an ``Outcome``) and a message, true only when DONE; nothing raises for a rig
that refuses or does not answer. A field set is held (sent again at 5 Hz: coils_node's
watchdog ramps an unrenewed field to zero after watchdog_s) until ``release_field`` or
``close``. Units: tesla, metre, second.
"""

from collections import deque
from dataclasses import dataclass
import enum
import math
import os
import threading
import time
from typing import NamedTuple

from geometry_msgs.msg import Vector3Stamped
import numpy as np
import rclpy
from rclpy.context import Context
from rclpy.duration import Duration
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from std_msgs.msg import Bool, Float64
from std_srvs.srv import SetBool, Trigger
from tentacle_common import contract
from tentacle_common.discovery import private_by_default
from tentacle_common.driver_node import client, publisher, subscription
from tentacle_common.waiting import wait_for

COILS_NODE = 'coils_node'
HOLD_PERIOD_S = 0.2     # a held field is sent again this often
KEEP = 400              # messages kept of each kind: the recent past a script looks at


class Outcome(enum.Enum):
    """How a call ended."""

    DONE = 'done'            # it happened, read back
    REFUSED = 'refused'      # the rig said no (the message says why)
    TIMED_OUT = 'timed out'  # no answer, or not there, by the deadline
    PAUSED = 'paused'        # a run paused (asked, or a fault: the message says which)
    ABORTED = 'aborted'      # a run aborted


@dataclass(frozen=True)
class Result:
    """An Outcome and what was said."""

    outcome: Outcome
    message: str = ''

    def __bool__(self):
        """Return True when the call did what it was asked."""
        return self.outcome is Outcome.DONE


class Status(NamedTuple):
    """One node's /diagnostics status: its level (DiagnosticStatus.OK, ...), text, values."""

    level: int
    message: str
    values: dict


@dataclass(frozen=True)
class Progress:
    """/player/progress: the step (1-based; 0 the end of a retraction) and the errors, m."""

    step: int
    steps: int
    inserted_m: float
    shape_rms_m: float
    tip_error_m: float


class RigCommander(Node):
    """The rig's topics and services behind a few calls with deadlines."""

    def __init__(self, name='rig_commander', axes=contract.AXES):
        """
        Start a private context, the node and its spin thread.

        On the rig's domain: discovery.private_by_default, unless the environment chose.
        """
        private_by_default(os.environ)
        self._context = Context()
        rclpy.init(context=self._context)
        super().__init__(name, context=self._context)
        self._lock = threading.Lock()
        self._kept = {}
        self._held = None
        self.field_pub = None   # made on the first field sent: the player pauses while
        #                         another node publishes field commands
        self.estop_pub = publisher(self, contract.ESTOP)
        self.target_pubs = {a: publisher(self, contract.axis_target(a)) for a in axes}
        self.follow('field', contract.FIELD)
        self.follow('progress', contract.PLAYER_PROGRESS)
        subscription(self, contract.DIAGNOSTICS, self._on_diagnostics)
        for axis in axes:
            self.follow(f'state:{axis}', contract.axis_state(axis))
        self.player_params = AsyncParameterClient(self, 'player_node')
        self._executor = SingleThreadedExecutor(context=self._context)
        self._executor.add_node(self)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    # -- plumbing ---------------------------------------------------------------------------
    def _spin(self):
        next_hold = time.monotonic()
        while not self._stop.is_set():
            self._executor.spin_once(timeout_sec=0.05)
            if self._held is not None and time.monotonic() >= next_hold:
                next_hold = time.monotonic() + HOLD_PERIOD_S
                self._send_field(renew=True)

    def _keep(self, key, msg):
        with self._lock:
            self._kept.setdefault(key, deque(maxlen=KEEP)).append((time.monotonic(), msg))

    def _on_diagnostics(self, msg):
        for status in msg.status:
            self._keep(f'status:{status.name}', status)

    def follow(self, key, topic):
        """Subscribe to a contract topic and keep its messages as a kind named key."""
        subscription(self, topic, lambda m: self._keep(key, m))

    def every(self, key, since=-math.inf):
        """
        Return the kept messages of a kind received after a monotonic time, oldest first.

        Kinds: 'field', 'progress', 'state:<axis>', 'status:<diagnostic status name>' and
        those added by follow(); the last KEEP of each.
        """
        with self._lock:
            kept = list(self._kept.get(key, ()))
        return [m for t, m in kept if t >= since]

    def latest(self, key, since=-math.inf):
        """Return the newest message of a kind received after a monotonic time, or None."""
        with self._lock:
            kept = self._kept.get(key)
            got = kept[-1] if kept else None
        return got[1] if got is not None and got[0] >= since else None

    def status(self, name, since=-math.inf):
        """Return the newest Status a node published under a name after a time, or None."""
        msg = self.latest(f'status:{name}', since)
        return None if msg is None else Status(msg.level, msg.message,
                                               {v.key: v.value for v in msg.values})

    def _matched(self, pub, node_name, timeout_s):
        """
        Wait until node_name subscribes to pub's topic and pub has matched every subscriber.

        Any subscriber is not enough: recorder_node subscribes to the same commands, and a
        sample acknowledged by the recorder alone may never reach the driver.
        """
        def ready():
            subs = self.get_subscriptions_info_by_topic(pub.topic_name)
            return any(s.node_name == node_name for s in subs) and \
                pub.get_subscription_count() >= len(subs)
        return wait_for(ready, timeout_s)

    def _call(self, srv, request, timeout_s):
        handle = client(self, srv)
        try:
            if not handle.wait_for_service(timeout_sec=timeout_s):
                return Result(Outcome.TIMED_OUT, f'no {srv.name} in {timeout_s:g} s: is the '
                              'rig up?')
            future = handle.call_async(request)
            if not wait_for(future.done, timeout_s):
                return Result(Outcome.TIMED_OUT, f'{srv.name}: no answer in {timeout_s:g} s')
            answer = future.result()
            return Result(Outcome.DONE if answer.success else Outcome.REFUSED, answer.message)
        finally:
            self.destroy_client(handle)

    # -- the rig ----------------------------------------------------------------------------
    def wait_for_rig(self, timeout_s=30.0, needs=('field', 'state:inserter')):
        """Wait until the rig's readings arrive (default: the field and the inserter)."""
        def missing():
            return [k for k in needs if self.latest(k) is None]
        if wait_for(lambda: not missing(), timeout_s):
            return Result(Outcome.DONE, 'the rig is up')
        return Result(Outcome.TIMED_OUT, f'nothing from {", ".join(missing())} in '
                      f'{timeout_s:g} s: is the rig up?')

    def wait_for_recorder(self, topics, timeout_s=15.0):
        """Wait until recorder_node has a publisher matched on each topic (contract rows)."""
        since = time.monotonic()   # a status from before may be an earlier recorder's

        def missing():
            status = self.status('recorder_node: bag', since)
            matched = set() if status is None else set(
                status.values.get('matched', '').split(','))
            return [t.name for t in topics if t.name not in matched]
        if wait_for(lambda: not missing(), timeout_s):
            return Result(Outcome.DONE, 'recording')
        return Result(Outcome.TIMED_OUT, f'recorder_node has no publisher on '
                      f'{", ".join(missing())} after {timeout_s:g} s')

    def field_t(self):
        """Return the field read back (3,), T, or None."""
        msg = self.latest('field')
        return None if msg is None else np.array([msg.vector.x, msg.vector.y, msg.vector.z])

    def _field_publisher(self):
        # Under self._lock.
        if self.field_pub is None:
            self.field_pub = publisher(self, contract.FIELD_CMD)
        return self.field_pub

    def _send_field(self, field_t=None, frame_id=contract.COILS_FRAME, renew=False):
        # Under the lock: release_field may destroy the publisher from another thread, and a
        # renewal that lost that race must neither publish nor make a new publisher.
        with self._lock:
            field_t = self._held if renew else field_t
            if renew and (field_t is None or self.field_pub is None):
                return
            msg = Vector3Stamped()
            msg.header.stamp = self.get_clock().now().to_msg()
            msg.header.frame_id = frame_id
            msg.vector.x, msg.vector.y, msg.vector.z = (float(v) for v in field_t)
            self._field_publisher().publish(msg)

    def send_field(self, field_t, frame_id=contract.COILS_FRAME):
        """
        Publish one field command, T, as it is: not checked, held or read back.

        For tests of what the rig does with any command; a script wants set_field.
        """
        self._send_field(field_t, frame_id)

    def wait_for_coils(self, timeout_s=10.0):
        """Wait until coils_node is matched to this node's field commands."""
        with self._lock:
            pub = self._field_publisher()
        if self._matched(pub, COILS_NODE, timeout_s):
            return Result(Outcome.DONE, f'{COILS_NODE} takes field commands')
        return Result(Outcome.TIMED_OUT, f'{COILS_NODE} does not subscribe to '
                      f'{contract.FIELD_CMD.name} after {timeout_s:g} s: is the rig up?')

    def set_field(self, field_t, timeout_s=5.0, tolerance_t=2e-4, wait=True):
        """
        Command and hold a field, T (frame coils); wait until it reads back within tolerance.

        wait=False: DONE once coils_node takes the command, not waiting for its ramp.
        """
        field = np.asarray(field_t, dtype=float)
        if field.shape != (3,) or not np.all(np.isfinite(field)):
            return Result(Outcome.REFUSED, f'field {field_t!r}: three finite numbers, tesla')
        result = self.wait_for_coils(timeout_s)
        if not result:
            return result
        since = time.monotonic()
        self._held = field
        self._send_field(field)
        if not wait:
            return Result(Outcome.DONE, f'{field * 1e3} mT sent and held')

        def there():
            msg = self.latest('field', since)
            return msg is not None and np.abs(self.field_t() - field).max() <= tolerance_t
        if wait_for(there, timeout_s):
            return Result(Outcome.DONE, f'the field reads {self.field_t() * 1e3} mT')
        return Result(Outcome.TIMED_OUT, f'the field reads {self.field_t()} T, not {field} T, '
                      f'after {timeout_s:g} s (coils_node logs a refusal)')

    def release_field(self):
        """
        Stop holding the field and stop publishing field commands (a player may then play).

        coils_node ramps the field to zero after its watchdog_s.
        """
        with self._lock:
            self._held = None
            if self.field_pub is not None:
                self.destroy_publisher(self.field_pub)
                self.field_pub = None

    def position_m(self, axis='inserter', since=-math.inf):
        """Return a stage's position read back after a monotonic time, m, or None."""
        msg = self.latest(f'state:{axis}', since)
        return None if msg is None else msg.position[0]

    def send_target(self, axis, position_m):
        """
        Publish one target to a stage, m, as it is: not checked, waited for or read back.

        For tests of what the rig does with any target; a script wants move_axis.
        """
        self.target_pubs[axis].publish(Float64(data=float(position_m)))

    def move_axis(self, axis, position_m, timeout_s=30.0, tolerance_m=2e-5):
        """Send a stage to a position, m; wait until it stands there."""
        if axis not in self.target_pubs:
            return Result(Outcome.REFUSED, f'{axis!r} is not one of {", ".join(self.target_pubs)}')
        if not math.isfinite(position_m):
            return Result(Outcome.REFUSED, f'{axis} target {position_m!r}: a finite number, m')
        pub = self.target_pubs[axis]
        node = contract.axis_node_name(axis)
        if not self._matched(pub, node, min(timeout_s, 10.0)):
            return Result(Outcome.TIMED_OUT, f'{node} does not subscribe to {pub.topic_name} '
                          f'after {min(timeout_s, 10.0):g} s: is the rig up?')
        since = time.monotonic()
        self.send_target(axis, position_m)
        # One target, sent once: the node may not yet have matched this publisher back; a
        # reliable sample is kept until every matched reader (the node's among them) acks it.
        if not pub.wait_for_all_acked(Duration(seconds=min(timeout_s, 5.0))):
            return Result(Outcome.TIMED_OUT, f'{axis} target not acknowledged by its node in '
                          f'{min(timeout_s, 5.0):g} s')

        def there():
            msg = self.latest(f'state:{axis}', since)
            return msg is not None and abs(msg.position[0] - position_m) <= tolerance_m and \
                abs(msg.velocity[0]) < 1e-4
        if wait_for(there, timeout_s):
            return Result(Outcome.DONE, f'{axis} at {position_m * 1e3:.3f} mm')
        msg = self.latest(f'state:{axis}')
        where = f'{msg.position[0] * 1e3:.3f} mm' if msg is not None else 'unknown'
        return Result(Outcome.TIMED_OUT, f'{axis} at {where}, not {position_m * 1e3:.3f} mm, '
                      f'after {timeout_s:g} s (inserter_node logs a refusal)')

    def home(self, axis='inserter', timeout_s=30.0):
        """Make where a stage stands its zero."""
        return self._call(contract.axis_service(axis, 'home'), Trigger.Request(), timeout_s)

    def stop_axis(self, axis='inserter', timeout_s=10.0):
        """Stop a stage now."""
        return self._call(contract.axis_service(axis, 'stop'), Trigger.Request(), timeout_s)

    def enable_coils(self, on=True, timeout_s=10.0):
        """Energise (True) or de-energise the coils' outputs."""
        return self._call(contract.COILS_ENABLE, SetBool.Request(data=bool(on)), timeout_s)

    def estop(self, on, timeout_s=5.0):
        """Publish the latched estop state once the rig subscribes to it."""
        if not wait_for(lambda: self.estop_pub.get_subscription_count() > 0, timeout_s):
            return Result(Outcome.TIMED_OUT, f'no subscriber to {contract.ESTOP.name} in '
                          f'{timeout_s:g} s: is the rig up?')
        self.estop_pub.publish(Bool(data=bool(on)))
        if not self.estop_pub.wait_for_all_acked(Duration(seconds=timeout_s)):
            return Result(Outcome.TIMED_OUT, f'estop {"on" if on else "off"} sent, not '
                          f'acknowledged in {timeout_s:g} s')
        return Result(Outcome.DONE, f'estop {"on" if on else "off"}')

    def capture_background(self, timeout_s=20.0):
        """
        Have the tracker take its latest frame as the empty scene (nothing inserted).

        Asked again while the tracker has no frame yet (a rig just up), until the deadline.
        """
        deadline = time.monotonic() + timeout_s
        while True:
            result = self._call(contract.VISION_CAPTURE_BACKGROUND, Trigger.Request(),
                                max(deadline - time.monotonic(), 0.1))
            if result or 'no frame yet' not in result.message or time.monotonic() > deadline:
                return result
            time.sleep(0.2)

    # -- the player -------------------------------------------------------------------------
    def set_player(self, timeout_s=10.0, **values):
        """Set player_node parameters (schedule, mode, gains, ...); DONE when all were taken."""
        if not self.player_params.wait_for_services(timeout_sec=timeout_s):
            return Result(Outcome.TIMED_OUT, 'player_node has no parameter services: is it up?')
        future = self.player_params.set_parameters(
            [Parameter(name, value=value) for name, value in values.items()])
        if not wait_for(future.done, timeout_s):
            return Result(Outcome.TIMED_OUT, 'player_node did not answer the parameters')
        refused = [f'{name}: {r.reason}' for name, r in zip(values, future.result().results)
                   if not r.successful]
        return Result(Outcome.REFUSED, '; '.join(refused)) if refused else \
            Result(Outcome.DONE, 'set')

    def player(self, verb, timeout_s=10.0):
        """Call the player's service of a verb: start, retract, pause, resume or abort."""
        return self._call(contract.player_service(verb), Trigger.Request(), timeout_s)

    def progress(self, since=-math.inf):
        """Return the latest Progress received after a monotonic time, or None."""
        msg = self.latest('progress', since)
        if msg is None:
            return None
        values = dict(zip(msg.name, msg.position))
        return Progress(int(values['step']), int(values['steps']), values['insertion'],
                        values['shape_rms'], values['tip_error'])

    def run_state(self, since=-math.inf):
        """Return (phase, message) of the player's latest status, or None."""
        status = self.status('player_node: run', since)
        if status is None:
            return None
        return status.values.get('phase', ''), status.message

    def wait_for_run(self, timeout_s=600.0, on_progress=None, since=None):
        """
        Wait until the run is done, paused or aborted; return the Result.

        :param on_progress: called with each new Progress
        :param since: only statuses received after this monotonic time count (default now)
        """
        since = time.monotonic() if since is None else since
        deadline, last = time.monotonic() + timeout_s, None
        while True:
            progress = self.progress(since)
            if on_progress is not None and progress is not None and progress != last:
                on_progress(progress)
                last = progress
            state = self.run_state(since)
            if state is not None and state[0] in ('done', 'paused', 'aborted'):
                outcome = {'done': Outcome.DONE, 'paused': Outcome.PAUSED,
                           'aborted': Outcome.ABORTED}[state[0]]
                return Result(outcome, state[1])
            if time.monotonic() >= deadline:
                return Result(Outcome.TIMED_OUT, f'the run is still {state and state[0]} '
                              f'after {timeout_s:g} s')
            time.sleep(0.02)

    def wait_for_player(self, timeout_s=30.0, since=-math.inf):
        """
        Wait until player_node says it is ready (it knows the coils' limits) or runs.

        :param since: only statuses received after this monotonic time count
        """
        def ready():
            state = self.run_state(since)
            return state is not None and (state[0] != 'idle' or state[1] == 'ready')
        if wait_for(ready, timeout_s):
            return Result(Outcome.DONE, 'the player is ready')
        state = self.run_state()
        return Result(Outcome.TIMED_OUT, f'player_node: {state[1] if state else "not heard"} '
                      f'after {timeout_s:g} s')

    def play(self, schedule=None, retract=False, timeout_s=600.0, on_progress=None,
             **player_params):
        """Set the schedule (and any player parameters), start, wait; return the Result."""
        result = self.wait_for_player(min(timeout_s, 30.0))
        if not result:
            return result
        values = dict(player_params, **({'schedule': str(schedule)} if schedule else {}))
        if values:
            result = self.set_player(**values)
            if not result:
                return result
            # Ready for this schedule, said after it was set: the schedule may command a
            # stage the player has not heard yet.
            result = self.wait_for_player(min(timeout_s, 30.0), since=time.monotonic())
            if not result:
                return result
        result = self.player('retract' if retract else 'start')
        if not result:
            return result
        return self.wait_for_run(timeout_s, on_progress, since=time.monotonic())

    # -- the end ----------------------------------------------------------------------------
    def close(self):
        """Stop holding, stop spinning, end the context."""
        self._held = None
        self._stop.set()
        self._thread.join(timeout=5.0)
        self._executor.shutdown()
        self.destroy_node()
        rclpy.try_shutdown(context=self._context)

    def __enter__(self):
        """Use as a context manager: closed at the end."""
        return self

    def __exit__(self, *exc):
        """Close."""
        self.close()
