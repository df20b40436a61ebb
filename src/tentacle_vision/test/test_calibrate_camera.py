"""scripts/calibrate_camera: bad input refused with exit 2, and --write keeps the file's rest."""

import shutil

import cv2
import numpy as np
import pytest
from tentacle_vision.calibrate import main
from tentacle_vision.pixels import HomographyMap
import yaml


def board(cols=9, rows=6, square_px=40, margin_px=40):
    """Return a straight checkerboard image with (cols, rows) inner corners."""
    image = np.full(((rows + 1) * square_px + 2 * margin_px,
                     (cols + 1) * square_px + 2 * margin_px), 255, np.uint8)
    for j in range(rows + 1):
        for i in range(cols + 1):
            if (i + j) % 2 == 0:
                y, x = margin_px + j * square_px, margin_px + i * square_px
                image[y:y + square_px, x:x + square_px] = 0
    return image


@pytest.fixture
def files(tmp_path):
    cv2.imwrite(str(tmp_path / 'board.png'), board())
    cv2.imwrite(str(tmp_path / 'tiny.png'), np.zeros((1, 1), np.uint8))
    cv2.imwrite(str(tmp_path / 'small.png'), np.zeros((30, 300), np.uint8))
    cv2.imwrite(str(tmp_path / 'blank.png'), np.full((200, 200), 255, np.uint8))
    (tmp_path / 'notes.txt').write_text('not an image')
    return tmp_path


def run(capsys, argv):
    """Return (exit status, stdout, stderr) of calibrate_camera in this process."""
    try:
        main(argv)
        status = 0
    except SystemExit as exc:
        status = exc.code
    out, err = capsys.readouterr()
    return status, out, err


# (arguments, with {d} the folder; the exit status; a piece of stderr)
CASES = [
    (['{d}/board.png', '--square-mm', '-5'], 2, 'must be a positive length in mm'),
    (['{d}/board.png', '--square-mm', '0'], 2, 'must be a positive length in mm'),
    (['{d}/board.png', '--square-mm', 'nan'], 2, 'must be a positive length in mm'),
    (['{d}/board.png', '--square-mm', '5', '--origin-mm', 'inf', '0'], 2, 'must be finite'),
    (['{d}/board.png', '--square-mm', '5', '--pattern', '0x6'], 2,
     'a board needs at least 3x3 inner corners'),
    (['{d}/board.png', '--square-mm', '5', '--pattern', '2x2'], 2,
     'a board needs at least 3x3 inner corners'),
    (['{d}/board.png', '--square-mm', '5', '--pattern', 'nine'], 2, 'is not COLUMNSxROWS'),
    (['{d}/tiny.png', '--square-mm', '5'], 2,
     'tiny.png: 1 x 1 px is too small for a 9 x 6 board (at least 40 x 28 px'),
    (['{d}/small.png', '--square-mm', '5', '--pattern', '3x3'], 2,
     'no 3 x 3 checkerboard found'),
    (['{d}/blank.png', '--square-mm', '5'], 2, 'no 9 x 6 checkerboard found'),
    (['{d}/notes.txt', '--square-mm', '5'], 2, 'notes.txt is not an image'),
    (['{d}/missing.png', '--square-mm', '5'], 2, 'cannot be read: No such file'),
    (['/dev/zero', '--square-mm', '5'], 2, '/dev/zero: not a regular file'),
    (['{d}', '--square-mm', '5'], 2, 'not a regular file'),
    (['{d}/board.png', '--square-mm', '5', '--write', '{d}'], 2,
     'not a regular file (a device, FIFO or folder); nothing written'),
    (['{d}/board.png'], 2, 'the following arguments are required: --square-mm'),
    (['{d}/board.png', '--square-mm', '5'], 0, ''),
]


@pytest.mark.parametrize('argv, status, message', CASES)
def test_command_line_cases(files, capsys, argv, status, message):
    code, out, err = run(capsys, [a.format(d=files) for a in argv])
    assert code == status and message in err, err
    assert 'Traceback' not in err
    if status == 0:
        assert 'homography (pixels -> workspace metres' in out


def test_a_positive_square_gives_a_proper_not_a_mirrored_map(files, capsys):
    assert run(capsys, [str(files / 'board.png'), '--square-mm', '5', '--write',
                        str(files / 't.yaml')])[0] == 0
    h = yaml.safe_load((files / 't.yaml').read_text())['tracker_node']['ros__parameters'][
        'homography']
    fitted = HomographyMap(h)
    a, b = fitted.to_metres([[100.0, 100.0], [140.0, 100.0]])  # one square right
    assert b[0] - a[0] == pytest.approx(5e-3, rel=0.02)  # +u is +x, 5 mm a square
    c, = fitted.to_metres([[100.0, 140.0]])  # one square down the image is -y
    assert c[1] - a[1] == pytest.approx(-5e-3, rel=0.02)


def test_write_keeps_comments_and_other_keys_of_an_existing_file(files, capsys):
    target = files / 'coils_copy.yaml'  # the case of the issue: a copy of coils.yaml
    shutil.copy('config/coils.yaml', target)
    before = target.read_text()
    assert run(capsys, [str(files / 'board.png'), '--square-mm', '5', '--write',
                        str(target)])[0] == 0
    after = target.read_text()
    assert after.startswith(before)  # every line kept: the section is appended
    assert 'WARNING: the dxkdp wire dialect' in after
    document = yaml.safe_load(after)
    assert document['coils_node'] == yaml.safe_load(before)['coils_node']
    first = document['tracker_node']['ros__parameters']['homography']
    # Again into the same file: the homography's line is replaced in place, nothing else.
    tracker = files / 'tracker.yaml'
    tracker.write_text('# lab camera, bench 2\ntracker_node:\n  ros__parameters:\n'
                       '    base_px: [10.0, 20.0]  # insertion point\n'
                       '    homography: [0.0, 0.0, 0.0,\n                 0.0, 0.0, 0.0,\n'
                       '                 0.0, 0.0, 0.0]  # fitted here\n'
                       '    dark: true\n')
    assert run(capsys, [str(files / 'board.png'), '--square-mm', '5', '--write',
                        str(tracker)])[0] == 0
    lines = tracker.read_text().splitlines()
    assert lines[:4] == ['# lab camera, bench 2', 'tracker_node:', '  ros__parameters:',
                         '    base_px: [10.0, 20.0]  # insertion point']
    assert lines[4].startswith('    homography: [') and lines[6].endswith('# fitted here')
    assert lines[7:] == ['    dark: true']
    assert np.allclose(yaml.safe_load('\n'.join(lines))['tracker_node']['ros__parameters'][
        'homography'], first)


def test_a_file_it_cannot_edit_safely_is_left_alone(files, capsys):
    target = files / 'flow.yaml'
    text = '# mine\n{tracker_node: {ros__parameters: {dark: true}}}\n'
    target.write_text(text)
    status, out, err = run(capsys, [str(files / 'board.png'), '--square-mm', '5', '--write',
                                    str(target)])
    assert status == 2 and 'nothing written' in err and 'homography: [' in err
    assert target.read_text() == text
    target.write_text('tracker_node:\n  ros__parameters:\n    dark: true\n    dark: false\n')
    status, out, err = run(capsys, [str(files / 'board.png'), '--square-mm', '5', '--write',
                                    str(target)])
    assert status == 2 and "duplicate key 'dark' at line 4 (first at line 3)" in err
