"""
Where camera_node's frames come from (no ROS): a capture device, a video file, or a folder.

``open_source(spec)`` returns a source with ``read()`` (the next frame, bgr8 or mono8, or
None at the end), ``rate_hz`` (its own frame rate, or None) and ``close()``. A folder
replays a recorded run: its images in name order (png, jpg, bmp, tif). A video and a
device go through OpenCV's VideoCapture.

A Basler or other GenICam camera is a source a lab plugs in the same way: a class with
those three members (with pypylon's ``InstantCamera.RetrieveResult``, or harvesters'
``fetch``) registered in ``SOURCES`` under a prefix, e.g. ``SOURCES['basler'] = Basler``;
``source:=basler:<serial>`` then opens it. Nothing else changes: camera_node publishes what
``read()`` returns.
"""

import pathlib

import cv2

IMAGE_SUFFIXES = ('.png', '.jpg', '.jpeg', '.bmp', '.tif', '.tiff')
FOLDER_RATE_HZ = 30.0  # a folder has no rate of its own
ENCODINGS = ('bgr8', 'mono8')  # what camera_node publishes


class CaptureSource:
    """An OpenCV VideoCapture: a device number or a video file."""

    def __init__(self, what, loop=False):
        """Open ``what`` (an int device or a path); raise ValueError if it does not open."""
        self.what, self.loop = what, loop
        self.capture = cv2.VideoCapture(what)
        if not self.capture.isOpened():
            raise ValueError(f'camera source {what!r} does not open (no such device or '
                             'file, or a format OpenCV cannot read)')
        fps = self.capture.get(cv2.CAP_PROP_FPS)
        self.rate_hz = float(fps) if fps and fps > 0 else None

    def read(self):
        """Return the next frame, or None at the end (a video that does not loop)."""
        ok, frame = self.capture.read()
        if not ok and self.loop and isinstance(self.what, str):
            self.capture.set(cv2.CAP_PROP_POS_FRAMES, 0)
            ok, frame = self.capture.read()
        return frame if ok else None

    def close(self):
        """Release the device or file."""
        self.capture.release()


class FolderSource:
    """The images of a folder in name order (a recorded run)."""

    rate_hz = None

    def __init__(self, folder, loop=False):
        """List the folder's images; raise ValueError if there are none."""
        self.paths = sorted(p for p in pathlib.Path(folder).iterdir()
                            if p.suffix.lower() in IMAGE_SUFFIXES)
        if not self.paths:
            raise ValueError(f'camera source {folder}: no images ({", ".join(IMAGE_SUFFIXES)})')
        self.loop, self.index = loop, 0

    def read(self):
        """Return the next image (mono8 if it is grey, else bgr8), or None at the end."""
        if self.index >= len(self.paths):
            if not self.loop:
                return None
            self.index = 0
        path = self.paths[self.index]
        self.index += 1
        image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if image is None:
            raise ValueError(f'camera source: {path} is not an image OpenCV can read')
        if image.ndim == 3 and image.shape[2] == 4:
            image = cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
        return image

    def close(self):
        """Nothing to release."""


SOURCES = {}  # prefix -> class(rest of the spec, loop): cameras a lab adds (see above)


def open_source(spec, loop=False):
    """
    Return the source a spec names: 'N' a device, a folder, a video file, or 'prefix:...'.

    :raises ValueError: nothing there, or it does not open
    """
    spec = str(spec).strip()
    prefix, sep, rest = spec.partition(':')
    if sep and prefix in SOURCES:
        return SOURCES[prefix](rest, loop)
    if spec.isdigit():
        return CaptureSource(int(spec), loop)
    path = pathlib.Path(spec)
    if path.is_dir():
        return FolderSource(path, loop)
    if path.is_file():
        return CaptureSource(str(path), loop)
    raise ValueError(f'camera source {spec!r}: not a device number, folder or file'
                     + (f' (known prefixes: {sorted(SOURCES)})' if SOURCES else ''))


def as_encoding(frame, encoding):
    """Return a frame (mono8 or bgr8) in the encoding to publish: bgr8 or mono8."""
    if encoding == 'mono8':
        return frame if frame.ndim == 2 else cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
    if encoding == 'bgr8':
        return frame if frame.ndim == 3 else cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR)
    raise ValueError(f'camera encoding {encoding!r} is not bgr8 or mono8')
