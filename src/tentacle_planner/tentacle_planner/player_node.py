"""
player_node: play a schedule on the rig, the coils and the stages in step, with a closed loop.

Services (std_srvs/Trigger): /player/start reads ``schedule`` and plays it from nothing
inserted; /player/retract plays it backwards to nothing inserted and zero field;
/player/pause holds the field and the stages where they are; /player/resume plays the
paused step again; /player/abort commands zero field and stops the stages. A schedule is
refused, with the reason, when it is of a format this reader does not know, was planned for
another tentacle than ``tentacle``, or its fields break the coils' limits (the tighter of
this node's and coils_node's own ``max_field``).

Each step: /inserter/target (and /backbone/target) and /coils/field_cmd, then wait until
/inserter/state and /coils/field say both have arrived, dwell, go on
(tentacle_planner.player). The field held is sent again at ``hold_rate`` (coils_node's
watchdog). ``mode`` closed_loop corrects the field at every fresh /vision/shape while a step
dwells (tentacle_planner.shape_control), tip_angle by thesis eq. 6.10 on /vision/tip; the
loop's knobs may be set while a run plays. A fault (the estop, a driver's error in
/diagnostics, a reading lost, a deadline missed, another node publishing /coils/field_cmd)
pauses the run and says why (``on_fault`` abort: aborts it). Progress on /player/progress
and /diagnostics. On exit a run still commanding is aborted: zero field, stages stopped.
"""

import math
import os
import sys
import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Vector3Stamped
from nav_msgs.msg import Path
import numpy as np
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter_client import AsyncParameterClient
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64
from std_srvs.srv import Trigger
from tentacle_common import contract, frames
from tentacle_common.cdr import header_stamp_s
from tentacle_common.driver_node import (client, declare_parameters, diagnostic_status,
                                         publisher, qos_profile, run_node, service,
                                         subscription)
from tentacle_common.errors import ConfigError
from tentacle_model.model import TentacleModel
from tentacle_model.tentacle_spec import load_tentacle, SpecError
from tentacle_planner import paths
from tentacle_planner.errors import PlanInputError
from tentacle_planner.loop_gate import LoopGate
from tentacle_planner.player import (commanded_axes, Phase, play_steps, Player, Seen,
                                     Settings)
from tentacle_planner.player_params import (LOOP_PARAMS, MODES, NODE_NAME, PLAYER_PARAMS,
                                            REFERENCES)
from tentacle_planner.schedule_check import CoilLimits, field_refusals, tentacle_refusals
from tentacle_planner.schedule_file import read_schedule
from tentacle_planner.shape_control import (CoilingController, Gains, in_limits,
                                            REFERENCE_SAMPLES, ShapeController,
                                            TipAngleController, tracked_at)

TICK_S = 0.01           # the player's clock tick, s
DRIVER_PREFIXES = ('coils', 'inserter_node')   # /diagnostics statuses a run depends on


def _name_of(endpoint):
    """Return a publisher's node as /namespace/name (discovery may not know it yet)."""
    if endpoint.node_name == '_NODE_NAME_UNKNOWN_':
        return 'a node not yet named by discovery'
    return f'{endpoint.node_namespace.rstrip("/")}/{endpoint.node_name}'


def _stamp_s(msg):
    return msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec


class PlayerNode(Node):
    """The schedule player's ROS side: services in, commands out, the loop on frames."""

    def __init__(self):
        """Declare parameters, wire topics and services, start the clock."""
        super().__init__(NODE_NAME)
        self.p = declare_parameters(self, PLAYER_PARAMS)
        self.loop = declare_parameters(self, LOOP_PARAMS, read_only=False)
        for name, allowed in (('mode', MODES), ('reference', REFERENCES),
                              ('on_fault', ('pause', 'abort'))):
            value = self.loop.get(name, self.p.get(name))
            if value not in allowed:
                raise ConfigError(f'{name}: {value!r} is not one of {", ".join(allowed)}')
        self.rig_tentacle = None
        if self.p['tentacle']:
            try:
                self.rig_tentacle = load_tentacle(self.p['tentacle'])
            except SpecError as exc:
                raise ConfigError(f'tentacle: {exc}') from None
        self.add_on_set_parameters_callback(self._on_set)
        self.seen, self.driver_status = Seen(), {}
        self.player = self.schedule = None
        self.controller = self.tip_control = self.coiling = None
        self.path = self.insertion_point = None
        self.coils_max_field = None
        self._published_field, self._published_at, self._step_key = None, -math.inf, None
        self.gate, self._shape_at = LoopGate(), -math.inf
        self._shape_raw, self._shape_points = None, None
        self._others = []
        self._phase = None
        self._schedule_axes = (None, ['inserter'])   # ((file, mtime), axes): schedule_axes

        self.field_pub = publisher(self, contract.FIELD_CMD)
        self.target_pubs = {axis: publisher(self, contract.axis_target(axis))
                            for axis in contract.AXES}
        self.stop_clients = {axis: client(self, contract.axis_service(axis, 'stop'))
                             for axis in contract.AXES}
        self.progress_pub = publisher(self, contract.PLAYER_PROGRESS)
        self.diag_pub = publisher(self, contract.DIAGNOSTICS)
        subscription(self, contract.FIELD, self.on_field)
        for axis in contract.AXES:
            subscription(self, contract.axis_state(axis),
                         lambda msg, a=axis: self.on_state(a, msg))
        subscription(self, contract.ESTOP, self.on_estop)
        subscription(self, contract.DIAGNOSTICS, self.on_diagnostics)
        # Serialized: the loop reads a centreline's stamp first, and the poses only of the
        # frames it takes (hundreds of poses at 30 Hz cost milliseconds each in Python).
        self.create_subscription(Path, contract.VISION_SHAPE.name, self.on_shape,
                                 qos_profile(contract.VISION_SHAPE.qos), raw=True)
        subscription(self, contract.VISION_TIP, self.on_tip)
        for verb in contract.PLAYER_VERBS:
            service(self, contract.player_service(verb),
                    lambda req, res, v=verb: self.on_service(v, res))
        self.coils_params = AsyncParameterClient(self, self.p['coils_node'])
        self.create_timer(TICK_S, self.tick)
        # A dwell ends between two ticks: this one-shot ends it on time, not up to a tick late.
        self._dwell_timer = self.create_timer(TICK_S, self._dwell_over, autostart=False)
        self.create_timer(1.0 / self.p['progress_rate'], self.publish_progress)
        self._ticks = 0   # housekeeping runs at 5 Hz; coils_node's limits are asked every 1 s
        self.create_timer(0.2, self.housekeeping)
        if self.rig_tentacle is None:
            self.get_logger().warning('tentacle: not given: a schedule planned for another '
                                      'tentacle is not refused')

    # -- parameters --------------------------------------------------------------------
    def _on_set(self, parameters):
        changes = {}
        for parameter in parameters:
            if parameter.name in ('mode', 'reference'):
                allowed = MODES if parameter.name == 'mode' else REFERENCES
                if parameter.value not in allowed:
                    return SetParametersResult(successful=False, reason=(
                        f'{parameter.name}: {parameter.value!r} is not one of '
                        f'{", ".join(allowed)}'))
            if parameter.name in self.loop:
                changes[parameter.name] = parameter.value
        self.loop.update(changes)
        self._apply_gains()
        return SetParametersResult(successful=True)

    def gains(self):
        """Return the loop's Gains from the parameters now."""
        q = self.loop
        return Gains(gain=q['gain'], damping=q['damping'], max_step_t=q['max_step'],
                     tolerance_m=q['tolerance'], max_iterations=q['max_iterations'],
                     stall_ratio=q['stall_ratio'], tip_gain=q['tip_gain'],
                     tip_tolerance_rad=q['tip_tolerance'])

    def _apply_gains(self):
        for controller in (self.controller, self.tip_control, self.coiling):
            if controller is not None:
                controller.gains = self.gains()

    # -- what the rig says -------------------------------------------------------------
    def on_field(self, msg):
        """Keep the field read back, T."""
        self.seen.field_t = np.array([msg.vector.x, msg.vector.y, msg.vector.z])
        self.seen.field_at = time.monotonic()
        self._arrival_check()

    def on_state(self, axis, msg):
        """Keep a stage's position, m, and velocity, m/s."""
        if msg.position:
            self.seen.positions_m[axis] = float(msg.position[0])
            self.seen.velocities_m_s[axis] = float(msg.velocity[0]) if msg.velocity else 0.0
            self.seen.positions_at[axis] = time.monotonic()
            self._arrival_check()

    def _arrival_check(self):
        # A step's arrival is seen on the reading that shows it, not up to a tick later: the
        # dwell, and so the step, starts that much sooner.
        if self.player is not None and self.player.phase is Phase.MOVING:
            self.tick()

    def on_estop(self, msg):
        """Keep the estop's state."""
        self.seen.estop = bool(msg.data)

    def on_diagnostics(self, msg):
        """Keep the drivers' statuses: an error is a fault of the run."""
        for status in msg.status:
            if status.name.startswith(DRIVER_PREFIXES):
                self.driver_status[status.name] = (status.level, status.message)

    def faults(self):
        """Return the faults of the rig now, in words."""
        found = [f'{name}: {message}' for name, (level, message) in self.driver_status.items()
                 if level == 2]
        if self._others:
            found.append(f'another node publishes {contract.FIELD_CMD.name}: '
                         + ', '.join(self._others))
        late = time.monotonic() - self._shape_at
        if self.looping() and self.player.phase is Phase.DWELL \
                and late > self.p['feedback_timeout_s']:
            found.append(f'{self.loop["mode"]}: no {contract.VISION_SHAPE.name} for '
                         f'{min(late, 1e6):.1f} s (is tracker_node running?)')
        return tuple(found)

    def waiting_for(self):
        """Return what the player has not heard yet and needs to start: [] when ready."""
        missing = [] if self.coils_max_field is not None else \
            [f'the limits of {self.p["coils_node"]}']
        if self.seen.field_t is None:
            missing.append(contract.FIELD.name)
        missing += [contract.axis_state(axis).name for axis in self.schedule_axes()
                    if axis not in self.seen.positions_m]
        return missing

    def axes(self):
        """Return the stages this node may command: the backbone too where it is allowed."""
        return ('inserter', 'backbone') if self.p['backbone'] else ('inserter',)

    def schedule_axes(self):
        """
        Return the stages a run of the schedule set now would command (the inserter at least).

        Read again only when the file or its modification time changes; a schedule that
        cannot be read is said so when a run is started.
        """
        path = self.loop['schedule']
        try:
            key = (path, os.stat(path).st_mtime_ns) if path else None
        except OSError:
            key = None
        if key is None:
            return ['inserter']
        if self._schedule_axes[0] != key:
            try:
                axes = commanded_axes(read_schedule(path), self.axes())
            except PlanInputError:
                axes = ['inserter']
            self._schedule_axes = (key, axes)
        return self._schedule_axes[1]

    def planned_centreline(self):
        """Return the step under way's planned centreline (k, 3), coils m, or None."""
        index = self.player.step.index if self.player is not None else 0
        return self.schedule.steps[index - 1].predicted_centreline_m if index > 0 else None

    def looping(self):
        """Return whether a closed loop corrects the step under way."""
        if self.loop['mode'] == 'open_loop' or self.player is None or \
                self.player.step.inserted_m < self.loop['loop_min_inserted']:
            return False
        if self.loop['mode'] == 'coiling':   # eq. 6.10 up to coil_feedback_max, then open
            planned = self.planned_centreline()
            return planned is not None and self.coiling.active(planned)
        return True

    # -- the run -----------------------------------------------------------------------
    def limits(self):
        """Return the tighter of this node's limits and coils_node's own max_field."""
        own = CoilLimits(self.p['max_field'], self.p['max_total_field'],
                         self.p['max_field_change'])
        return own.tightest(CoilLimits(self.coils_max_field))

    def load(self, retract):
        """Return a new Player for the schedule file, or raise ValueError saying why not."""
        if self.coils_max_field is None:
            raise ValueError(f'the limits of {self.p["coils_node"]} are not known: is it '
                             'running? (its max_field is asked for)')
        if not self.loop['schedule']:
            raise ValueError('schedule: no schedule file given (-p schedule:=DIR/schedule.yaml)')
        try:
            schedule = read_schedule(self.loop['schedule'])
            planned = schedule.tentacle_spec()
        except PlanInputError as exc:
            raise ValueError(f'refused: {exc}') from None
        reasons = []
        if self.rig_tentacle is not None:
            reasons += [f'planned for another tentacle than {self.p["tentacle"]}: {r}'
                        for r in tentacle_refusals(planned, self.rig_tentacle)]
        limits = self.limits()
        reasons += field_refusals([s.field_t for s in schedule.steps], limits)
        if schedule.interrupted:
            reasons.append('the plan was interrupted (Ctrl-C): plan it again to play it')
        if reasons:
            raise ValueError(f'refused {schedule.source}: ' + '; '.join(reasons))
        start, steps = play_steps(schedule, self.axes(), self.p['insertion_offset_m'], retract)
        q = self.p
        settings = Settings(
            dwell_s=q['dwell_s'], position_tolerance_m=q['position_tolerance'],
            field_tolerance_t=q['field_tolerance'], settle_timeout_s=q['settle_timeout_s'],
            speed_m_s=q['stage_speed'], feedback_timeout_s=q['feedback_timeout_s'],
            abort_on_fault=q['on_fault'] == 'abort',
            max_correction_t=limits.max_field_change_t or np.inf)
        self.schedule, self.path = schedule, paths.Path(schedule.path_m, str(schedule.source))
        self.insertion_point = planned.base_position_m
        model = TentacleModel(planned, **schedule.model.as_options())
        self.controller = ShapeController(model, self.path, limits, self.gains())
        self.tip_control = TipAngleController(self.path, limits, self.gains())
        direction = planned.base_rotation[:, 0]   # the insertion direction, frame coils
        self.coiling = CoilingController(limits, self.gains(), self.loop['coil_feedback_max'],
                                         math.atan2(direction[1], direction[0]))
        return Player(start, steps, settings, lambda b: in_limits(b, limits))

    def on_service(self, verb, response):
        """Answer /player/<verb>."""
        now = time.monotonic()
        try:
            if verb in ('start', 'retract'):
                if self.player is not None and self.player.phase in (
                        Phase.MOVING, Phase.DWELL, Phase.PAUSED):
                    raise ValueError(f'a run is {self.player.phase.value}: abort it first')
                player = self.load(retract=verb == 'retract')
                self.seen.faults = self.faults()
                command = player.start(now, self.seen)
                self.player = player
                self.gate = LoopGate()
                command.said[0] += (f' ({"retracting" if verb == "retract" else "inserting"}'
                                    f' {self.schedule.source}, {self.loop["mode"]})')
            elif self.player is None:
                raise ValueError('no run: call /player/start first')
            elif verb == 'pause':
                command = self.player.pause(now)
            elif verb == 'resume':
                self.seen.faults = self.faults()
                command = self.player.resume(now, self.seen)
            else:
                command = self.player.abort(now, seen=self.seen)
        except ValueError as exc:
            response.success, response.message = False, str(exc)
            self.get_logger().warning(f'/player/{verb}: {exc}')
            return response
        self.apply(command)
        response.success, response.message = True, '; '.join(command.said) or verb
        return response

    def tick(self):
        """Advance the run and send what it holds."""
        if self.player is None:
            return
        self.seen.faults = self.faults()
        busy = self.looping() and not self.gate.converged
        now = time.monotonic()
        self.apply(self.player.update(now, self.seen, busy))
        left = self.player.dwell_left_s(now)
        if not busy and left is not None and 0.0 < left < TICK_S and \
                self._dwell_timer.is_canceled():
            self._dwell_timer.timer_period_ns = int(left * 1e9)
            self._dwell_timer.reset()
        if self.player.phase is not self._phase:
            self._phase = self.player.phase
            if self._phase is Phase.DWELL:
                self.gate.dwell_began(self.get_clock().now().nanoseconds * 1e-9)
        if self.player.zero_read_back(self.seen):
            self.player.release()   # the coils are free for another commander
            self.get_logger().info(f'{self.player.phase.value}: the field reads zero ('
                                   f'{np.abs(self.seen.field_t).max() * 1e3:.3f} mT): no '
                                   'longer commanding the coils')

    def _dwell_over(self):
        self._dwell_timer.cancel()
        self.tick()

    def apply(self, command):
        """Send a Command: the targets, the field (on change and at hold_rate), stops."""
        now = time.monotonic()
        for line in command.said:
            self.get_logger().info(line)
        for axis, target in command.targets_m.items():
            self.target_pubs[axis].publish(Float64(data=float(target)))
        if command.stop_axes:
            for axis in self.seen.positions_m:
                if axis in self.stop_clients and self.stop_clients[axis].service_is_ready():
                    self.stop_clients[axis].call_async(Trigger.Request())
        if command.field_t is not None and (
                self._published_field is None
                or not np.array_equal(command.field_t, self._published_field)
                or now - self._published_at >= 1.0 / self.p['hold_rate']):
            self.publish_field(command.field_t, now)
        key = (id(self.player), self.player.index) if self.player else None
        if key != self._step_key:
            self._step_key = key
            for controller in (self.controller, self.tip_control, self.coiling):
                if controller is not None:
                    controller.new_step()
            self.gate.new_step()
            self.publish_progress()

    def publish_field(self, field_t, now):
        """Publish /coils/field_cmd, T, frame coils."""
        msg = Vector3Stamped()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = contract.COILS_FRAME
        msg.vector.x, msg.vector.y, msg.vector.z = (float(v) for v in field_t)
        if self._published_field is None or not np.array_equal(field_t, self._published_field):
            self.gate.field_changed(_stamp_s(msg), self.loop['loop_settle_s'])
        self.field_pub.publish(msg)
        self._published_field, self._published_at = np.array(field_t, dtype=float), now

    # -- the closed loop ----------------------------------------------------------------
    def _fresh(self, stamp_s):
        """Return whether a frame taken at stamp_s (ROS time, s) may drive a correction now."""
        self._shape_at = time.monotonic()
        return self.looping() and self.player.phase is Phase.DWELL and \
            self.gate.fresh(stamp_s, self._shape_at, self.loop['loop_rate'])

    def latest_shape(self):
        """Return the latest tracked centreline (N, 2), workspace m, or None."""
        if self._shape_points is None and self._shape_raw is not None:
            msg = deserialize_message(self._shape_raw, Path)
            self._shape_points = np.array([[p.pose.position.x, p.pose.position.y]
                                           for p in msg.poses]).reshape(-1, 2)
        return self._shape_points

    def on_shape(self, raw):
        """Keep the tracked centreline; in closed_loop, correct the field from it."""
        self._shape_raw, self._shape_points = raw, None
        stamp = header_stamp_s(raw)
        if self.loop['mode'] not in ('closed_loop', 'coiling') or not self._fresh(stamp):
            return
        points = self.latest_shape()
        if self.loop['mode'] == 'coiling':
            seen = frames.coils_from_workspace(points, self.insertion_point)
            self._corrected(stamp, self.coiling.correct(self.planned_centreline(),
                                                        self.player.field_t, seen))
            return
        planned = None
        if self.loop['reference'] == 'planned' and self.player.step.index > 0:
            planned = self.schedule.steps[self.player.step.index - 1].predicted_centreline_m
        seen = frames.coils_from_workspace(points, self.insertion_point)[:, :2] \
            if len(points) else points
        correction = self.controller.correct(self.player.step.inserted_m, self.player.field_t,
                                             seen, planned)
        self._corrected(stamp, correction)

    def on_tip(self, msg):
        """In tip_angle mode, correct the field from the tracked tip's heading."""
        if self.loop['mode'] != 'tip_angle' or not self._fresh(_stamp_s(msg)):
            return
        q = msg.pose.orientation
        heading = 2.0 * math.atan2(q.z, q.w)
        correction = self.tip_control.correct(self.player.step.inserted_m, self.player.field_t,
                                              heading)
        self._corrected(_stamp_s(msg), correction)

    def _corrected(self, stamp_s, correction):
        now = time.monotonic()
        latency = self.get_clock().now().nanoseconds * 1e-9 - stamp_s
        if not correction.converged:
            self.apply(self.player.adjust_field(correction.field_t))
        self.gate.corrected(now, self.player.index, latency, correction.converged)
        if correction.converged:   # the dwell was held for the loop: it may end now
            self.tick()

    # -- reports ------------------------------------------------------------------------
    def tracked_errors(self):
        """Return (shape RMS, tip error), m, of the latest tracked shape, or NaN."""
        shape = self.latest_shape()
        if self.player is None or shape is None or len(shape) < 2:
            return math.nan, math.nan
        inserted = self.player.step.inserted_m
        if inserted <= 0:
            return math.nan, math.nan
        inserted = min(inserted, self.path.length_m)
        along = np.linspace(0.0, inserted, REFERENCE_SAMPLES)
        points = frames.coils_from_workspace(tracked_at(shape, inserted, along),
                                             self.insertion_point)
        return paths.shape_error(points, self.path, inserted)

    def publish_progress(self):
        """Publish /player/progress (during a run) and the player's /diagnostics status."""
        if self.player is None:
            waiting = self.waiting_for()
            self._publish_status('warn' if waiting else 'ok',
                                 f'waiting for {", ".join(waiting)}' if waiting else 'ready',
                                 {'phase': 'idle', 'mode': self.loop['mode']})
            return
        step, count = self.player.step, len(self.schedule.steps)
        shape_rms, tip_error = self.tracked_errors()
        msg = JointState(name=list(contract.PROGRESS_NAMES),
                         position=[float(step.index), float(count), float(step.inserted_m),
                                   float(shape_rms), float(tip_error)])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.progress_pub.publish(msg)
        phase = self.player.phase
        level = 'ok' if phase not in (Phase.PAUSED, Phase.ABORTED) else \
            ('warn' if self.player.reason == 'asked to' else 'error')
        values = {'phase': phase.value, 'step': step.index, 'steps': count,
                  'inserted_mm': f'{step.inserted_m * 1e3:.3f}', 'mode': self.loop['mode'],
                  'schedule': str(self.schedule.source), **self.gate.figures.values()}
        self._publish_status(level, phase.value + (f': {self.player.reason}'
                                                   if self.player.reason else ''), values)

    def _publish_status(self, level, message, values):
        diag = DiagnosticArray(status=[diagnostic_status(f'{NODE_NAME}: run', NODE_NAME, level,
                                                         message, values)])
        diag.header.stamp = self.get_clock().now().to_msg()
        self.diag_pub.publish(diag)

    def housekeeping(self):
        """Ask coils_node for its limits; look for other publishers of /coils/field_cmd."""
        if self.coils_params.services_are_ready() and (
                self.coils_max_field is None or self._ticks % 5 == 0):
            future = self.coils_params.get_parameters(['max_field'])
            future.add_done_callback(self._got_coils_limits)
        self._ticks += 1
        mine = self.get_fully_qualified_name()
        self._others = sorted({_name_of(i) for i in self.get_publishers_info_by_topic(
            contract.FIELD_CMD.name)} - {mine})

    def _got_coils_limits(self, future):
        try:
            values = future.result().values
        except Exception:   # noqa: BLE001 - coils_node went away: keep the last known
            return
        if values and values[0].type == 3:   # PARAMETER_DOUBLE
            self.coils_max_field = values[0].double_value

    def shutdown(self):
        """Abort a run that still commands the rig; return the line said at exit."""
        if self.player is None or self.player.phase is Phase.IDLE or self.player.field_t is None:
            return 'no run commanding the rig'
        self.apply(self.player.abort(time.monotonic(), 'the player is stopping', self.seen))
        return 'run aborted: zero field commanded, moving stages stopped'


def main(args=None):
    """Run the node; on exit a run still commanding is aborted."""
    argv = sys.argv[1:] if args is None else args
    run_node(argv, NODE_NAME, PLAYER_PARAMS + LOOP_PARAMS, __doc__, PlayerNode,
             PlayerNode.shutdown)


if __name__ == '__main__':
    main()
