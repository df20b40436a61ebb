"""
Parameter tables: one row per parameter (name, default, range, unit in the description).

Plain data (no rclpy): a node declares every row with a descriptor (driver_node.py),
``--help`` prints the table (``describe``), and what a lab writes in a params file or with
``-p`` is checked against it before rcl reads it (``check_ros_args``): integers given for
doubles are converted (rcl refuses 40 for a double, and a sequence mixing 0 and 0.53e-3), an
integer given for text becomes its digits (ROS reads ``source:=0`` as an integer), a misspelt
name is warned about with a suggestion, and a value of the wrong type or out of its range
(each element of a list) is an error naming the file and the parameter. A tool without ROS
(``resolve``) refuses a misspelt name outright. Params files are read bounded and parsed
strictly (tentacle_common.yaml_files: no device or FIFO, no key given twice).
"""

from dataclasses import dataclass
import difflib
import json

from tentacle_common.errors import ConfigError
from tentacle_common.yaml_files import FileRefused, load, read_text
import yaml


@dataclass(frozen=True)
class Param:
    """One parameter: its default fixes its type; low/high bound numbers (inclusive)."""

    name: str
    default: object
    description: str
    low: float | None = None
    high: float | None = None


def describe(params):
    """Return the table as text for ``--help``."""
    lines = []
    for p in params:
        bounds = (f' [{p.low:g}, {p.high:g}]' + (' each' if isinstance(p.default, list)
                                                 else '')) if p.low is not None else ''
        lines.append(f'  {p.name} (default {p.default!r}){bounds}\n      {p.description}')
    return '\n'.join(lines)


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
        if kind is str and type(v) is int:
            return str(v)  # a device index or a number-like name, as ROS parsed it
        if type(v) is not kind:  # bool is an int in Python, not in ROS
            raise ValueError(f'{v!r} is not {"an integer" if kind is int else kind.__name__}')
        return v

    if isinstance(p.default, list):
        if not isinstance(value, list):
            raise ValueError(f'{value!r} is not a list')
        return [exact(type(p.default[0]), v) for v in value]
    return exact(type(p.default), value)


def out_of_range(p, value):
    """Return why a (coerced) value is outside p's bounds, each element of a list; or ''."""
    if p.low is None:
        return ''
    bounds = f'[{p.low:g}, {p.high:g}]'
    if isinstance(value, list):
        for i, v in enumerate(value):
            if not p.low <= v <= p.high:
                return f'element {i} is {v!r}, outside {bounds}'
        return ''
    return '' if p.low <= value <= p.high else f'{value!r} is outside {bounds}'


def checked(p, value):
    """
    Return value coerced to p's type and within p's bounds (each element of a list).

    :raises ValueError: the wrong type, or out of range; the message says which
    """
    value = _coerce(p, value)
    problem = out_of_range(p, value)
    if problem:
        raise ValueError(problem)
    return value


def _suggestion(name, table):
    close = difflib.get_close_matches(name, [p.name for p in table], n=1)
    return f' (did you mean {close[0]}?)' if close else ''


def _own_section(section, node_name):
    """Return 'node' for this node's own section, 'all' for a wildcard, '' otherwise."""
    name = str(section).lstrip('/')
    if name == node_name or name.endswith('/' + node_name):
        return 'node'
    return 'all' if name in ('**', '*') else ''


def check_params_file(path, node_name, table, unknown='warn'):
    """
    Read a ROS params file and check this node's parameters in it against the table.

    :param unknown: 'warn' (a node: rcl ignores the name, the node logs the warning) or
        'refuse' (a tool: a misspelt name is an error, with the nearest known name)
    :return: (the document, with integers in double parameters made doubles; warnings, one
        per unknown parameter in this node's section; whether anything was converted)
    :raises ConfigError: the file is missing, unreadable, not a regular file, larger than
        tentacle_common.yaml_files.MAX_FILE_BYTES or not a params file, gives a key twice, or
        a parameter has a value of the wrong type or out of range; the message names the file
        and the parameter
    """
    try:
        document = load(read_text(path))
    except OSError as exc:
        raise ConfigError(f'params file {path}: cannot be read: '
                          f'{exc.strerror or exc}') from None
    except FileRefused as exc:
        raise ConfigError(f'params file {path}: {exc}') from None
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
                if kind == 'node' and unknown == 'refuse':
                    raise ConfigError(f'params file {path}: {name} is not a {node_name} '
                                      f'parameter{_suggestion(name, table)}')
                if kind == 'node':
                    warnings.append(f'params file {path}: {name} is not a {node_name} '
                                    f'parameter{_suggestion(name, table)}: ignored')
                continue
            try:
                coerced = checked(p, value)
            except ValueError as exc:
                raise ConfigError(f'params file {path}: {name}: {exc}') from None
            if coerced != value or type(coerced) is not type(value) or (
                    isinstance(value, list) and any(
                        type(a) is not type(b) for a, b in zip(coerced, value))):
                params[name] = coerced
                changed = True
    return document, warnings, changed


def check_ros_args(argv, node_name, table):
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
                value = checked(by_name[name], yaml.safe_load(text))
            except (ValueError, yaml.YAMLError) as exc:
                raise ConfigError(f'-p {name}: {exc}') from None
            argv[i + 1] = f'{owner + ":" if owner else ""}{name}:=' + json.dumps(value)
    return argv, warnings, rewrite


def resolve(table, node_name, params_file=None, overrides=None):
    """
    Return {name: value} as a node would get them, for a tool that runs without ROS.

    Defaults, then this node's section of a params file, then ``overrides``; each value is
    checked against its row's type and range (each element of a list).

    :raises ConfigError: a bad file or one with no section for this node, an unknown name in
        this node's section or in the overrides (the nearest known name suggested), or a
        value of the wrong type or out of range, named
    """
    by_name = {p.name: p for p in table}
    values = {p.name: p.default for p in table}
    if params_file is not None:
        document, _, _ = check_params_file(params_file, node_name, table, unknown='refuse')
        own = [section for section in document if _own_section(section, node_name)]
        if not own:  # the defaults would stand in silently for what the file meant to say
            raise ConfigError(f'params file {params_file}: no {node_name} section (it has: '
                              f'{", ".join(map(str, document)) or "none"})')
        for section in own:
            values.update({k: v for k, v in document[section]['ros__parameters'].items()
                           if k in by_name})
    for name, value in (overrides or {}).items():
        if name not in by_name:
            raise ConfigError(f'{name}: not a {node_name} parameter{_suggestion(name, table)}')
        try:
            values[name] = checked(by_name[name], value)
        except ValueError as exc:
            raise ConfigError(f'{name}: {exc}') from None
    for name, value in values.items():
        problem = out_of_range(by_name[name], value)
        if problem:  # a default outside its own row's range: the table is wrong
            raise ConfigError(f'{name}: {problem}')
    return values
