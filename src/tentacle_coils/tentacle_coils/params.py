"""
The coils node's parameters, in one table: name, default, range, unit, description.

Plain data (no rclpy): the node declares every row with a descriptor, ``coils_node --help``
prints the table, and tests read it. Names are those of DESIGN.md; units are in the
descriptions. What a lab writes is checked against it before rcl reads it
(tentacle_common.params): integers given for doubles (40 for 40.0, also in arrays) are
converted, and a misspelt name is warned about, naming it.
"""

from tentacle_common import params as common
from tentacle_common.params import Param

NODE_NAME = 'coils_node'
REFERENCE_MATRIX_T_PER_A = (0.53e-3, 0.0, 0.0,
                            0.0, 1.07e-3, 0.0,
                            0.0, 0.0, 0.65e-3)


COILS_PARAMS = (
    Param('ports', ['/dev/ttyUSB0', '/dev/ttyUSB1', '/dev/ttyUSB2'],
          'serial device paths of the x, y and z supplies'),
    Param('dialect', 'dxkdp', 'supply wire dialect: dxkdp or scpi'),
    Param('baud', 9600, 'serial line rate, bit/s', 300, 4_000_000),
    Param('addresses', [1, 1, 1], 'dxkdp bus address of each supply (x, y, z)', 0, 255),
    Param('polarity_inverted', [False, False, False],
          'per supply: wired reversed, so the sign is flipped at the wire'),
    Param('polarity_mode', 'signed',
          "dxkdp: signed (second generation, two's complement current) or command "
          '(first generation, polarity by command 0x24)'),
    Param('actuation_matrix', list(REFERENCE_MATRIX_T_PER_A),
          'B = A @ I + field_offset: 3x3 row-major, tesla per ampere'),
    Param('field_offset', [0.0, 0.0, 0.0], 'field at zero current (x, y, z), tesla'),
    Param('max_current', 40.0, 'largest current magnitude per supply, ampere', 0.0, 300.0),
    Param('max_field', 0.022, 'largest field component per axis, tesla', 0.0, 0.2),
    Param('clamp', False,
          'scale an over-limit command down (keeping its direction) instead of rejecting it'),
    Param('slew_rate', 200.0, 'largest rate of change of each current, ampere per second',
          0.001, 1.0e6),
    Param('watchdog_s', 1.0, 'ramp to zero after this long without a field command, second',
          0.01, 86400.0),
    Param('publish_rate', 20.0,
          'rate of /coils/currents and /coils/field, and of current readbacks, hertz',
          0.1, 200.0),
    Param('retries', 3, 'attempts after the first before a command counts as failed', 0, 20),
    Param('reply_timeout_s', 0.1,
          "wait for a reply beyond the bytes' own wire time, second", 0.001, 5.0),
    Param('max_turnaround_s', 0.25,
          "the supplies' worst time to answer, second: after a timeout the line must be quiet "
          'this long before the next request, so a late reply never answers a later one',
          0.001, 5.0),
    Param('voltage_limit', 30.0, 'compliance voltage programmed into dxkdp supplies, volt',
          0.0, 650.0),
    Param('auto_enable', True,
          'energise the outputs (at zero current) once every supply is connected'),
)


def check_params_file(path):
    """Check a params file against the table; see tentacle_common.params."""
    return common.check_params_file(path, NODE_NAME, COILS_PARAMS)


def check_ros_args(argv):
    """Check --ros-args against the table; see tentacle_common.params."""
    return common.check_ros_args(argv, NODE_NAME, COILS_PARAMS)
