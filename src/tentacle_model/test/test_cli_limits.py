"""
tentacle-statics on hostile input: refused at once with the reason, or answered in time.

Problems beyond the size limits are refused (exit code 2) and the largest accepted ones
solve well within the time limit, which bounds them; negative numbers with exponents are
numbers; bad tentacle files and knobs are refused naming the file and the field.

What had no bound runs in a child process with a timeout and a memory limit (so that a
run that never answers, or eats the machine's memory, fails instead of hanging the suite or
the machine); the child times its own main() call: imports and numba's cache are not
charged to the refusal. Bounds are generous: the machine's speed drifts by 2x.
"""

import inspect
import json
import os
import pathlib
import re
import resource
import subprocess
import sys
import time

import numpy as np
import pytest
from tentacle_model import statics_cli
from tentacle_model.chain import discretise, MAX_CHAIN_LINKS, ProblemTooLarge
from tentacle_model.statics import check_size, compile_kernels, MAX_LINKS, solve
from tentacle_model.tentacle_spec import load_tentacle

ROOT = pathlib.Path(__file__).resolve().parents[3]
TENTACLES = ROOT / 'config' / 'tentacles'
CANTILEVER = str(TENTACLES / 'cantilever.yaml')
BRAIDED = str(TENTACLES / 'braided_chapter5.yaml')
REFUSAL_S = 2.0    # a refusal answers within this, in-process
CHILD_TIMEOUT_S = 60.0  # today's unbounded runs took 27 to 56 s, or never answered
CHILD_MEMORY_BYTES = 4 * 2 ** 30  # address space; a refusal or solve here uses 0.6 GiB
TIME_LIMIT_S = inspect.signature(solve).parameters['time_limit_s'].default  # 10 s
FIELD = ['--field', '0', '0.005', '0']
TIMED_MAIN = """
import sys, time
from tentacle_model.statics import compile_kernels
from tentacle_model.statics_cli import main
compile_kernels()
started = time.monotonic()
code = main(sys.argv[1:])
print(f'elapsed_s={time.monotonic() - started}', file=sys.stderr)
sys.exit(code)
"""


@pytest.fixture(autouse=True, scope='module')
def compiled():
    """Compile before the in-process clocks below start."""
    compile_kernels()


def run_cli(*args):
    """Return (exit code, stdout, stderr, seconds main() took) of tentacle-statics."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(ROOT / 'src' / 'tentacle_model'), os.environ.get('PYTHONPATH', '')]))

    def limit_memory():
        resource.setrlimit(resource.RLIMIT_AS, (CHILD_MEMORY_BYTES, CHILD_MEMORY_BYTES))

    done = subprocess.run([sys.executable, '-c', TIMED_MAIN, *args], capture_output=True,
                          text=True, timeout=CHILD_TIMEOUT_S, env=env, preexec_fn=limit_memory)
    lines = done.stderr.strip().splitlines()
    assert lines and lines[-1].startswith('elapsed_s='), done.stderr[-2000:]
    return done.returncode, done.stdout, '\n'.join(lines[:-1]), float(lines[-1][10:])


def run_main(capsys, *args):
    """Return (exit code, stdout, stderr, seconds) of tentacle-statics' main() in-process."""
    started = time.monotonic()
    code = statics_cli.main(list(args))
    elapsed_s = time.monotonic() - started
    out, err = capsys.readouterr()
    return code, out, err, elapsed_s


def largest_accepted(spec, dof, dipoles):
    """Return the most sublinks whose chain check_size accepts."""

    def accepted(sublinks):
        try:
            chain = discretise(spec, sublinks=sublinks)
            check_size(chain.size, dof, chain.interacting_pair_count() if dipoles else 0)
        except ProblemTooLarge:
            return False
        return True
    low, high = 1, MAX_LINKS[dof] // len(spec.segments)
    if accepted(high):
        return high
    while low < high:
        middle = (low + high + 1) // 2
        low, high = (middle, high) if accepted(middle) else (low, middle - 1)
    return low


# -- 1. sizes: refused at once with the reason, exit code 2 -------------------------------
@pytest.mark.parametrize('args, reason', [
    (['--tentacle', CANTILEVER, '--sublinks', '1000000000'],
     f'make 1000000000 links, more than the {MAX_CHAIN_LINKS} any joint model solves'),
    (['--tentacle', CANTILEVER, '--sublinks', '3000', '--dof', '3'],
     f'3000 links: the 3-DoF model solves at most {MAX_LINKS[3]}'),
    (['--tentacle', CANTILEVER, '--sublinks', '100000', '--dof', '3'],
     f'100000 links: the 3-DoF model solves at most {MAX_LINKS[3]}'),
    (['--tentacle', BRAIDED, '--sublinks', '20000', '--dipoles'],
     'interacting dipole pairs in the planar model need an estimated .* MiB'),
    (['--tentacle', BRAIDED, '--sublinks', '20000', '--dipoles', '--dof', '3'],
     f'links: the 3-DoF model solves at most {MAX_LINKS[3]}'),
    (['--tentacle', '/dev/zero'], '/dev/zero: a character device, not a regular file'),
])
def test_oversized_problems_are_refused_at_once(args, reason):
    code, out, err, elapsed_s = run_cli(*args, *FIELD)
    assert code == 2, err
    assert err.startswith('tentacle-statics: ')
    assert re.search(reason, err), err
    assert 'Traceback' not in err and not out
    assert elapsed_s < REFUSAL_S


def test_a_one_segment_rod_has_no_dipole_pairs_to_refuse():
    # 100000 links with --dipoles died building n^2 / 2 pairs; one segment is one magnet.
    code, out, err, elapsed_s = run_cli('--tentacle', CANTILEVER, '--sublinks', '100000',
                                        '--dipoles', '--json', *FIELD)
    assert code == 0, err
    assert json.loads(out)['links'] == 100000
    assert elapsed_s < 10.0


@pytest.mark.parametrize('tentacle, dof, dipoles', [
    ('cantilever', 1, False), ('cantilever', 3, False), ('braided_chapter5', 3, False),
    ('braided_chapter5', 1, True), ('braided_chapter5', 3, True),
    ('vsr_chapter6', 3, True)])
def test_the_largest_accepted_size_still_solves_in_time(capsys, tentacle, dof, dipoles):
    path = str(TENTACLES / f'{tentacle}.yaml')
    spec = load_tentacle(path)
    sublinks = largest_accepted(spec, dof, dipoles)
    if not dipoles:  # the link count is the binding limit
        assert discretise(spec, sublinks=sublinks).size > MAX_LINKS[dof] - len(spec.segments)
    options = ['--dof', str(dof)] + (['--dipoles'] if dipoles else [])
    code, out, err, elapsed_s = run_main(capsys, '--tentacle', path, '--sublinks',
                                         str(sublinks), '--json', *options,
                                         '--field', '0', '0.013', '0.013')
    result = json.loads(out)
    if tentacle != 'vsr_chapter6':  # its 24 magnets fold onto each other and touch
        assert code == 0 and result['converged'], (err, result['reason'])
    assert code in (0, 3) and result['reason'], err
    assert elapsed_s < 0.5 * TIME_LIMIT_S  # well within the limit (here: 0.1 to 1.5 s)
    code, _, err, elapsed_s = run_main(capsys, '--tentacle', path, '--sublinks',
                                       str(sublinks + 1), *options, *FIELD)
    assert code == 2 and 'use fewer sublinks' in err, err
    assert elapsed_s < REFUSAL_S


def test_the_library_refuses_too(cantilever, braided):
    spec = cantilever[0]
    with pytest.raises(ProblemTooLarge, match='more than the 100000'):
        discretise(spec, sublinks=MAX_CHAIN_LINKS + 1)
    with pytest.raises(ProblemTooLarge, match='the 3-DoF model solves at most'):
        solve(discretise(spec, sublinks=MAX_LINKS[3] + 1), [0.0, 5e-3, 0.0], dof=3)
    sublinks = largest_accepted(braided, 3, True)
    with pytest.raises(ProblemTooLarge, match='estimated .* MiB of dense arrays'):
        solve(discretise(braided, sublinks=sublinks + 1), [0.0, 5e-3, 0.0], dof=3,
              dipoles=True)
    # Only the free links count: a short insertion may be cut finer.
    chain = discretise(spec, inserted_m=spec.length_m / 4, sublinks=4 * MAX_LINKS[3])
    assert chain.size == MAX_LINKS[3]
    assert solve(chain, [0.0, 5e-3, 0.0], dof=3).converged


@pytest.mark.parametrize('tentacle, dof, dipoles', [
    ('cantilever', 1, False), ('braided_chapter5', 3, False), ('braided_chapter5', 1, True),
    ('braided_chapter5', 3, True)])
def test_the_time_limit_bounds_the_largest_accepted_problems(tentacle, dof, dipoles):
    spec = load_tentacle(TENTACLES / f'{tentacle}.yaml')
    chain = discretise(spec, sublinks=largest_accepted(spec, dof, dipoles))
    limit_s = 0.05  # far less than any of these needs
    for field in ([-0.02, 0.001, 0.001], [0.1, 0.1, 0.0]):
        started = time.monotonic()
        eq = solve(chain, field, dof=dof, dipoles=dipoles, time_limit_s=limit_s)
        assert time.monotonic() - started < limit_s + 1.0, eq.reason
        assert eq.converged or 'limit' in eq.reason, eq.reason


# -- 2. negative numbers in scientific notation are numbers -------------------------------
def test_negative_numbers_with_exponents_are_numbers(capsys):
    code = statics_cli.main(['--tentacle', CANTILEVER, '--field', '0', '-5e-3', '0',
                             '--gravity', '0', '-9.81e0', '-1E-1', '--sublinks', '4',
                             '--json'])
    result = json.loads(capsys.readouterr().out)
    assert code == 0
    assert result['field_t'] == [0.0, -5e-3, 0.0]
    assert result['tip'][1] < 0  # bent towards -y, by the field and by gravity


@pytest.mark.parametrize('text', ['-5e-3', '-5E+3', '-.5e-2', '-5.e1', '-5', '-0.5', '-inf',
                                  '-nan'])
def test_the_negative_number_pattern_takes_any_float(text):
    assert statics_cli.NEGATIVE_NUMBER.match(text)
    float(text)


def test_options_and_help_still_work(capsys):
    with pytest.raises(SystemExit) as done:
        statics_cli.main(['--help'])
    assert done.value.code == 0
    assert '--field BX BY BZ' in capsys.readouterr().out
    with pytest.raises(SystemExit) as done:  # not a number: still an argparse error
        statics_cli.main(['--tentacle', CANTILEVER, '--field', '0', '-x', '0'])
    assert done.value.code == 2
    # A non-finite field parses, then is refused by the solver with the reason.
    assert statics_cli.main(['--tentacle', CANTILEVER, '--field', '0', '-inf', '0']) == 2
    assert 'must be three finite numbers' in capsys.readouterr().err


# -- 3. tentacle files and knobs that do not fit ------------------------------------------
def test_a_null_name_is_refused_naming_file_and_field(tmp_path, capsys):
    path = tmp_path / 'cantilever.yaml'
    path.write_text(pathlib.Path(CANTILEVER).read_text().replace('name: cantilever',
                                                                 'name: null'))
    assert statics_cli.main(['--tentacle', str(path), *FIELD]) == 2
    assert 'cantilever.yaml: name: expected a non-empty string, got None' in \
        capsys.readouterr().err


def test_a_backbone_position_without_a_backbone_is_refused(capsys):
    assert statics_cli.main(['--tentacle', CANTILEVER, '--backbone', '0.01', *FIELD]) == 2
    err = capsys.readouterr().err
    assert "tentacle 'cantilever' has no backbone" in err and 'backbone:' in err
    # The chapter 6 strip has one: the same option is a knob there.
    assert statics_cli.main(['--tentacle', str(TENTACLES / 'vsr_chapter6.yaml'),
                             '--backbone', '0.01', '--sublinks', '1', *FIELD]) == 0


@pytest.mark.parametrize('data', [
    np.random.default_rng(7).bytes(4096),                        # random bytes
    'name: caf\u00e9\nsegments: []\n'.encode('latin-1'),          # not UTF-8
    b'\x00\x01\x02' * 100,                                        # UTF-8, but not text
    b'[' * 30000 + b']' * 30000,                                  # nested past recursion
])
def test_unreadable_files_are_named(tmp_path, capsys, data):
    path = tmp_path / 'binary.yaml'
    path.write_bytes(data)
    assert statics_cli.main(['--tentacle', str(path), *FIELD]) == 2
    err = capsys.readouterr().err
    assert f'tentacle-statics: {path}: ' in err, err
    assert len(err) < 1000
