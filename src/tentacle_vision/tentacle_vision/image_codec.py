"""
Camera frames as sensor_msgs/Image carries them (encoding, step, bytes) to numpy and back.

No ROS import: the node hands over the message's fields. mono8 and bgr8 arrive as they are
(no copy when the rows are packed), rgb8 is reordered, and bayer_rggb8 is demosaicked by
OpenCV (whose pattern names are shifted by one: ROS's RGGB is OpenCV's BayerBG, as cv_bridge
has it). ``for_tracking`` gives the tracker mono8, or bgr8 where it segments by colour.
"""

import cv2
import numpy as np

CHANNELS = {'mono8': 1, 'bgr8': 3, 'rgb8': 3, 'bayer_rggb8': 1}


def from_message(encoding, height, width, step, data):
    """
    Return the frame as a (height, width) or (height, width, 3) uint8 array.

    :raises ValueError: an encoding not in CHANNELS, or a step or size that does not match
    """
    if encoding not in CHANNELS:
        raise ValueError(f'image encoding {encoding!r} is not one of {sorted(CHANNELS)}')
    channels = CHANNELS[encoding]
    if step < width * channels or len(data) < step * height:
        raise ValueError(f'{encoding} image {width} x {height}: step {step} and '
                         f'{len(data)} bytes do not hold its rows')
    rows = np.frombuffer(data, np.uint8, count=step * height).reshape(height, step)
    image = rows[:, :width * channels]
    return image.reshape(height, width, channels) if channels == 3 else image


def for_tracking(encoding, image, colour=False):
    """Return mono8 (or bgr8 if ``colour``) of a decoded frame."""
    if encoding == 'bayer_rggb8':
        return cv2.cvtColor(image, cv2.COLOR_BayerBG2BGR if colour else cv2.COLOR_BayerBG2GRAY)
    if encoding == 'rgb8':
        return cv2.cvtColor(image, cv2.COLOR_RGB2BGR if colour else cv2.COLOR_RGB2GRAY)
    if encoding == 'bgr8':
        return image if colour else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    if image.ndim == 3:  # already converted (bgr8)
        return image if colour else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    if colour:
        raise ValueError('colour segmentation needs a colour image, not mono8')
    return image


def to_message(image, encoding):
    """Return (height, width, step, bytes) of an array in an encoding (for publishers)."""
    if encoding not in CHANNELS:
        raise ValueError(f'image encoding {encoding!r} is not one of {sorted(CHANNELS)}')
    channels = 1 if image.ndim == 2 else image.shape[2]
    if channels != CHANNELS[encoding]:
        raise ValueError(f'{encoding} needs {CHANNELS[encoding]} channels, got {channels}')
    image = np.ascontiguousarray(image, np.uint8)
    return image.shape[0], image.shape[1], image.shape[1] * channels, image.tobytes()


def read_background(path):
    """
    Return a background frame from an image file: mono8 or bgr8 (alpha dropped).

    :raises ValueError: the file is missing or not an image OpenCV reads
    """
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise ValueError(f'background_image {path}: missing or not an image')
    if image.ndim == 3 and image.shape[2] == 4:
        image = image[:, :, :3]
    return image.astype(np.uint8)
