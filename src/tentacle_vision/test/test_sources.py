"""Frame sources (a folder, a video file) and the pixel maps, without ROS."""

import pathlib
import subprocess

import cv2
import numpy as np
import pytest
from tentacle_vision.pixels import fit_homography, HomographyMap, pixel_map, ScaleMap
from tentacle_vision.sources import as_encoding, open_source, SOURCES
import yaml

ROOT = pathlib.Path(__file__).resolve().parents[3]


def frames(n, shape=(48, 64)):
    return [np.full(shape, 10 * k, np.uint8) for k in range(n)]


def test_a_folder_replays_in_name_order_and_loops_if_asked(tmp_path):
    for k, frame in enumerate(frames(3)):
        cv2.imwrite(str(tmp_path / f'frame_{k:04d}.png'), frame)
    (tmp_path / 'notes.txt').write_text('not an image')
    source = open_source(str(tmp_path))
    assert [int(source.read()[0, 0]) for _ in range(3)] == [0, 10, 20]
    assert source.read() is None and source.rate_hz is None
    looping = open_source(str(tmp_path), loop=True)
    assert [int(looping.read()[0, 0]) for _ in range(4)] == [0, 10, 20, 0]


def test_a_video_file_is_read_with_its_rate(tmp_path):
    path = str(tmp_path / 'run.avi')
    writer = cv2.VideoWriter(path, cv2.VideoWriter_fourcc(*'MJPG'), 25.0, (64, 48))
    for frame in frames(5):
        writer.write(cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR))
    writer.release()
    source = open_source(path)
    assert source.rate_hz == pytest.approx(25.0)
    read = [source.read() for _ in range(6)]
    assert all(f is not None for f in read[:5]) and read[5] is None
    assert [int(f[0, 0, 0]) for f in read[:5]] == pytest.approx([0, 10, 20, 30, 40], abs=3)
    source.close()


def test_bad_sources_say_what_is_wrong(tmp_path):
    with pytest.raises(ValueError, match='not a device number, folder or file'):
        open_source(str(tmp_path / 'absent'))
    with pytest.raises(ValueError, match='no images'):
        open_source(str(tmp_path))
    (tmp_path / 'broken.avi').write_bytes(b'not a video')
    with pytest.raises(ValueError, match='does not open'):
        open_source(str(tmp_path / 'broken.avi'))
    with pytest.raises(ValueError, match="'rgb8' is not bgr8 or mono8"):
        as_encoding(frames(1)[0], 'rgb8')


def test_a_lab_camera_plugs_in_under_a_prefix():
    class Fake:
        rate_hz = 120.0

        def __init__(self, serial, loop):
            self.serial = serial

        def read(self):
            return np.zeros((2, 2), np.uint8)

        def close(self):
            pass
    SOURCES['basler'] = Fake
    try:
        source = open_source('basler:40123456')
        assert source.serial == '40123456' and source.read().shape == (2, 2)
    finally:
        del SOURCES['basler']


def test_pixel_maps_round_trip_and_agree_on_scale():
    scale = ScaleMap(5e-5, (100.0, 200.0))
    px = np.array([[100.0, 200.0], [300.0, 50.0]])
    assert np.allclose(scale.to_metres(px), [[0.0, 0.0], [0.01, 0.0075]])  # y up the image
    assert np.allclose(scale.to_pixels(scale.to_metres(px)), px)
    tilted = HomographyMap([5e-5, 1e-6, -0.005, 2e-6, -5e-5, 0.01, 1e-5, 2e-5, 1.0])
    assert np.allclose(tilted.to_pixels(tilted.to_metres(px)), px)
    local = tilted.metres_per_px_at((500.0, 500.0))
    a, b = tilted.to_metres([[500.0, 500.0], [501.0, 500.0]])
    assert local == pytest.approx(np.hypot(*(b - a)), rel=0.05)
    assert isinstance(pixel_map(5e-5, (), (0.0, 0.0)), ScaleMap)
    with pytest.raises(ValueError, match='9 numbers'):
        pixel_map(5e-5, [1.0, 2.0])
    with pytest.raises(ValueError, match='positive'):
        ScaleMap(0.0, (0.0, 0.0))


def board_image(square=0.002, cols=9, rows=6):
    """Return (a tilted view of a checkerboard, the homography pixels -> metres it has)."""
    board = np.full(((rows + 1) * 40 + 80, (cols + 1) * 40 + 80), 255, np.uint8)
    k = square / 40
    for j in range(rows + 1):
        for i in range(cols + 1):
            if (i + j) % 2 == 0:
                board[40 + j * 40:80 + j * 40, 40 + i * 40:80 + i * 40] = 0
    # Board pixels -> metres: inner corner (i, j) at (i, -j) squares. The first corner is
    # between pixels 79 and 80, at 79.5 (pixel centres are at integers).
    to_m = np.array([[k, 0, -k * 79.5], [0, -k, k * 79.5], [0, 0, 1]])
    truth = np.array([[1.1, 0.05, 300.0], [-0.03, 1.05, 200.0], [1e-5, 2e-5, 1.0]])
    image = cv2.warpPerspective(board, truth, (1000, 800), borderValue=255)
    return image, HomographyMap(to_m @ np.linalg.inv(truth))


def test_a_checkerboard_gives_back_the_homography_that_drew_it():
    image, expected = board_image()
    fitted = fit_homography(image, (9, 6), 0.002)
    px = np.array([[400.0, 300.0], [700.0, 500.0], [350.0, 550.0]])
    assert np.allclose(fitted.to_metres(px), expected.to_metres(px), atol=2e-5)
    with pytest.raises(ValueError, match='no 9 x 6 checkerboard'):
        fit_homography(np.full((100, 100), 255, np.uint8))


def test_calibrate_camera_writes_the_homography_into_the_params_file(tmp_path):
    image, expected = board_image()
    cv2.imwrite(str(tmp_path / 'board.png'), image)
    params = tmp_path / 'tracker.yaml'
    params.write_text('tracker_node:\n  ros__parameters:\n    base_px: [10.0, 20.0]\n')
    done = subprocess.run([str(ROOT / 'scripts' / 'calibrate_camera'), str(tmp_path / 'board.png'),
                           '--square-mm', '2', '--write', str(params)],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    section = yaml.safe_load(params.read_text())['tracker_node']['ros__parameters']
    assert section['base_px'] == [10.0, 20.0]
    fitted = HomographyMap(section['homography'])
    px = np.array([[400.0, 300.0], [700.0, 500.0]])
    assert np.allclose(fitted.to_metres(px), expected.to_metres(px), atol=2e-5)
    bad = subprocess.run([str(ROOT / 'scripts' / 'calibrate_camera'), str(params),
                          '--square-mm', '2'], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and 'is not an image' in bad.stderr
