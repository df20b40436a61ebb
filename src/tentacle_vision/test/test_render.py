"""The frame renderer: its coverage is area-exact and its truth is the drawn centreline."""

import numpy as np
import pytest
from tentacle_vision.pixels import ScaleMap
from tentacle_vision.render import (_fill, _quads, centreline_of, Renderer, to_bayer_rggb,
                                    to_bgr)

MAP = ScaleMap(5e-5, (100.0, 700.0))


@pytest.mark.parametrize('angle_deg', [0.0, 10.0, 33.0, 45.0, 100.0, 260.0])
@pytest.mark.parametrize('width_px', [20.0, 7.3])
def test_coverage_has_the_area_of_the_body(angle_deg, width_px):
    a = np.radians(angle_deg)
    line = np.array([[250.0, 250.0], [250 + 200 * np.cos(a), 250 + 200 * np.sin(a)]])
    canvas = np.zeros((500, 500), np.float32)
    _fill(canvas, _quads(line, width_px))
    # Sampled on a 4 x 4 grid per pixel: an edge is placed to within half a sample, an eighth
    # of a pixel (where it runs along the grid the error does not average out).
    assert canvas.sum() == pytest.approx(200 * width_px, abs=2 * 200 / 8 + 1)
    assert canvas.max() <= 1.0


def test_a_bend_keeps_its_width_and_an_arc_its_area():
    r_px, width_px = 300.0, 20.0
    t = np.linspace(0, np.pi, 400)
    line = np.column_stack([400 + r_px * np.cos(t), 400 - r_px * np.sin(t)])
    canvas = np.zeros((500, 800), np.float32)
    _fill(canvas, _quads(line, width_px))
    assert canvas.sum() == pytest.approx(np.pi * r_px * width_px, rel=1e-3)


def test_the_truth_is_the_centreline_end_and_its_direction():
    line = centreline_of([(0.02, 0.0), (np.pi / 2 * 0.01, 100.0)])
    frame = Renderer(MAP, noise_sigma=0.0).render(line, 1e-3)
    assert np.allclose(frame.tip_m, [0.03, 0.01], atol=1e-9)
    assert frame.heading_rad == pytest.approx(np.pi / 2, abs=0.02)
    assert np.allclose(frame.tip_px, MAP.to_pixels(frame.tip_m)[0])
    assert np.allclose(frame.centreline_m[0], [0.0, 0.0])


def test_noise_blur_magnets_and_phantom_change_the_picture_not_the_truth():
    line = centreline_of([(0.03, 0.0)])
    plain = Renderer(MAP, noise_sigma=0.0, blur_px=0.0, lighting=0.0).render(line, 1e-3)
    busy = Renderer(MAP, noise_sigma=5.0, phantom_m=line).render(line, 1e-3,
                                                                 magnets_m=[(0.01, 0.02)])
    assert np.allclose(plain.tip_m, busy.tip_m)
    u = int(MAP.to_pixels([[0.015, 0.0]])[0, 0])
    assert busy.image[700, u] < plain.image[700, u]               # the magnet is darker
    assert 2.0 < np.std(busy.image[100:200, 1500:1600].astype(float)) < 8.0   # the noise
    assert plain.image[700, 1000] == 200                          # lit background, flat


def test_bayer_mosaic_keeps_each_colour_at_its_site():
    bgr = to_bgr(np.full((4, 4), 100, np.uint8))
    mosaic = to_bayer_rggb(bgr)
    assert mosaic[0, 0] == bgr[0, 0, 2] and mosaic[1, 1] == bgr[1, 1, 0]
    assert mosaic[0, 1] == bgr[0, 1, 1] == mosaic[1, 0]


def test_obstacles_and_walls_are_drawn_where_they_are():
    pixel_map = ScaleMap(1e-4, (100, 100))   # 0.1 mm/px, the origin at (100, 100) px
    plain = Renderer(pixel_map, (200, 200), noise_sigma=0.0, lighting=0.0).background
    drawn = Renderer(pixel_map, (200, 200), noise_sigma=0.0, lighting=0.0,
                     obstacles_m=[((0.003, 0.0), 0.002)],        # centre (130, 100) px, r 20
                     walls_m=[np.array([[-0.008, -0.005], [0.008, -0.005]])]).background
    darker = drawn.astype(int) < plain.astype(int) - 20
    v, u = np.mgrid[0:200, 0:200]
    disc = np.hypot(u - 130, v - 100) < 19
    wall = (np.abs(v - 150) < 1) & (np.abs(u - 100) < 79)   # y = -5 mm is v = 150 px
    assert darker[disc].all() and darker[wall].all()
    away = (np.hypot(u - 130, v - 100) > 22) & (np.abs(v - 150) > 3)
    assert not darker[away].any()
