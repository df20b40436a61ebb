"""
Params files on disk: read them bounded, parse them strictly, edit them line by line.

Plain code (no rclpy), for nodes and for the tools that run without ROS:

- ``read_text`` (and ``read_bytes``) refuse what is not a regular file (a FIFO would hang,
  /dev/zero would fill memory) before opening it, and read at most ``MAX_FILE_BYTES``.
- ``load`` parses YAML with ``StrictLoader``, which refuses a key given twice in one mapping
  (PyYAML keeps the last silently), naming the key and both lines.
- ``set_flow_list`` puts ``key: [numbers]`` into a node's ``ros__parameters`` by editing only
  the lines of that key, so comments and the rest of the file stay as they were; the edited
  text is parsed again and refused unless exactly that value changed.
"""

import copy
import os
import stat

import yaml
from yaml.constructor import ConstructorError

MAX_FILE_BYTES = 1 << 20  # a params file is a few kB; this is far beyond any real one


class FileRefused(ValueError):
    """A file is not one to read: not a regular file, too large, not UTF-8, not YAML."""


class DuplicateKeyError(ConstructorError):
    """A mapping gives the same key twice."""

    def __init__(self, key, line, first_line, mark):
        """Key and the 1-based lines of its second and first appearance."""
        super().__init__(None, None, f'duplicate key {key!r} at line {line} (first at line '
                         f'{first_line})', mark)
        self.key, self.line, self.first_line = key, line, first_line


class StrictLoader(yaml.SafeLoader):
    """A SafeLoader that refuses a key given twice in one mapping."""

    def construct_mapping(self, node, deep=False):
        """Check the mapping's own keys for repeats, then construct it as SafeLoader does."""
        if isinstance(node, yaml.MappingNode):
            seen = {}
            for key_node, _ in node.value:
                if key_node.tag == 'tag:yaml.org,2002:merge':
                    continue  # '<<' may bring keys this mapping then overrides: allowed
                key = self.construct_object(key_node, deep=True)
                line = key_node.start_mark.line + 1
                try:
                    if key in seen:
                        raise DuplicateKeyError(key, line, seen[key], key_node.start_mark)
                    seen[key] = line
                except TypeError:
                    continue  # an unhashable key: SafeLoader's own error follows
        return super().construct_mapping(node, deep=deep)


def read_bytes(path, max_bytes=MAX_FILE_BYTES):
    """
    Return a regular file's bytes, refusing anything else before opening it.

    :param max_bytes: larger files are refused
    :raises FileRefused: not a regular file, or too large (the message says which, without
        the path: the caller names the file)
    :raises OSError: missing, unreadable
    """
    # stat before open: opening a serial device already toggles its DTR line, a FIFO blocks.
    if not stat.S_ISREG(os.stat(path).st_mode):
        raise FileRefused('not a regular file (a device, FIFO or folder)')
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, 'O_CLOEXEC', 0))
    with os.fdopen(fd, 'rb') as handle:
        if not stat.S_ISREG(os.fstat(handle.fileno()).st_mode):  # replaced since the stat
            raise FileRefused('not a regular file (a device, FIFO or folder)')
        data = handle.read(max_bytes + 1)
    if len(data) > max_bytes:
        raise FileRefused(f'larger than {max_bytes} bytes')
    return data


def read_text(path, max_bytes=MAX_FILE_BYTES, encoding='utf-8'):
    """
    Return a regular file's text; see read_bytes.

    :param encoding: 'utf-8-sig' also drops a leading byte-order mark (Excel's CSV UTF-8)
    :raises FileRefused: not a regular file, too large, or not valid text
    :raises OSError: missing, unreadable
    """
    data = read_bytes(path, max_bytes)
    try:
        return data.decode(encoding)
    except UnicodeDecodeError as exc:
        raise FileRefused(f'not UTF-8 text (byte 0x{data[exc.start]:02x} at offset '
                          f'{exc.start})') from None


def load(text):
    """
    Parse YAML text with StrictLoader.

    :raises FileRefused: not YAML, or a key given twice (its name and lines in the message)
    """
    try:
        return yaml.load(text, Loader=StrictLoader)
    except DuplicateKeyError as exc:
        raise FileRefused(exc.problem) from None
    except yaml.YAMLError as exc:
        raise FileRefused(f'not YAML: {exc}') from None


def read_yaml(path, max_bytes=MAX_FILE_BYTES):
    """Return the strictly parsed document of a YAML file; see read_text and load."""
    return load(read_text(path, max_bytes))


def number(value):
    """Return a float as YAML text PyYAML reads back as a float (``1e-05`` it reads as text)."""
    text = f'{float(value):.9g}'
    mantissa, e, exponent = text.partition('e')
    if '.' not in mantissa and mantissa.lstrip('-').isdigit():
        mantissa += '.0'
    return mantissa + e + exponent


def flow_list(values, per_line=None, indent=0):
    """Return numbers as a YAML flow list, ``per_line`` to a line, continued at ``indent``."""
    items = [number(v) for v in values]
    per_line = per_line or len(items) or 1
    rows = [', '.join(items[i:i + per_line]) for i in range(0, len(items), per_line)]
    return '[' + (',\n' + ' ' * indent).join(rows) + ']'


def _indent(line):
    return len(line) - len(line.lstrip(' '))


def _content(line):
    """Return a line without its comment and trailing space ('' for blank or comment)."""
    stripped = line.strip()
    return '' if not stripped or stripped.startswith('#') else line.rstrip()


def _bare(line):
    """Return a line's text without indentation and a trailing `` # comment``."""
    return _content(line).split(' #', 1)[0].strip()


def _block_end(lines, start, indent):
    """Return the index after the block of lines deeper than ``indent`` after ``start``."""
    end = start + 1
    last = start + 1
    while end < len(lines):
        content = _content(lines[end])
        if content:
            if _indent(lines[end]) <= indent:
                break
            last = end + 1
        end += 1
    return last


def _sequence_end(lines, start, indent):
    """Return the index after the '- ' items at ``indent`` that follow line ``start``."""
    end = last = start + 1
    while end < len(lines):
        content = _content(lines[end])
        if content:
            if _indent(lines[end]) < indent or (
                    _indent(lines[end]) == indent and not content.lstrip().startswith('-')):
                break
            last = end + 1
        end += 1
    return last


def _find_key(lines, start, end, key, indent=None):
    """Return the indices of the ``key:`` lines among lines[start:end] (at ``indent``)."""
    found = []
    for i in range(start, end):
        content = _content(lines[i])
        if content and (indent is None or _indent(lines[i]) == indent) and (
                _bare(lines[i]) == f'{key}:' or content.strip().startswith(f'{key}: ')
                or content.strip().startswith(f'{key}:[')):
            found.append(i)
    return found


def set_flow_list(text, node_name, key, values, per_line=None):
    """
    Return params-file text with ``node_name.ros__parameters.key`` set to a list of numbers.

    Only the lines of that key change (it is added at the end of the section, or a section is
    appended, when missing); comments and every other line are kept. The result is parsed
    again and must differ from the original in exactly that value.

    :param per_line: numbers per line of the written list (all on one line by default)
    :raises FileRefused: the text is not a params file, or its layout is not one this can
        edit safely (the message says so; the caller can tell the user what to paste)
    """
    before = load(text) if text.strip() else {}
    if before is None:
        before = {}
    if not isinstance(before, dict):
        raise FileRefused('not a mapping of node names to ros__parameters')
    lines = text.splitlines(keepends=True)
    if lines and not lines[-1].endswith('\n'):
        lines[-1] += '\n'
    sections = [i for i, line in enumerate(lines) if _content(line) and _indent(line) == 0
                and _bare(line) in (f'{node_name}:', f'/{node_name}:')]
    if len(sections) > 1:
        raise FileRefused(f'{node_name} appears {len(sections)} times')
    if not sections:
        if node_name in before or f'/{node_name}' in before:
            raise FileRefused(f'its {node_name} section is not in block style')
        body = f'  ros__parameters:\n    {key}: {flow_list(values, per_line, 4 + len(key) + 3)}\n'
        lines += [f'{node_name}:\n', body]
    else:
        top = sections[0]
        top_end = _block_end(lines, top, 0)
        params = _find_key(lines, top + 1, top_end, 'ros__parameters')
        if len(params) != 1 or _bare(lines[params[0]]) != 'ros__parameters:':
            raise FileRefused(f'{node_name} has no block-style ros__parameters')
        p = params[0]
        p_indent = _indent(lines[p])
        p_end = _block_end(lines, p, p_indent)
        children = [i for i in range(p + 1, p_end) if _content(lines[i])]
        child_indent = _indent(lines[children[0]]) if children else p_indent + 2
        found = _find_key(lines, p + 1, p_end, key, child_indent)
        if len(found) > 1:
            raise FileRefused(f'{key} appears {len(found)} times in {node_name}')
        prefix = ' ' * child_indent + f'{key}: '
        new = prefix + flow_list(values, per_line, len(prefix) + 1)
        if found:
            i = found[0]
            end = _block_end(lines, i, child_indent)
            if _bare(lines[i]) == f'{key}:':  # a block list, maybe indentless
                end = max(end, _sequence_end(lines, i, child_indent))
            comment = ''
            last = lines[end - 1].rstrip('\n')
            tail = last[last.rfind(']') + 1:] if ']' in last else ''
            if tail.strip().startswith('#'):
                comment = '  ' + tail.strip()  # the comment after the list stays
            lines[i:end] = [new + comment + '\n']
        else:
            lines[p_end:p_end] = [new + '\n']
    edited = ''.join(lines)
    try:
        after = load(edited)
    except FileRefused:
        after = None
    expected = _with_value(before, node_name, key, [float(number(v)) for v in values])
    if after != expected:
        raise FileRefused(f'its layout is not one this tool can edit safely (editing '
                          f'{node_name}.ros__parameters.{key} would change other values)')
    return edited


def _with_value(document, node_name, key, value):
    """Return a deep copy of a params document with one value set (the section made)."""
    document = copy.deepcopy(document)
    name = f'/{node_name}' if f'/{node_name}' in document else node_name
    section = document.get(name) or {}
    params = section.get('ros__parameters') or {} if isinstance(section, dict) else None
    if not isinstance(params, dict):
        raise FileRefused(f'its {name} section is not a ros__parameters mapping')
    document[name] = section
    section['ros__parameters'] = params
    params[key] = value
    return document


def write_text(path, text):
    """
    Replace a file's text in one step (a temporary file beside it, then a rename).

    A crash mid-write leaves the old file, never half a config; the file's mode is kept.

    :raises OSError: the folder cannot be written, or the path is a folder
    """
    target = os.path.realpath(path)
    if os.path.isdir(target):
        raise IsADirectoryError(21, 'Is a directory', path)
    mode = stat.S_IMODE(os.stat(target).st_mode) if os.path.exists(target) else None
    temporary = f'{target}.tmp{os.getpid()}'
    try:
        with open(temporary, 'w', encoding='utf-8') as handle:
            handle.write(text)
        if mode is not None:
            os.chmod(temporary, mode)
        os.replace(temporary, target)
    except BaseException:
        if os.path.exists(temporary):
            os.unlink(temporary)
        raise
