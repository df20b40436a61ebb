"""
scripts/calibrate_camera: the pixels-to-metres homography from a checkerboard image.

    scripts/calibrate_camera board.png --pattern 9x6 --square-mm 5 [--origin-mm X Y]
                             [--write config/tracker.yaml]

Finds the board's inner corners (cv2.findChessboardCorners, refined to sub-pixel), fits
the homography that puts the first corner at ``--origin-mm`` and the board's rows along +x
(columns along -y), prints it with the residual at the corners, and with ``--write`` puts it
into a params file's tracker_node section (other keys kept), where tracker_node reads it.
"""

import argparse
import pathlib
import sys

import cv2
import numpy as np
from tentacle_vision.params import TRACKER_NODE
from tentacle_vision.pixels import fit_homography
import yaml


def build_parser():
    """Return the command-line parser."""
    parser = argparse.ArgumentParser(prog='calibrate_camera',
                                     description=__doc__.strip().split('\n')[0])
    parser.add_argument('image', help='a camera frame of the checkerboard on the work plane')
    parser.add_argument('--pattern', default='9x6', help='inner corners, columns x rows')
    parser.add_argument('--square-mm', type=float, required=True, help="the board's square")
    parser.add_argument('--origin-mm', type=float, nargs=2, default=(0.0, 0.0),
                        help='where the first corner is in the workspace, mm')
    parser.add_argument('--write', help='a params file to put the homography into')
    return parser


def main(args=None):
    """Fit, report, and write if asked; exit 1 with the reason when the board is not found."""
    opts = build_parser().parse_args(args)
    image = cv2.imread(opts.image, cv2.IMREAD_GRAYSCALE)
    if image is None:
        sys.exit(f'calibrate_camera: {opts.image} is not an image')
    try:
        cols, rows = (int(v) for v in opts.pattern.lower().split('x'))
        fitted = fit_homography(image, (cols, rows), opts.square_mm * 1e-3,
                                np.asarray(opts.origin_mm) * 1e-3)
    except ValueError as exc:
        sys.exit(f'calibrate_camera: {exc}')
    h = (fitted.h / fitted.h[2, 2]).ravel().tolist()
    print('homography (pixels -> workspace metres, row-major):')
    print('  [' + ', '.join(f'{v:.9g}' for v in h) + ']')
    print(f'scale at the image centre: '
          f'{fitted.metres_per_px_at(np.array(image.shape[::-1]) / 2) * 1e6:.2f} um/px')
    if opts.write:
        path = pathlib.Path(opts.write)
        document = yaml.safe_load(path.read_text()) if path.exists() else {}
        section = document.setdefault(TRACKER_NODE, {}).setdefault('ros__parameters', {})
        section['homography'] = h
        path.write_text(yaml.safe_dump(document, sort_keys=False))
        print(f'written to {path} ({TRACKER_NODE}.ros__parameters.homography)')


if __name__ == '__main__':
    main()
