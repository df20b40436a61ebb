#!/usr/bin/env python3
"""
Benchmark: the tracker's time per 2048 x 1536 frame, one core, and the renderer's.

Frames are rendered (tentacle_vision.render) with noise, uneven lighting and a channel
phantom: straight, 90 deg and S-shaped bodies. Each is tracked 30 times in a row as a camera
would send it (the search window follows the body), as mono8 and as bayer_rggb8 (the
demosaicking counted), and once from scratch (the whole frame searched: the first frame, or
after the body was lost). The target is 8 ms median to keep up with 120 fps; 4 ms is the aim.

Run: .venv/bin/python bench/vision_speed.py
"""

import os
import pathlib
import statistics
import sys
import time

os.environ.setdefault('OMP_NUM_THREADS', '1')
ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path[:0] = [str(p) for p in sorted((ROOT / 'src').iterdir()) if (p / 'package.xml').exists()]

import cv2  # noqa: E402
import numpy as np  # noqa: E402
from tentacle_vision.pixels import ScaleMap  # noqa: E402
from tentacle_vision.render import centreline_of, Renderer, to_bayer_rggb, to_bgr  # noqa: E402
from tentacle_vision.tracker import Tracker  # noqa: E402

cv2.setNumThreads(1)  # one core, as the target says
BASE_PX = (120.0, 1000.0)
MAP = ScaleMap(5e-5, BASE_PX)
R = 0.015
SHAPES = {'straight': [(0.045, 0.0)],
          '90': [(0.02, 0.0), (np.pi / 2 * R, 1 / R), (0.01, 0.0)],
          'S': [(0.02, 0.0), (np.pi / 2 * R, 1 / R), (np.pi / 2 * R, -1 / R)]}
REPEATS = 30


def milliseconds(times):
    """Return 'median / p95 ms' of a list of seconds."""
    ordered = sorted(times)
    return (f'{statistics.median(times) * 1e3:6.2f} / '
            f'{ordered[int(0.95 * (len(ordered) - 1))] * 1e3:6.2f} ms')


def track_times(frame, encoding):
    """Return (times following the body, time from scratch) of one frame, s."""
    def once(tracker):
        t0 = time.perf_counter()
        track = tracker.track(frame, encoding)   # converts the window it searches
        elapsed = time.perf_counter() - t0
        assert track.found, track.reason
        return elapsed
    tracker = Tracker(BASE_PX, MAP)
    once(tracker)  # the first frame opens the window
    following = [once(tracker) for _ in range(REPEATS)]
    scratch = [once(Tracker(BASE_PX, MAP)) for _ in range(5)]
    return following, scratch


def main():
    """Render the frames, time the renderer and the tracker, print the table."""
    print(f'{cv2.getNumThreads()} OpenCV thread; 2048 x 1536 frames, 50 um/px, 1 mm body')
    renderer = Renderer(MAP, noise_sigma=3.0, lighting=0.3,
                        phantom_m=centreline_of(SHAPES['90']))
    Tracker(BASE_PX, MAP).track(renderer.render(centreline_of(SHAPES['90']), 1e-3).image)
    print('  shape     encoding      tracked (median / p95)   from scratch     render')
    everything = []
    for name, pieces in SHAPES.items():
        line = centreline_of(pieces)
        render_times = []
        for _ in range(10):
            t0 = time.perf_counter()
            rendered = renderer.render(line, 1e-3, magnets_m=[(0.01, 0.015)])
            render_times.append(time.perf_counter() - t0)
        for encoding in ('mono8', 'bayer_rggb8'):
            frame = rendered.image if encoding == 'mono8' else to_bayer_rggb(
                to_bgr(rendered.image))
            following, scratch = track_times(frame, encoding)
            everything += following
            print(f'  {name:8s}  {encoding:12s}  {milliseconds(following)}   '
                  f'{statistics.median(scratch) * 1e3:6.2f} ms    '
                  f'{statistics.median(render_times) * 1e3:6.2f} ms', flush=True)
    print(f'all frames followed: {milliseconds(everything)} (target 8 ms median, aim 4 ms)')


if __name__ == '__main__':
    main()
