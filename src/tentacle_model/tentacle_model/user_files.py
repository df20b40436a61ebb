"""
Reading the files people write (tentacle files, scenes, paths): capped, and every refusal named.

``read_capped`` reads a regular file of no more than a limit (a FIFO, a device or a
directory is refused before a byte is read, a huge file at once, not read for minutes);
``load_yaml`` parses YAML strictly (a key given twice is refused, naming it and its line,
where PyYAML would keep the last silently); ``FieldReader`` gives typed access to a parsed
YAML document and refuses a value with the file and the path of the key in the message,
raising the caller's error.
"""

import math
import os
import stat

import numpy as np
from tentacle_common.yaml_files import StrictLoader
import yaml

_KINDS = ((stat.S_ISDIR, 'a directory'), (stat.S_ISFIFO, 'a FIFO (named pipe)'),
          (stat.S_ISCHR, 'a character device'), (stat.S_ISBLK, 'a block device'),
          (stat.S_ISSOCK, 'a socket'))


def read_capped(path, limit_bytes, error, what):
    """
    Return a file's bytes, reading at most limit_bytes + 1.

    :param error: the exception class to raise (message: the path, then the reason)
    :param what: what kind of file, for the message ('a tentacle file')
    :raises error: a file that cannot be opened, is not a regular file (a FIFO would block
        until a writer comes, a device never ends), or is larger than limit_bytes
    """
    try:
        # Non-blocking: opening a FIFO for reading otherwise waits for a writer, forever.
        # The kind is taken from the open descriptor, so nothing can swap the file between.
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    except OSError as exc:
        raise error(f'{path}: {exc.strerror}') from None
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            kind = next((name for test, name in _KINDS if test(mode)), 'not a regular file')
            raise error(f'{path}: {kind}, not a regular file: give {what} saved on disk')
        with os.fdopen(fd, 'rb', closefd=False) as file:
            data = file.read(limit_bytes + 1)
    except OSError as exc:
        raise error(f'{path}: {exc.strerror}') from None
    finally:
        os.close(fd)
    if len(data) > limit_bytes:
        size = f'{limit_bytes // 2 ** 20} MiB' if limit_bytes >= 2 ** 20 else \
            f'{limit_bytes // 1024} KiB'
        raise error(f'{path}: larger than {size}, the limit for {what}')
    return data


def load_yaml(text):
    """
    Return the document of YAML text, as yaml.safe_load would, refusing a repeated key.

    :raises yaml.YAMLError: malformed YAML, or a mapping that gives a key twice (the message
        names the key and both lines)
    """
    return yaml.load(text, Loader=StrictLoader)  # a SafeLoader: plain data only


class FieldReader:
    """Typed access to a document that names the file and the key of what it refuses."""

    def __init__(self, source, error=ValueError):
        """Name the source; refusals raise error."""
        self.source = source
        self.error = error

    def fail(self, where, message):
        """Raise the error for the value at where."""
        raise self.error(f'{self.source}: {where}: {message}')

    def mapping(self, value, where, allowed, required=()):
        """Return value if it is a mapping with only allowed keys and every required one."""
        if not isinstance(value, dict):
            self.fail(where, f'expected a mapping, got {type(value).__name__}')
        unknown = sorted(set(value) - set(allowed), key=repr)  # YAML keys need not be str
        if unknown:
            self.fail(where, f'unknown key(s) {unknown}; allowed: {sorted(allowed)}')
        missing = [k for k in required if k not in value]
        if missing:
            self.fail(where, f'missing key(s) {missing}')
        return value

    def number(self, value, where, positive=True, allow_zero=False):
        """Return a finite float (positive by default)."""
        if isinstance(value, str):
            try:  # YAML 1.1 reads 1e-3 and 1.0e5 (no dot, or no sign) as strings
                value = float(value)
            except ValueError:
                self.fail(where, f'expected a number, got {value!r}')
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.fail(where, f'expected a number, got {value!r}')
        value = float(value)
        if not math.isfinite(value):
            self.fail(where, f'{value} is not finite')
        if positive and (value < 0 or (value == 0 and not allow_zero)):
            self.fail(where, f'{value} must be {"non-negative" if allow_zero else "positive"}')
        return value

    def optional_number(self, block, key, where):
        """Return block[key] as a positive number, or None when it is absent or null."""
        value = block.get(key)
        return None if value is None else self.number(value, f'{where}.{key}')

    def flag(self, value, where):
        """Return a bool."""
        if not isinstance(value, bool):
            self.fail(where, f'expected true or false, got {value!r}')
        return value

    def vector(self, value, where, unit=False):
        """Return (3,) floats; with unit, normalised (a zero-length one refused)."""
        if not isinstance(value, (list, tuple)) or len(value) != 3:
            self.fail(where, f'expected [x, y, z], got {value!r}')
        vec = np.array([self.number(v, f'{where}[{i}]', positive=False)
                        for i, v in enumerate(value)])
        if unit:
            norm = np.linalg.norm(vec)
            if norm < 1e-12:
                self.fail(where, 'zero-length direction')
            vec = vec / norm
        return vec

    def points(self, value, where):
        """Return (k, 3) floats from a non-empty list of [x, y, z]."""
        if not isinstance(value, list) or not value:
            self.fail(where, f'expected a non-empty list of [x, y, z], got {value!r}')
        return np.array([self.vector(p, f'{where}[{i}]') for i, p in enumerate(value)])
