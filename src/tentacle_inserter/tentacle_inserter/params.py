"""
The inserter node's parameters, in one table: name, default, range, unit, description.

Plain data (no rclpy), as tentacle_coils/params.py: the node declares every row with a
descriptor, ``inserter_node --help`` prints the table, and what a lab writes is checked
against it before rcl reads it. Names are those of DESIGN.md; units are in the descriptions.
"""

from tentacle_common.contract import is_name_token
from tentacle_common.errors import ConfigError
from tentacle_common.params import Param

NODE_NAME = 'inserter_node'

INSERTER_PARAMS = (
    Param('port', '/dev/ttyACM0', 'serial device path of the stage'),
    Param('dialect', 'gcode', 'stage wire dialect: gcode or step1mm'),
    Param('baud', 115200, 'serial line rate, bit/s (step1mm: 9600)', 300, 4_000_000),
    Param('axis', 'inserter', 'topic namespace, one ROS name token (letters, digits, _): '
          '/<axis>/target, /<axis>/state, ...'),
    Param('max_length', 0.1, 'soft limit: targets in [0, max_length], metre', 0.0, 10.0),
    Param('max_speed', 0.005, 'speed of every move, metre per second (step1mm: the '
          "firmware's own, for the moves' expected time)", 1e-6, 1.0),
    Param('acceleration', 0.5, "the firmware's acceleration, metre per second squared",
          1e-6, 100.0),
    Param('steps_per_mm', 100.0, 'gcode: motor steps per mm, sent with M92 at connect',
          1e-3, 1e6),
    Param('reply_timeout_s', 0.5, 'wait for a reply to a command, second', 0.001, 10.0),
    Param('retries', 2, 'attempts after the first before a command counts as failed', 0, 20),
    Param('time_margin', 1.5, 'a move may take its expected time times this', 1.0, 100.0),
    Param('slack_s', 0.5, '... plus this before it counts as stalled, second', 0.0, 60.0),
    Param('restart_timeout_s', 5.0, 'gcode: wait for a firmware that restarts after M112 '
          '(M999 refused), and for a first answer after the port opens, second', 0.0, 120.0),
    Param('state_rate', 20.0, 'rate of /<axis>/state, hertz', 0.1, 1000.0),
    Param('step1mm_extend', '2',
          "step1mm: the character that extends 1 mm (earlier lab code: '1')"),
    Param('step1mm_retract', '1', "step1mm: the character that retracts 1 mm (earlier: '2')"),
    Param('step1mm_stop', '3', 'step1mm: the character that stops'),
)


def check_axis(axis):
    """
    Return the axis name without surrounding slashes if it is one ROS name token.

    :raises ConfigError: anything else (it becomes /<axis>/target, /<axis>/state, ...)
    """
    name = str(axis).strip('/')
    if not is_name_token(name):
        raise ConfigError(f'axis: {axis!r} is not a ROS name token (letters, digits and _, '
                          f'not starting with a digit), as its topics /<axis>/target, '
                          '/<axis>/state, ... need: e.g. inserter or backbone')
    return name
