"""
player_node's parameters, in two tables: fixed for the node's life, and those set any time.

Plain data (no rclpy). ``PLAYER_PARAMS`` are read when the node starts; ``LOOP_PARAMS`` may
be set while the node runs: ``schedule`` (read at the next start, so a new plan needs no
restart), ``mode``, the loop's gains and tolerances (the next correction uses them).
"""

import math

from tentacle_common.params import Param

NODE_NAME = 'player_node'
MODES = ('open_loop', 'closed_loop', 'tip_angle', 'coiling')
REFERENCES = ('path', 'planned')

PLAYER_PARAMS = (
    Param('tentacle', '', "the rig's tentacle file: a schedule planned for another tentacle "
          'is refused (empty: not checked, and said so at start)'),
    Param('coils_node', 'coils_node', "the coil driver's node name: its max_field is asked "
          'for and a schedule over it refused'),
    Param('max_field', 0.022, 'largest field component per axis a schedule may use, tesla',
          0.0, 0.2),
    Param('max_total_field', 0.030, 'largest |B| a schedule may use, tesla', 0.0, 0.35),
    Param('max_field_change', 0.015, 'largest change of a field component from one step to '
          'the next (and from and to zero), tesla', 0.0, 0.35),
    Param('insertion_offset_m', 0.0, "the inserter stage's position with the tip at the "
          'insertion point, metre', -1.0, 1.0),
    Param('backbone', True, 'command the backbone stage where the schedule has its reach '
          '(/backbone/target)'),
    Param('stage_speed', 0.005, "the stages' speed, metre per second (a move's expected time)",
          1e-6, 1.0),
    Param('dwell_s', 0.3, 'at a step once the stages and the field have arrived, second',
          0.0, 60.0),
    Param('position_tolerance', 2e-5, 'a stage within this of its target has arrived, metre',
          1e-7, 0.01),
    Param('field_tolerance', 2e-4, 'the field read back within this per axis has arrived, '
          'tesla', 1e-6, 0.01),
    Param('settle_timeout_s', 2.0, "a step's deadline beyond its move's own time, second",
          0.1, 600.0),
    Param('feedback_timeout_s', 1.0, 'a reading (field, stage state, and in closed loop the '
          'tracked shape) older than this is a fault, second', 0.05, 60.0),
    Param('on_fault', 'pause', 'a fault mid-run (estop, a driver error, a reading lost, a '
          'deadline missed): pause (hold, resume later) or abort (zero field, stop)'),
    Param('hold_rate', 5.0, "the field held is sent again this often (coils_node's watchdog), "
          'hertz', 1.5, 100.0),
    Param('progress_rate', 5.0, '/player/progress and /diagnostics, hertz', 0.1, 100.0),
)

LOOP_PARAMS = (
    Param('schedule', '', 'the schedule file to play (tentacle-plan --out DIR writes '
          'DIR/schedule.yaml); read at every start'),
    Param('mode', 'open_loop', 'open_loop (the schedule as planned), closed_loop (the '
          'tracked shape corrects the field), tip_angle (thesis eq. 6.10 on the tip heading) '
          "or coiling (chapter 6: eq. 6.10 on how far the body turns, the step's planned "
          'turn the target, up to coil_feedback_max; open loop beyond)'),
    Param('reference', 'path', 'closed_loop follows: path (the desired path, as the shape '
          "error is measured) or planned (the step's planned centreline)"),
    Param('loop_min_inserted', 0.003, 'the loop acts from this inserted length on (shorter, '
          'the camera sees too little of the body), metre', 0.0, 1.0),
    Param('loop_rate', 30.0, 'the most corrections per second, hertz', 0.1, 100.0),
    Param('loop_settle_s', 0.02, 'a frame counts once taken this long after the last field '
          'command (the coils slewing), second', 0.0, 5.0),
    Param('gain', 1.0, 'closed_loop: the fraction of the Gauss-Newton step taken', 0.0, 1.0),
    Param('damping', 1e-3, "closed_loop: Tikhonov damping, relative to the sensitivity's "
          'scale', 0.0, 1e3),
    Param('max_step', 0.003, 'the largest change of a field component per correction, tesla',
          1e-6, 0.05),
    Param('tolerance', 1e-4, 'closed_loop: converged below this shape RMS, metre', 0.0, 0.01),
    Param('max_iterations', 8, 'corrections per step at most', 0, 1000),
    Param('stall_ratio', 0.9, 'closed_loop: converged too once a correction cut the error by '
          'less than this factor', 0.0, 1.0),
    Param('tip_gain', 0.5, "tip_angle, coiling: eq. 6.10's K_P", 0.0, 5.0),
    Param('tip_tolerance', math.radians(5.0), 'tip_angle, coiling: converged below this tip '
          'angle error, radian', 0.0, math.pi),
    Param('coil_feedback_max', math.radians(220.0), 'coiling: the feedback ends where a step '
          'is planned to turn further (the tip closes the coil, out of sight), radian', 0.0,
          4.0 * math.pi),
)
