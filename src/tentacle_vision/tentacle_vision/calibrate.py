"""
scripts/calibrate_camera: the pixels-to-metres homography from a checkerboard image.

    scripts/calibrate_camera board.png --pattern 9x6 --square-mm 5 [--origin-mm X Y]
                             [--write config/tracker.yaml]

Finds the board's inner corners (cv2.findChessboardCorners, refined to sub-pixel), fits
the homography that puts the first corner at ``--origin-mm`` and the board's rows along +x
(columns along -y), prints it with its scale at the image centre, and with ``--write`` puts it
into a params file's tracker_node section, where tracker_node reads it: only the
``homography`` lines change (added if missing), comments and other keys stay; a file this
cannot edit safely is left alone, with the line to paste printed. The pattern needs at least
3 x 3 inner corners (OpenCV's limit) and the image at least MIN_SQUARE_PX pixels per square.

Exit status: 0 fitted (and written); 2 bad input: the arguments, an image that is not one
or has no board, a params file that cannot be edited (the file and value named).
"""

import argparse
import math
import pathlib
import re
import sys

import cv2
import numpy as np
from tentacle_common.yaml_files import (
    FileRefused, flow_list, read_bytes, read_text, set_flow_list, write_text)
from tentacle_vision.params import TRACKER_NODE
from tentacle_vision.pixels import fit_homography

MAX_IMAGE_BYTES = 256 << 20  # a camera frame is a few MB even as an uncompressed TIFF
MIN_CORNERS = 3  # per side: cv2.findChessboardCorners refuses fewer
MIN_SQUARE_PX = 4  # a square smaller than this cannot be told from noise
NEW_FILE_HEADER = ('# tracker_node parameters; homography fitted by scripts/calibrate_camera\n')


class Refused(Exception):
    """An input the tool cannot use; the message names it."""


def pattern_type(text):
    """Return (columns, rows) of inner corners from 'CxR'; argparse type."""
    match = re.fullmatch(r'\s*(\d+)\s*[xX]\s*(\d+)\s*', text)
    if not match:
        raise argparse.ArgumentTypeError(f'{text!r} is not COLUMNSxROWS, e.g. 9x6')
    cols, rows = int(match[1]), int(match[2])
    if min(cols, rows) < MIN_CORNERS:
        raise argparse.ArgumentTypeError(
            f'{text}: a board needs at least {MIN_CORNERS}x{MIN_CORNERS} inner corners '
            '(count the corners where four squares meet, not the squares)')
    return cols, rows


def positive_mm(text):
    """Return a finite, positive length in mm; argparse type."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'{text!r} is not a number') from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f'{text}: must be a positive length in mm (a '
                                         'negative one mirrors the homography)')
    return value


def finite_mm(text):
    """Return a finite length in mm; argparse type."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'{text!r} is not a number') from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f'{text}: must be finite')
    return value


def build_parser():
    """Return the command-line parser."""
    parser = argparse.ArgumentParser(prog='calibrate_camera',
                                     description=__doc__.strip().split('\n')[0])
    parser.add_argument('image', help='a camera frame of the checkerboard on the work plane')
    parser.add_argument('--pattern', default=(9, 6), type=pattern_type,
                        help='inner corners, columns x rows (default 9x6; at least 3x3)')
    parser.add_argument('--square-mm', type=positive_mm, required=True,
                        help="the board's square, mm (positive)")
    parser.add_argument('--origin-mm', type=finite_mm, nargs=2, default=(0.0, 0.0),
                        help='where the first corner is in the workspace, mm')
    parser.add_argument('--write', help='a params file to put the homography into')
    return parser


def read_image(path, pattern):
    """
    Return a file's image in grey, large enough for the pattern.

    :raises Refused: not a regular file, not an image, or too small for the pattern
    """
    try:
        data = read_bytes(path, MAX_IMAGE_BYTES)
    except OSError as exc:
        raise Refused(f'{path}: cannot be read: {exc.strerror or exc}') from None
    except FileRefused as exc:
        raise Refused(f'{path}: {exc}') from None
    image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_GRAYSCALE)
    if image is None:
        raise Refused(f'{path} is not an image (png, jpg, bmp, tif)')
    # The board may be turned either way in the frame: compare short side with short side.
    need = sorted(MIN_SQUARE_PX * (n + 1) for n in pattern)
    have = sorted(image.shape)
    if have[0] < need[0] or have[1] < need[1]:
        raise Refused(f'{path}: {image.shape[1]} x {image.shape[0]} px is too small for a '
                      f'{pattern[0]} x {pattern[1]} board (at least {need[1]} x {need[0]} px: '
                      f'{MIN_SQUARE_PX} px a square)')
    return image


def write_homography(path, h):
    """
    Put the homography into a params file's tracker_node section, keeping everything else.

    :raises Refused: the file cannot be read, written or edited safely; nothing is written
    """
    path = pathlib.Path(path)
    try:
        text = read_text(path) if path.exists() or path.is_symlink() else NEW_FILE_HEADER
        write_text(path, set_flow_list(text, TRACKER_NODE, 'homography', h, per_line=3))
    except OSError as exc:
        raise Refused(f'{path}: {exc.strerror or exc}; nothing written') from None
    except FileRefused as exc:
        raise Refused(f'{path}: {exc}; nothing written. Put this under {TRACKER_NODE}: '
                      f'ros__parameters: by hand:\n  homography: {flow_list(h)}') from None


def main(args=None):
    """Fit, report, and write if asked; exit 2 with the reason on any bad input."""
    opts = build_parser().parse_args(args)
    try:
        image = read_image(opts.image, opts.pattern)
        try:
            fitted = fit_homography(image, opts.pattern, opts.square_mm * 1e-3,
                                    np.asarray(opts.origin_mm) * 1e-3)
        except ValueError as exc:
            raise Refused(f'{opts.image}: {exc}') from None
        except cv2.error as exc:  # a last line of defence: OpenCV's own refusal, named
            raise Refused(f'{opts.image}: OpenCV could not search it: '
                          f'{str(exc).strip().splitlines()[-1]}') from None
        h = (fitted.h / fitted.h[2, 2]).ravel().tolist()
        print('homography (pixels -> workspace metres, row-major):')
        print('  ' + flow_list(h))
        print(f'scale at the image centre: '
              f'{fitted.metres_per_px_at(np.array(image.shape[::-1]) / 2) * 1e6:.2f} um/px')
        if opts.write:
            write_homography(opts.write, h)
            print(f'written to {opts.write} ({TRACKER_NODE}.ros__parameters.homography)')
    except Refused as exc:
        print(f'calibrate_camera: {exc}', file=sys.stderr)
        sys.exit(2)


if __name__ == '__main__':
    main()
