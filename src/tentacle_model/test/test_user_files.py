"""
Bad input to the model's tools (issue 15, section 3): refused or flagged, never taken.

Only regular files are read; a YAML key given twice is refused, naming the file, the key and
its lines; the small-angle model says when it is out of its range. A FIFO nobody writes to
used to block the reader for ever: each FIFO here gets a writer after a few seconds (a
daemon thread), so code that waits on it fails the test instead of hanging the suite.
"""

import os
import pathlib
import re
import threading
import time

import pytest
from tentacle_model import statics_cli
from tentacle_model.statics import SMALL_ANGLE_LIMIT_RAD
from tentacle_model.tentacle_spec import load_tentacle, SpecError
from tentacle_model.user_files import load_yaml, read_capped
import yaml

ROOT = pathlib.Path(__file__).resolve().parents[3]
CANTILEVER = str(ROOT / 'config' / 'tentacles' / 'cantilever.yaml')
BRAIDED = str(ROOT / 'config' / 'tentacles' / 'braided_chapter5.yaml')
UNBLOCK_AFTER_S = 3.0  # a reader still waiting on a FIFO by then gets its data: the test fails
SEGMENT = ('  - length_m: 0.1\n    section: {diameter_m: 0.002}\n    youngs_modulus_pa: 1.0e5\n'
           '    density_kg_m3: 1400.0\n')


def fifo(folder, data=b'name: from a pipe\nsegments: []\n'):
    """Return a FIFO in folder that a writer opens after UNBLOCK_AFTER_S, if anyone reads."""
    path = folder / 'pipe.yaml'
    os.mkfifo(path)

    def write():  # to every reader that comes, for a while: a reader may come twice
        time.sleep(UNBLOCK_AFTER_S)
        deadline = time.monotonic() + 30.0
        while time.monotonic() < deadline:
            try:  # succeeds only while a reader has it open
                fd = os.open(path, os.O_WRONLY | os.O_NONBLOCK)
            except OSError:
                time.sleep(0.05)
                continue
            os.write(fd, data)
            os.close(fd)
            time.sleep(0.05)

    threading.Thread(target=write, daemon=True).start()
    return path


@pytest.mark.parametrize('text, key, lines', [
    ('name: a\nname: b\nsegments: []\n', "'name'", (1, 2)),
    ('segments:\n' + SEGMENT + '    length_m: 0.1\n', "'length_m'", (2, 6)),
    ('base: {position_m: [0, 0, 0], position_m: [1, 0, 0]}\n', "'position_m'", (1, 1)),
    ('1: a\n1.0: b\n', '1.0', (1, 2)),   # the same key, spelt differently
])
def test_a_key_given_twice_is_refused_naming_it_and_both_lines(text, key, lines):
    with pytest.raises(yaml.constructor.ConstructorError) as error:
        load_yaml(text)
    message = str(error.value)
    assert f'duplicate key {key} at line {lines[1]} (first at line {lines[0]})' in message


def test_strict_yaml_reads_what_safe_load_reads():
    text = ('a: 1\nb: [1, 2.5, 1e-3, null, true]\nc: &shared {d: 1, e: 2}\n'
            'f: {<<: *shared, e: 3}\n')   # a key overriding a merged one is not a repeat
    assert load_yaml(text) == yaml.safe_load(text)
    assert load_yaml(text)['f'] == {'d': 1, 'e': 3}
    with pytest.raises(yaml.YAMLError):
        load_yaml('!!python/object:os.system {}\n')  # still the safe loader


def test_a_segment_with_length_twice_is_refused_not_a_longer_rod(tmp_path):
    path = tmp_path / 'twice.yaml'
    path.write_text('segments:\n' + SEGMENT.replace('0.1\n', '0.1\n    length_m: 0.2\n', 1))
    with pytest.raises(SpecError, match=r'(?s)twice.yaml: not valid YAML: .*duplicate key '
                                        r"'length_m' at line \d+ \(first at line 2\)"):
        load_tentacle(path)


def test_only_regular_files_are_read(tmp_path):
    data = b'name: x\n'
    regular = tmp_path / 'regular.yaml'
    regular.write_bytes(data)
    assert read_capped(regular, 100, ValueError, 'a test file') == data
    cases = ((tmp_path, 'a directory'), (pathlib.Path('/dev/zero'), 'a character device'),
             (fifo(tmp_path), 'a FIFO'))
    for path, kind in cases:
        started = time.monotonic()
        with pytest.raises(ValueError, match=f'^{path}: {kind}.*, not a regular file: give a '
                                             'test file saved on disk$'):
            read_capped(path, 100, ValueError, 'a test file')
        assert time.monotonic() - started < 1.0


@pytest.mark.parametrize('make, field, code, message', [
    # Files that are not regular: refused at once, naming the file and what it is.
    (lambda d: fifo(d), ['0', '0.005', '0'], 2,
     r'pipe.yaml: a FIFO \(named pipe\), not a regular file: give a tentacle file'),
    (lambda d: d, ['0', '0.005', '0'], 2, 'a directory, not a regular file'),
    (lambda d: '/dev/zero', ['0', '0.005', '0'], 2, '/dev/zero: a character device'),
    # A key twice: the file, the key and both lines.
    (lambda d: write(d, 'segments:\n' + SEGMENT + '    length_m: 0.1\n'), ['0', '0.005', '0'],
     2, r"twice.yaml: not valid YAML: .*duplicate key 'length_m' at line 6 \(first at "
        r'line 2\)'),
])
def test_statics_refuses_bad_files_with_exit_2(tmp_path, capsys, make, field, code, message):
    started = time.monotonic()
    assert statics_cli.main(['--tentacle', str(make(tmp_path)), '--field', *field]) == code
    err = capsys.readouterr().err
    assert time.monotonic() - started < UNBLOCK_AFTER_S
    assert err.startswith('tentacle-statics: ') and 'Traceback' not in err
    assert re.search(message, err, re.S), err


def write(folder, text):
    path = folder / 'twice.yaml'
    path.write_text(text)
    return path


@pytest.mark.parametrize('tentacle, field, dof, valid', [
    (CANTILEVER, ['0', '1000', '0'], '1', False),      # 9 km from a 20 mm rod, at 1e3 T
    (CANTILEVER, ['0', '0.001', '0'], '1', False),     # 0.6 rad at the tip: 9.1 mm, not 7.7
    (CANTILEVER, ['0', '0.0002', '0'], '1', True),     # 0.12 rad
    (BRAIDED, ['0', '0.002', '0.001'], '3', False),    # 0.66 rad
    (BRAIDED, ['0', '0.0005', '0.00025'], '3', True),  # 0.16 rad
])
def test_the_small_angle_model_says_when_it_is_out_of_its_range(capsys, tentacle, field, dof,
                                                                valid):
    args = ['--tentacle', tentacle, '--field', *field, '--dof', dof, '--linear']
    code = statics_cli.main(args)
    out = capsys.readouterr().out
    assert code == (0 if valid else 3)
    assert ('converged: converged' in out) == valid
    if not valid:
        assert "NOT VALID: outside the small-angle model's range: link " in out
        assert f'more than the {SMALL_ANGLE_LIMIT_RAD:g} rad the model holds for' in out
    assert statics_cli.main(args + ['--json']) == code
    result = yaml.safe_load(capsys.readouterr().out)  # JSON is YAML
    assert result['converged'] == valid
    assert ('outside the small-angle model' in result['reason']) != valid
