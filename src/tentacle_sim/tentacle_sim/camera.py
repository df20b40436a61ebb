"""
The simulated camera: frames of the body in the phantom, as the tracker will see them.

A camera looking down ``coils`` z, calibrated as tracker_node is (``metres_per_px``, the
insertion point at ``base_px``): the scene's nominal insertion point is the ``workspace``
origin (tentacle_common.frames), so a mismatch that moves the real insertion point shows as
a body that starts off ``base_px``, as on the rig. The phantom (a channel along the path,
the scene's obstacles and walls) and, with ``artefacts``, what a rig's camera sees besides
(the inserter's dark sheath up to the insertion point, fluid in the channel, glare on its
walls) are drawn into the background once; each frame draws the body with
tentacle_vision's renderer (its magnetised segments darker).
"""

import numpy as np
from tentacle_common import frames
from tentacle_vision.pixels import ScaleMap
from tentacle_vision.render import Renderer

CHANNEL_WIDTH_M = 0.004  # the phantom's channel along the path, drawn behind the body
SHEATH_WIDTH_M, SHEATH_LENGTH_M = 0.004, 0.06   # the inserter's sheath, up to the insertion
FLUID = 0.15             # the fluid in the channel darkens it this much, mottled
GLARE_RADIUS_M = 6e-4    # specular spots on the channel's walls


class SimCamera:
    """Frames of one scene."""

    def __init__(self, scene, metres_per_px, base_px, size=(2048, 1536), noise=True,
                 artefacts=True):
        """
        Draw the phantom.

        :param scene: a tentacle_planner.scene.Scene
        :param metres_per_px: image scale, m/px
        :param base_px: (u, v) where the nominal insertion point images, px
        :param size: (width, height), px
        :param noise: sensor noise in every frame
        :param artefacts: draw what a real camera sees besides the body: the inserter's dark
            sheath up to the insertion point (it touches the body's base), fluid in the
            channel, glare on its walls
        """
        self.origin_m = scene.tentacle.base_position_m
        self.size = tuple(int(v) for v in size)
        path = self.workspace(scene.path.points_m)
        extras = {}
        if artefacts:
            inward = scene.tentacle.base_rotation[:2, 0]
            inward = inward / max(np.linalg.norm(inward), 1e-12)
            extras = {'fluid': FLUID, 'sheath_m': np.array([-SHEATH_LENGTH_M * inward,
                                                            [0.0, 0.0]]),
                      'sheath_width_m': SHEATH_WIDTH_M, 'glare_m': self._glare(path)}
        self.renderer = Renderer(
            ScaleMap(metres_per_px, base_px), self.size, noise_sigma=3.0 if noise else 0.0,
            phantom_m=path, phantom_width_m=CHANNEL_WIDTH_M,
            obstacles_m=[(self.workspace(s.centre_m)[0], s.radius_m) for s in scene.obstacles],
            walls_m=[self.workspace(w.points_m) for w in scene.walls], **extras)

    @staticmethod
    def _glare(path):
        """Return glare spots on the channel's walls, a third and two thirds along the path."""
        spots = []
        for k, side in ((len(path) // 3, 1.0), (2 * len(path) // 3, -1.0)):
            if 0 < k < len(path) - 1:
                d = path[k + 1] - path[k - 1]
                normal = np.array([-d[1], d[0]]) / max(np.linalg.norm(d), 1e-12)
                spots.append((path[k] + side * 0.5 * CHANNEL_WIDTH_M * normal, GLARE_RADIUS_M))
        return spots

    def workspace(self, points_m):
        """Return (N, 2) workspace points, m, of (N, 3) coils points."""
        return frames.workspace_from_coils(points_m, self.origin_m)

    def frame(self, points_m, width_m, magnets_m=()):
        """
        Return (mono8 frame, tip in workspace (2,) m or None) of a body.

        :param points_m: (n + 1, 3) the body's joints and tip, coils frame (fewer than two,
            or any not finite: nothing inserted to draw, the background alone)
        :param width_m: the body's width, m
        :param magnets_m: (start, end) arc lengths past the insertion point drawn darker, m
        """
        points = np.asarray(points_m, dtype=float)
        if len(points) < 2 or not np.all(np.isfinite(points)):
            return self.renderer.background.copy(), None
        centreline = self.workspace(points)
        if np.linalg.norm(centreline[-1] - centreline[0]) < 1e-6:
            return self.renderer.background.copy(), None   # end-on: nothing to see
        rendered = self.renderer.render(centreline, width_m, magnets_m)
        return rendered.image, rendered.tip_m
