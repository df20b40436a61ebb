"""
tentacle-plan on hostile input and Ctrl-C (issue 15, section 3): each case a row of a table.

Bad input is refused at once with exit code 2 and a message that names the file, the key
and the value, before any planning; Ctrl-C in any phase ends with exit code 130, the best
plan so far written and marked (or, before there is one, nothing written and that said),
and a folder never holds two runs' files. Ctrl-C is injected in-process by making a phase's
function raise KeyboardInterrupt; one test sends a real SIGINT to a real process.

A FIFO gets a writer after a few seconds (a daemon thread), so code that would wait on it
fails the test instead of hanging the suite.
"""

import io
import os
import pathlib
import re
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
from tentacle_planner import optimise, plan_cli, plan_plot, planner
from tentacle_planner import schedule_writer as schedule
from tentacle_planner.errors import PlanInputError
from tentacle_planner.paths import MAX_PATH_POINTS
from tentacle_planner.scene import MAX_PLAYBACK_STEPS, MIN_STEP_M, scene_of
from tentacle_planner.schedule_file import read_schedule
import yaml

ROOT = pathlib.Path(__file__).resolve().parents[3]
BRAIDED = ROOT / 'config' / 'tentacles' / 'braided_chapter5.yaml'
REFUSAL_S = 2.0         # a refusal answers within this, in-process
UNBLOCK_AFTER_S = 3.0   # a reader still waiting on a FIFO by then gets data: the test fails
QUICK = ['--starts', '1', '--iterations', '10']  # budgets: what is tested is not the plan


def arc_points(count=61, radius_m=0.06, length_m=0.06):
    """Return (count, 3) points along an in-plane arc from the origin, m."""
    s = np.linspace(0.0, length_m, count)
    return np.column_stack([radius_m * np.sin(s / radius_m),
                            radius_m * (1 - np.cos(s / radius_m)), 0 * s])


def arc_scene(folder, name='arc.yaml', **extra):
    """Write a small planar scene (the braided tentacle, 5 links, an arc); return its path."""
    document = {'name': 'arc', 'tentacle': str(BRAIDED),
                'path': {'points_m': arc_points().round(9).tolist()},
                'insertion_steps_m': [0.03, 0.04, 0.05], 'coil': {'max_field_t': 0.02},
                'model': {'dof': 1, 'sublinks': 1}, 'magnetisation': {'planar': True},
                **extra}
    path = folder / name
    path.write_text(yaml.safe_dump(document))
    return path


def fifo(folder, name):
    """Return a FIFO that gets a writer after UNBLOCK_AFTER_S if anyone is reading it."""
    path = folder / name
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
            os.write(fd, b'x_m,y_m,z_m\n0,0,0\n0.06,0,0\n')
            os.close(fd)
            time.sleep(0.05)

    threading.Thread(target=write, daemon=True).start()
    return path


def npy_claiming(folder, shape, data=b''):
    """Return a .npy file whose header claims shape (float64) followed by data."""
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {'descr': '<f8', 'fortran_order': False,
                                                  'shape': shape})
    path = folder / 'claims.npy'
    path.write_bytes(header.getvalue() + data)
    return path


def run(args, capsys):
    """Return (exit code, stdout, stderr, seconds) of tentacle-plan in-process."""
    started = time.monotonic()
    try:
        code = plan_cli.main([str(a) for a in args])
    except SystemExit as exit_:  # argparse
        code = exit_.code
    except KeyboardInterrupt:  # would end the whole pytest session, not fail this test
        pytest.fail('KeyboardInterrupt escaped tentacle-plan: a traceback, not exit 130')
    printed = capsys.readouterr()
    return code, printed.out, printed.err, time.monotonic() - started


def twice(folder, text, old, new, name):
    """Write text with old replaced by new (a key given a second time); return the path."""
    assert old in text
    path = folder / name
    path.write_text(text.replace(old, new, 1))
    return path


# Each row: (what, build the arguments in a folder, exit code, what stderr must match).
CASES = [
    ('--out an existing file', lambda d: ['--scene', arc_scene(d), '--out', d / 'arc.yaml'],
     2, r'--out .*arc.yaml exists and is not a folder'),
    ('--out under /proc', lambda d: ['--scene', arc_scene(d), '--out', '/proc/tentacle/out'],
     2, r'--out /proc/tentacle/out: cannot write in /proc'),
    ('--out whose schedule.yaml is a folder',
     lambda d: (d / 'o' / 'schedule.yaml').mkdir(parents=True) or [
         '--scene', arc_scene(d), '--out', d / 'o'], 2, 'schedule.yaml exists and is not a file'),
    ('--starts 0', lambda d: ['--scene', arc_scene(d), '--out', d / 'o', '--starts', '0'],
     2, f'argument --starts: 0 is not from 1 to {plan_cli.MAX_STARTS}'),
    ('--starts 1000000000',
     lambda d: ['--scene', arc_scene(d), '--out', d / 'o', '--starts', '1000000000'],
     2, f'argument --starts: 1000000000 is not from 1 to {plan_cli.MAX_STARTS}'),
    ('--seed -1', lambda d: ['--scene', arc_scene(d), '--out', d / 'o', '--seed', '-1'],
     2, 'argument --seed: -1 is not >= 0'),
    ('--seed x', lambda d: ['--scene', arc_scene(d), '--out', d / 'o', '--seed', 'x'],
     2, "argument --seed: expected a whole number, got 'x'"),
    ('--min-gain nan', lambda d: ['--scene', arc_scene(d), '--out', d / 'o', '--min-gain',
                                  'nan'], 2, 'argument --min-gain: nan is not from 0 to 1'),
    ('--min-gain 2', lambda d: ['--scene', arc_scene(d), '--out', d / 'o', '--min-gain', '2'],
     2, 'argument --min-gain: 2 is not from 0 to 1'),
    ('--iterations 0',
     lambda d: ['--scene', arc_scene(d), '--out', d / 'o', '--iterations', '0'],
     2, 'argument --iterations: 0 is not from 1 to'),
    ('playback_step_m 1e-9',
     lambda d: ['--scene', arc_scene(d, playback_step_m=1e-9), '--out', d / 'o'],
     2, rf'arc.yaml: playback_step_m: 1e-09 m is less than the smallest step, {MIN_STEP_M:g} m'),
    ('--playback-step 1e-9', lambda d: ['--tentacle', BRAIDED, '--path', csv_arc(d),
                                        '--playback-step', '1e-9', '--out', d / 'o'],
     2, r'\(command line\): playback_step_m: 1e-09 m is less than the smallest step'),
    ('playback_step_m of too many steps',
     lambda d: ['--scene', arc_scene(d, playback_step_m=2e-5), '--out', d / 'o'],
     2, rf'playback_step_m: 2e-05 m makes 2500 dense steps to 0.05 m, more than the '
        rf'{MAX_PLAYBACK_STEPS} planned at most: take at least 2.5e-05 m'),
    ('insertion step 1e-9', lambda d: ['--scene', arc_scene(d, insertion_steps_m=[1e-9, 0.03]),
                                       '--out', d / 'o'],
     2, r'arc.yaml: insertion_steps_m\[0\]: 1e-09 m is less than the smallest step, 1e-05 m'),
    ('--steps 1e-9 apart', lambda d: ['--tentacle', BRAIDED, '--path', csv_arc(d),
                                      '--steps', '0.03,0.030000001', '--out', d / 'o'],
     2, r'insertion_steps_m\[1\]: 0.03 m is 1e-09 m past insertion_steps_m\[0\] \(0.03 m\): '
        r'steps are at least 1e-05 m apart'),
    ('a .npy whose header claims 10^12 points',
     lambda d: ['--tentacle', BRAIDED, '--path', npy_claiming(d, (10 ** 12, 3), b'\0' * 48),
                '--out', d / 'o'],
     2, rf'claims.npy: its header says 1000000000000 points, more than the '
        rf'{MAX_PATH_POINTS} a path may have'),
    ('a .npy with fewer bytes than its header says',
     lambda d: ['--tentacle', BRAIDED, '--path', npy_claiming(d, (5, 3), b'\0' * 24),
                '--out', d / 'o'],
     2, 'claims.npy: its header says 5 points, but the file has 24 bytes of data, not 120'),
    ('a .npy of shape (k, 2)',
     lambda d: ['--tentacle', BRAIDED, '--path', npy_claiming(d, (10 ** 12, 2)),
                '--out', d / 'o'],
     2, r'claims.npy: expected a \(k, 3\) array, metres, got shape \(1000000000000, 2\)'),
    ('a FIFO as --path', lambda d: ['--tentacle', BRAIDED, '--path', fifo(d, 'pipe.csv'),
                                    '--steps', '0.05', '--out', d / 'o'],
     2, r'pipe.csv: a FIFO \(named pipe\), not a regular file: give a path file'),
    ('a FIFO as --tentacle', lambda d: ['--tentacle', fifo(d, 'pipe.yaml'), '--path',
                                        csv_arc(d), '--out', d / 'o'],
     2, r'pipe.yaml: a FIFO \(named pipe\), not a regular file: give a tentacle file'),
    ('a folder as --path', lambda d: (d / 'dir.csv').mkdir() or [
        '--tentacle', BRAIDED, '--path', d / 'dir.csv', '--steps', '0.05', '--out', d / 'o'],
     2, r'dir.csv: a directory, not a regular file'),
    ('a device as --scene', lambda d: ['--scene', '/dev/zero', '--out', d / 'o'],
     2, '/dev/zero: a character device, not a regular file'),
    ('a scene key given twice',
     lambda d: twice(d, arc_scene(d).read_text(), 'name: arc\n', 'name: arc\nname: arc2\n',
                     'twice.yaml') and ['--scene', d / 'twice.yaml', '--out', d / 'o'],
     2, r"(?s)twice.yaml: not valid YAML: .*duplicate key 'name' at line"),
    ('an inline path key given twice',
     lambda d: ['--scene', twice(d, arc_scene(d).read_text(), 'path:\n',
                                 'path:\n  frame: rig\n  frame: image\n', 'twice.yaml'),
                '--out', d / 'o'],
     2, r"(?s)twice.yaml: not valid YAML: .*duplicate key 'frame' at line"),
    ('a segment with length_m twice (a 200 mm rod)',
     lambda d: ['--tentacle', twice(d, BRAIDED.read_text(), '  - length_m: 0.010\n',
                                    '  - length_m: 0.010\n    length_m: 0.190\n',
                                    'twice.yaml'), '--path', csv_arc(d), '--out', d / 'o'],
     2, r"(?s)twice.yaml: not valid YAML: .*duplicate key 'length_m' at line \d+ \(first "
        r'at line 14\)'),
]


def csv_arc(folder):
    """Write the arc as a CSV path file (mm); return its path."""
    path = folder / 'arc.csv'
    np.savetxt(path, arc_points() * 1e3, delimiter=',', header='x_mm,y_mm,z_mm', comments='')
    return path


@pytest.mark.parametrize('what, arguments, code, message', CASES, ids=[c[0] for c in CASES])
def test_bad_input_is_refused_at_once_naming_file_key_and_value(
        tmp_path, capsys, monkeypatch, what, arguments, code, message):
    monkeypatch.setattr(planner, 'plan_scene', refuse_to_plan)
    got, out, err, elapsed_s = run(arguments(tmp_path), capsys)
    assert (got, bool(re.search(message, err))) == (code, True), err
    assert 'Traceback' not in err and len(err) < 2000
    assert elapsed_s < REFUSAL_S
    assert not (tmp_path / 'o' / 'plan.png').exists()


def refuse_to_plan(*args, **kwargs):
    """Stand in for plan_scene where input must be refused before planning."""
    raise AssertionError('planned: the input should have been refused first')


def test_a_path_of_too_many_points_is_refused_before_it_is_parsed(tmp_path, monkeypatch):
    monkeypatch.setattr('tentacle_planner.paths.MAX_PATH_POINTS', 10)
    csv = tmp_path / 'dense.csv'
    np.savetxt(csv, arc_points(11) * 1e3, delimiter=',', header='x_mm,y_mm,z_mm',
               comments='')
    with pytest.raises(PlanInputError, match='dense.csv: 11 points, more than the 10 a path '
                                             'may have: resample it'):
        scene_of(BRAIDED, csv)


def test_a_million_point_path_is_planned_and_written_fast(tmp_path):
    # A million points along the arc (60 nm apart): accepted; the schedule and the picture
    # carry it thinned to SCHEDULE_PATH_POINTS, so writing takes seconds, not a minute.
    npy = tmp_path / 'million.npy'
    np.save(npy, arc_points(MAX_PATH_POINTS))
    scene = scene_of(BRAIDED, npy, [0.03, 0.05], model={'dof': 1},
                     magnetisation={'planar': True})
    result = planner.plan_scene(scene, starts=1, iterations=2)
    started = time.monotonic()
    path = schedule.write_schedule(tmp_path / 'o', result)
    elapsed_s = time.monotonic() - started
    document = yaml.safe_load(path.read_text())
    assert len(document['path_m']) <= schedule.SCHEDULE_PATH_POINTS
    assert document['path_thinned'] == {'of_points': MAX_PATH_POINTS, 'every': 501}
    assert document['path_m'][-1] == pytest.approx(arc_points(2)[-1].tolist(), abs=1e-9)
    assert elapsed_s < 10.0, elapsed_s  # 2.7 s here; the whole path took over a minute


def test_a_short_path_goes_into_the_schedule_whole():
    points = arc_points(schedule.SCHEDULE_PATH_POINTS)
    assert schedule.thinned(points)[0] is points
    kept, every = schedule.thinned(arc_points(schedule.SCHEDULE_PATH_POINTS + 1))
    assert every == 2 and len(kept) <= schedule.SCHEDULE_PATH_POINTS
    np.testing.assert_array_equal(kept[-1], arc_points(2)[-1])


# -- Ctrl-C ------------------------------------------------------------------------------
def interrupt(module, name, after=0, armed=lambda: True):
    """Make module.name raise KeyboardInterrupt on its call number after + 1 once armed()."""
    original = getattr(module, name)
    calls = []

    def wrapper(*args, **kwargs):
        calls.append(armed())
        if sum(calls) > after:
            raise KeyboardInterrupt
        return original(*args, **kwargs)
    return name, wrapper


AFTER_THE_ROBUST_PLAN = 'the first call once the robust plan is made'


def previous_run(out):
    """Leave a previous run's outputs in out."""
    out.mkdir()
    (out / 'schedule.yaml').write_text('previous run\n')
    (out / 'plan.png').write_bytes(b'previous run')


# Each row: (phase, module, function, calls let through, scene extras, options, whether a
# plan is written, what the flags must include).
PHASES = [
    ('loading the scene', plan_cli, '_scene', 0, {}, [], False, None),
    ('setting the problem up', planner, 'problem_of', 0, {}, [], False, None),
    ('the first step of the insertion-order start', optimise, 'fit', 0, {}, [], False, None),
    ('the insertion-order start of a fields-only scene (as all of ch6_coiling)', optimise,
     'fit', 2, {'magnetisation': {'given': True}}, [], True,
     'interrupted: the best plan so far (the first 2 of 3 steps fitted)'),
    ('the multi-start loop', optimise.Problem, 'plan', 1, {}, ['--starts', '3'], True,
     'interrupted: the best plan so far'),
    ('the robust plan', planner, 'RobustProblem', 0, {}, ['--robust'], True,
     'interrupted: left out the robust plan, the robustness report, the re-check in fuller '
     'models'),
    ('dense playback', planner, 'playback', 0, {'playback_step_m': 0.005}, [], True,
     'interrupted: left out dense playback (key steps only), the robustness report, '
     'the re-check in fuller models'),
    ('the robustness report', planner, 'report', 0, {}, [], True,
     'interrupted: left out the robustness report, the re-check in fuller models'),
    ('the polish in the finer model (its re-check first)', planner, 'recheck', 0, {}, [],
     True, 'interrupted: left out the polish in the finer model, the robustness report, '
     'the re-check in fuller models'),
    # (the polish's re-check serves the nominal plan: a robust plan is checked anew)
    ('the re-check', planner, 'recheck', AFTER_THE_ROBUST_PLAN, {}, ['--robust'], True,
     'interrupted: left out the re-check in fuller models'),
    ('writing the schedule', schedule, 'schedule_document', 0, {}, [], False, None),
]


@pytest.mark.parametrize('phase, module, name, after, extra, options, written, flag', PHASES,
                         ids=[p[0] for p in PHASES])
def test_ctrl_c_in_every_phase_exits_130_with_the_best_plan_so_far(
        tmp_path, capsys, monkeypatch, phase, module, name, after, extra, options, written,
        flag):
    scene, out = arc_scene(tmp_path, **extra), tmp_path / 'out'
    previous_run(out)
    if after == AFTER_THE_ROBUST_PLAN:   # however many re-checks the polish made before it
        made, robust = [], planner.RobustProblem
        monkeypatch.setattr(planner, 'RobustProblem',
                            lambda *args: made.append(True) or robust(*args))
        monkeypatch.setattr(module, *interrupt(module, name, 0, armed=lambda: bool(made)))
    else:
        monkeypatch.setattr(module, *interrupt(module, name, after))
    code, printed, err, _ = run(['--scene', scene, '--out', out, *QUICK, *options], capsys)
    assert code == 130, err
    assert 'Traceback' not in err
    if not written:
        assert 'nothing written' in err
        assert (out / 'schedule.yaml').read_text() == 'previous run\n'  # as it was
        assert (out / 'plan.png').read_bytes() == b'previous run'
        return
    document = yaml.safe_load((out / 'schedule.yaml').read_text())
    assert document['interrupted'] is True and flag in document['flags'], document['flags']
    assert document['steps'] and all(np.all(np.isfinite(s['field_t']))
                                     for s in document['steps'])
    assert 'interrupted: wrote the best plan so far' in err
    assert (out / 'plan.png').read_bytes().startswith(b'\x89PNG')
    assert f'FLAG: {flag}' in printed and '[INTERRUPTED: best plan so far]' in printed
    assert not list(out.glob('.*.tmp'))


class InterruptedImport:
    """A module finder that is Ctrl-C'd when it is asked for one module."""

    def __init__(self, name):
        """Interrupt the import of the module name."""
        self.name = name

    def find_spec(self, name, path=None, target=None):
        """Raise KeyboardInterrupt for the module; leave every other to the next finder."""
        if name == self.name:
            raise KeyboardInterrupt
        return None


def test_ctrl_c_while_the_libraries_load_exits_130(tmp_path, capsys, monkeypatch):
    # numpy, scipy, numba and matplotlib take most of the first second of a run.
    monkeypatch.delitem(sys.modules, 'tentacle_planner.planner')
    monkeypatch.setattr(sys, 'meta_path', [InterruptedImport('tentacle_planner.planner'),
                                           *sys.meta_path])
    code, _, err, _ = run(['--scene', arc_scene(tmp_path), '--out', tmp_path / 'o'], capsys)
    assert code == 130 and 'interrupted before a plan was found: nothing written' in err


def test_ctrl_c_while_drawing_keeps_the_schedule_and_no_stale_picture(
        tmp_path, capsys, monkeypatch):
    out = tmp_path / 'out'
    previous_run(out)
    monkeypatch.setattr(plan_plot, *interrupt(plan_plot, 'plot_plan'))
    code, _, err, _ = run(['--scene', arc_scene(tmp_path), '--out', out, *QUICK], capsys)
    assert code == 130 and 'interrupted: wrote the plan to ' in err
    assert 'schedule.yaml, not its picture' in err
    assert read_schedule(out / 'schedule.yaml').steps   # whole, and readable
    assert not (out / 'plan.png').exists()  # the previous run's is gone, not beside this one
    assert sorted(p.name for p in out.iterdir()) == ['schedule.yaml']


def test_a_second_run_replaces_both_outputs(tmp_path, capsys):
    out = tmp_path / 'out'
    previous_run(out)
    code, _, err, _ = run(['--scene', arc_scene(tmp_path), '--out', out, *QUICK], capsys)
    assert code in (0, 3), err
    assert (out / 'schedule.yaml').read_text() != 'previous run\n'
    assert (out / 'plan.png').read_bytes().startswith(b'\x89PNG')
    assert sorted(p.name for p in out.iterdir()) == ['plan.png', 'schedule.yaml']


def test_a_real_sigint_writes_the_best_plan_so_far(tmp_path):
    # A real process and a real Ctrl-C: sent once the first start is done (its progress
    # line), while the next of many starts runs.
    out = tmp_path / 'out'
    child = subprocess.Popen(
        [sys.executable, '-m', 'tentacle_planner.plan_cli', '--scene',
         str(arc_scene(tmp_path)), '--out', str(out), '--starts', '200', '--iterations', '50'],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=dict(os.environ))
    progress, deadline = b'', time.monotonic() + 120.0
    try:
        while b' 1/200 starts' not in progress and b' 2/200 starts' not in progress:
            assert time.monotonic() < deadline and child.poll() is None, progress
            progress += os.read(child.stderr.fileno(), 4096)
        child.send_signal(signal.SIGINT)
        printed, rest = child.communicate(timeout=120.0)
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
    err = (progress + rest).decode()
    assert child.returncode == 130, err
    assert 'Traceback' not in err and 'interrupted: wrote the best plan so far' in err
    document = yaml.safe_load((out / 'schedule.yaml').read_text())
    assert document['interrupted'] is True
    assert 'interrupted: the best plan so far' in document['flags']
    assert b'[INTERRUPTED: best plan so far]' in printed
