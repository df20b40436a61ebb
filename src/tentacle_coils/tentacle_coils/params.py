"""
The coils node's parameters, in one table: name, default, range, unit, description.

Plain data (no rclpy): the node declares every row with a descriptor, ``coils_node --help``
prints the table, and tests read it. Names are those of DESIGN.md; units are in the
descriptions. ROS parameters are typed; integers given for doubles (40 for 40.0, also in
arrays) are converted before rcl reads them (``check_ros_args``), and a misspelt name is
warned about, naming it.
"""

from dataclasses import dataclass
import difflib
import json
import pathlib

from tentacle_coils.errors import ConfigError
import yaml

REFERENCE_MATRIX_T_PER_A = (0.53e-3, 0.0, 0.0,
                            0.0, 1.07e-3, 0.0,
                            0.0, 0.0, 0.65e-3)


@dataclass(frozen=True)
class Param:
    """One parameter: its default fixes its type; low/high bound numbers (inclusive)."""

    name: str
    default: object
    description: str
    low: float | None = None
    high: float | None = None


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


def describe(params=COILS_PARAMS):
    """Return the table as text for ``--help``."""
    lines = []
    for p in params:
        bounds = f' [{p.low:g}, {p.high:g}]' if p.low is not None else ''
        lines.append(f'  {p.name} (default {p.default!r}){bounds}\n      {p.description}')
    return '\n'.join(lines)


# -- checking what a lab writes, before rcl reads it ---------------------------------------
MAX_EXACT_INT = 2 ** 53  # integers up to this convert to doubles exactly


def _coerce(p, value):
    """
    Return value as the type of p's default, converting only where that is exact.

    Integers are accepted for doubles, also inside arrays (rcl refuses a sequence that
    mixes 0 and 0.53e-3), and numbers PyYAML reads as text (``5e-3`` has no dot) as well.

    :raises ValueError: a value of another type, or a double that is not finite
    """
    def as_double(v):
        if isinstance(v, bool):
            raise ValueError(f'{v!r} is not a number')
        if isinstance(v, int):
            if abs(v) > MAX_EXACT_INT:
                raise ValueError(f'{v} is too large to be a double exactly')
            return float(v)
        if isinstance(v, str):
            try:
                v = float(v)
            except ValueError:
                raise ValueError(f'{v!r} is not a number') from None
        if not isinstance(v, float):
            raise ValueError(f'{v!r} is not a number')
        if v != v or v in (float('inf'), float('-inf')):
            raise ValueError(f'{v} is not finite')
        return v

    def exact(kind, v):
        if kind is float:
            return as_double(v)
        if type(v) is not kind:  # bool is an int in Python, not in ROS
            raise ValueError(f'{v!r} is not {"an integer" if kind is int else kind.__name__}')
        return v

    if isinstance(p.default, list):
        if not isinstance(value, list):
            raise ValueError(f'{value!r} is not a list')
        return [exact(type(p.default[0]), v) for v in value]
    return exact(type(p.default), value)


def _suggestion(name, table):
    close = difflib.get_close_matches(name, [p.name for p in table], n=1)
    return f' (did you mean {close[0]}?)' if close else ''


def _own_section(section, node_name):
    """Return 'node' for this node's own section, 'all' for a wildcard, '' otherwise."""
    name = str(section).lstrip('/')
    if name == node_name or name.endswith('/' + node_name):
        return 'node'
    return 'all' if name in ('**', '*') else ''


def check_params_file(path, node_name='coils_node', table=COILS_PARAMS):
    """
    Read a ROS params file and check this node's parameters in it against the table.

    :return: (the document, with integers in double parameters made doubles; warnings, one
        per unknown parameter in this node's section; whether anything was converted)
    :raises ConfigError: the file is missing, unreadable or not a params file, or a
        parameter has a value of the wrong type; the message names the file and parameter
    """
    try:
        text = pathlib.Path(path).read_text(encoding='utf-8')
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f'params file {path}: cannot be read: '
                          f'{getattr(exc, "strerror", None) or exc}') from None
    try:
        document = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ConfigError(f'params file {path}: not YAML: {exc}') from None
    if not isinstance(document, dict):
        raise ConfigError(f'params file {path}: not a mapping of node names to '
                          'ros__parameters')
    by_name = {p.name: p for p in table}
    warnings, changed = [], False
    for section, body in document.items():
        kind = _own_section(section, node_name)
        if not kind:
            continue
        params = body.get('ros__parameters') if isinstance(body, dict) else None
        if not isinstance(params, dict):
            raise ConfigError(f'params file {path}: {section}: no ros__parameters mapping')
        for name, value in params.items():
            p = by_name.get(name)
            if p is None:
                if kind == 'node':
                    warnings.append(f'params file {path}: {name} is not a {node_name} '
                                    f'parameter{_suggestion(name, table)}: ignored')
                continue
            try:
                coerced = _coerce(p, value)
            except ValueError as exc:
                raise ConfigError(f'params file {path}: {name}: {exc}') from None
            if coerced != value or type(coerced) is not type(value) or (
                    isinstance(value, list) and any(
                        type(a) is not type(b) for a, b in zip(coerced, value))):
                params[name] = coerced
                changed = True
    return document, warnings, changed


def check_ros_args(argv, node_name='coils_node', table=COILS_PARAMS):
    """
    Check the parameters that ``--ros-args`` give: params files and ``-p NAME:=VALUE``.

    :param argv: the command line after the program name
    :return: (argv to hand to rclpy, warnings, {index in argv: normalised params document}
        for each params file that needed conversions: write it out and put its path there)
    :raises ConfigError: see check_params_file; also a -p value of the wrong type
    """
    argv = list(argv)
    warnings, rewrite = [], {}
    by_name = {p.name: p for p in table}
    in_ros_args = False
    for i, arg in enumerate(argv):
        if arg == '--ros-args':
            in_ros_args = True
        elif arg == '--':
            in_ros_args = False
        elif in_ros_args and arg == '--params-file' and i + 1 < len(argv):
            document, found, changed = check_params_file(argv[i + 1], node_name, table)
            warnings += found
            if changed:
                rewrite[i + 1] = document
        elif in_ros_args and arg in ('-p', '--param') and i + 1 < len(argv):
            name, sep, text = argv[i + 1].partition(':=')
            owner, _, name = name.rpartition(':')
            if not sep or owner not in ('', node_name):
                continue
            if name not in by_name:
                warnings.append(f'-p {name}: not a {node_name} parameter'
                                f'{_suggestion(name, table)}: ignored')
                continue
            try:
                value = _coerce(by_name[name], yaml.safe_load(text))
            except (ValueError, yaml.YAMLError) as exc:
                raise ConfigError(f'-p {name}: {exc}') from None
            argv[i + 1] = f'{owner + ":" if owner else ""}{name}:=' + json.dumps(value)
    return argv, warnings, rewrite
