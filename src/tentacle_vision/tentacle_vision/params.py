"""
The vision nodes' parameters, in tables: name, default, range, unit, description.

Plain data (no rclpy), as the drivers' tables: the nodes declare every row with a
descriptor, ``--help`` prints the table, and what a lab writes is checked against it. Names
of DESIGN.md (``base_px``, ``metres_per_px``, ``homography``) come first.
"""

from tentacle_common import contract
from tentacle_common.params import Param

TRACKER_NODE = 'tracker_node'
CAMERA_NODE = 'camera_node'

TRACKER_PARAMS = (
    Param('base_px', [0.0, 0.0], 'the insertion point (u, v), pixels: where the body starts'),
    Param('metres_per_px', 5e-5, 'image scale, metre per pixel (when no homography)',
          1e-7, 1.0),
    Param('homography', [0.0] * 9, 'pixels to workspace metres, 3 x 3 row-major (all zero: '
          'use metres_per_px with the origin at base_px); scripts/calibrate_camera fits it'),
    Param('background_image', '', 'a frame of the scene without the tentacle (taken before '
          'insertion; /vision/capture_background writes it): the body is what differs from '
          'it, in any colour; empty: none, the segmentation settings apply'),
    Param('image_topic', contract.IMAGE.name, 'frames: mono8, bgr8, rgb8 or bayer_rggb8'),
    Param('image_reliability', 'reliable', 'QoS of the frames: reliable or best_effort (to '
          'match a best-effort camera driver)'),
    Param('segmentation', 'otsu', 'otsu (of the contrast to the local background), adaptive, '
          'fixed or colour'),
    Param('dark', True, 'the body is darker than the background'),
    Param('threshold', 128, 'fixed: grey level between body and background', 0, 255),
    Param('block_px', 51, 'adaptive: local mean window, pixels (odd)', 3, 1001),
    Param('offset', 10, 'adaptive: below the local mean by this much, grey levels', -255, 255),
    Param('colour_low', [0, 0, 0], 'colour: lowest blue, green, red of the body', 0, 255),
    Param('colour_high', [255, 255, 255], 'colour: highest blue, green, red', 0, 255),
    Param('blur_px', 1.0, 'smoothing before thresholding, pixels (0: none)', 0.0, 20.0),
    Param('max_width_px', 40.0, 'otsu: the body is at most this wide, pixels', 1.0, 1000.0),
    Param('base_search_px', 30.0, 'the body must come this close to base_px, pixels',
          1.0, 4096.0),
    Param('min_body_px', 150, 'fewer pixels at the insertion point are not a body', 1,
          100_000_000),
    Param('band_px', 2.0, 'centreline spacing along the body, pixels', 0.5, 100.0),
    Param('fit_length_px', 80.0, "the tip's heading is fitted over this much body, pixels",
          4.0, 4096.0),
    Param('roi_margin_px', 80, 'search window around the last body, pixels', 0, 4096),
    Param('min_loop_area_px', 150.0, 'a smaller enclosed hole is not a loop, pixels^2',
          1.0, 1e8),
    Param('debug_rate', 2.0, 'rate of /vision/debug_image, hertz (0: off)', 0.0, 120.0),
    Param('debug_scale', 0.5, 'size of the debug image relative to the frame', 0.05, 1.0),
)

CAMERA_PARAMS = (
    Param('source', '0', 'a capture device number, a video file, or a folder of images'),
    Param('rate', 0.0, "frames per second (0: the source's own: a video's, a device's, "
          '30 for a folder)', 0.0, 1000.0),
    Param('encoding', 'bgr8', 'published encoding: bgr8 or mono8', ),
    Param('frame_id', contract.CAMERA_FRAME, 'header frame of the frames and the camera info'),
    Param('loop', False, 'replay a video or folder from the start when it ends'),
    Param('wait_for_subscriber', False, 'start when /camera/image_raw has a subscriber (a '
          'replay then loses no frame to discovery)'),
)
