"""
sim_node's parameters, in one table: name, default, range, unit, description.

Plain data (no rclpy), as the drivers' tables. Names are those of DESIGN.md ("The simulated
rig"); ``base_px`` and ``metres_per_px`` mean what they mean to tracker_node, which must be
given the same (config/sim/tracker.yaml is).
"""

from tentacle_coils.params import REFERENCE_MATRIX_T_PER_A
from tentacle_common.params import Param

NODE_NAME = 'sim_node'
DEFAULT_DEVICE_DIR = '/tmp/tentacle_sim'

SIM_PARAMS = (
    Param('scene', '', 'the scene file: tentacle, model, path, phantom, mismatch (required)'),
    Param('schedule', '', 'a schedule file: the tentacle is the one made to its plan (the '
          "planned magnetisation), simulated with the plan's sub-links, in place of the "
          "scene's (empty: the scene's)"),
    Param('device_dir', DEFAULT_DEVICE_DIR, 'where the device links go: coil_x, coil_y, '
          'coil_z, inserter, backbone (created; one sim_node per folder)'),
    Param('coil_dialect', 'dxkdp', 'the emulated supplies: dxkdp (9600 baud, bus address 1) '
          'or scpi (115200 baud)'),
    Param('actuation_matrix', list(REFERENCE_MATRIX_T_PER_A), "the coils' true B = A I, "
          'tesla per ampere, row-major (the mismatch block scales its columns)'),
    Param('camera_rate', 30.0, 'frames, /sim/shape and physics, hertz', 0.5, 120.0),
    Param('image_size', [2048, 1536], 'frame width and height, pixels', 16, 8192),
    Param('metres_per_px', 5e-5, 'image scale, metre per pixel (as tracker_node)', 1e-7, 1.0),
    Param('base_px', [400.0, 768.0], 'where the insertion point images (u, v), pixels (as '
          'tracker_node)', -1e5, 1e5),
    Param('insertion_offset_m', 0.0, "the inserter stage's position with the tip at the "
          'insertion point, metre', -1.0, 1.0),
    Param('physics_budget', 0.5, "the physics' share of a frame period: a solve cut there "
          'goes on at the next frame', 0.05, 1.0),
    Param('markers_rate', 5.0, '/sim/markers, hertz (0: off)', 0.0, 60.0),
    Param('noise', True, 'sensor noise in the frames'),
    Param('artefacts', True, "what a real camera sees besides the body: the inserter's dark "
          'sheath up to the insertion point, fluid in the channel, glare (tracker_node then '
          'needs a background_image: /vision/capture_background before inserting)'),
    Param('coil_resistance_ohm', 1.0, 'each emulated coil: resistance, ohm', 1e-3, 1e3),
    Param('coil_inductance_h', 0.01, 'each emulated coil: inductance, henry (L/R is the lag '
          "of the current behind the supply's setpoint)", 0.0, 10.0),
    Param('compliance_v', 60.0, "each supply's largest output voltage, volt", 0.1, 1000.0),
)
