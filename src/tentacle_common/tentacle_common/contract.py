"""
The rig's contract (DESIGN.md "Topic contract" and "Frames"), as data: one place for names.

Every topic's name, message type and QoS, every service's name and type, and the frame ids.
Nodes, tests, benches and scripts take them from here; ``driver_node`` turns a row into a
publisher, subscription, service or client. Pure: no rclpy (a ``Qos`` row is what the
profile is, ``driver_node.qos_profile`` builds it).
"""

from dataclasses import dataclass
import re

COILS_FRAME = 'coils'          # the coil centre: every field, the model's world
WORKSPACE_FRAME = 'workspace'  # the image plane, metres, origin where base_px images
CAMERA_FRAME = 'camera'        # the frames' own header frame (camera_node's default)

AXES = ('inserter', 'backbone')  # the stages DESIGN.md names (any ROS name token works)


@dataclass(frozen=True)
class Qos:
    """A QoS profile as data: keep the last ``depth``, reliable or best effort, latched."""

    depth: int
    reliable: bool = True
    latched: bool = False  # transient local: a late subscriber gets the last message


STREAM = Qos(10)         # commands, states, measurements
LATCHED = Qos(1, latched=True)   # /estop: whoever starts later still sees it
# Camera frames: the latest two, reliable (NOTES.md section 4: best effort loses most 3 MB
# frames between two processes).
FRAMES = Qos(2)
DEBUG = Qos(1)


@dataclass(frozen=True)
class Topic:
    """One topic: its name, message type (``pkg/msg/Name``), QoS and frame id ('' any)."""

    name: str
    msg_type: str
    qos: Qos = STREAM
    frame_id: str = ''


@dataclass(frozen=True)
class Service:
    """One service: its name and type (``pkg/srv/Name``)."""

    name: str
    srv_type: str


FIELD_CMD = Topic('/coils/field_cmd', 'geometry_msgs/msg/Vector3Stamped', frame_id=COILS_FRAME)
FIELD = Topic('/coils/field', 'geometry_msgs/msg/Vector3Stamped', frame_id=COILS_FRAME)
CURRENTS = Topic('/coils/currents', 'geometry_msgs/msg/Vector3Stamped', frame_id=COILS_FRAME)
COILS_ENABLE = Service('/coils/enable', 'std_srvs/srv/SetBool')
ESTOP = Topic('/estop', 'std_msgs/msg/Bool', LATCHED)
DIAGNOSTICS = Topic('/diagnostics', 'diagnostic_msgs/msg/DiagnosticArray')

IMAGE = Topic('/camera/image_raw', 'sensor_msgs/msg/Image', FRAMES, CAMERA_FRAME)
CAMERA_INFO = Topic('/camera/camera_info', 'sensor_msgs/msg/CameraInfo', frame_id=CAMERA_FRAME)
VISION_TIP = Topic('/vision/tip', 'geometry_msgs/msg/PoseStamped', frame_id=WORKSPACE_FRAME)
VISION_SHAPE = Topic('/vision/shape', 'nav_msgs/msg/Path', frame_id=WORKSPACE_FRAME)
VISION_LOOP = Topic('/vision/loop', 'sensor_msgs/msg/JointState', frame_id=WORKSPACE_FRAME)
VISION_CAPTURE_BACKGROUND = Service('/vision/capture_background', 'std_srvs/srv/Trigger')
VISION_DEBUG = Topic('/vision/debug_image', 'sensor_msgs/msg/Image', DEBUG, WORKSPACE_FRAME)

SIM_SHAPE = Topic('/sim/shape', 'nav_msgs/msg/Path', frame_id=COILS_FRAME)
SIM_MARKERS = Topic('/sim/markers', 'visualization_msgs/msg/MarkerArray')
SIM_CONTACT = Topic('/sim/contact', 'sensor_msgs/msg/JointState', frame_id=COILS_FRAME)
PLAYER_PROGRESS = Topic('/player/progress', 'sensor_msgs/msg/JointState')
PROGRESS_NAMES = ('step', 'steps', 'insertion', 'shape_rms', 'tip_error')  # index, count, m
# player_node's services (std_srvs/Trigger): start inserts, retract plays backwards
PLAYER_VERBS = ('start', 'retract', 'pause', 'resume', 'abort')


def player_service(verb):
    """Return /player/<verb> (std_srvs/Trigger): start, retract, pause, resume, abort."""
    if verb not in PLAYER_VERBS:
        raise ValueError(f'{verb!r} is not a player service ({", ".join(PLAYER_VERBS)})')
    return Service(f'/player/{verb}', 'std_srvs/srv/Trigger')


_TOKEN = re.compile(r'[A-Za-z_][A-Za-z0-9_]*')


def is_name_token(name):
    """Return True when name is one ROS name token (rcl's rule: letters, digits, _)."""
    return bool(_TOKEN.fullmatch(name or ''))


def _checked_axis(axis):
    if not is_name_token(axis):
        raise ValueError(f'axis {axis!r} is not one ROS name token (letters, digits, _)')
    return axis


def axis_target(axis):
    """Return /<axis>/target: absolute stage position, m (std_msgs/Float64)."""
    return Topic(f'/{_checked_axis(axis)}/target', 'std_msgs/msg/Float64')


def axis_state(axis):
    """Return /<axis>/state: position m, velocity m/s (sensor_msgs/JointState)."""
    return Topic(f'/{_checked_axis(axis)}/state', 'sensor_msgs/msg/JointState')


def axis_service(axis, verb):
    """Return /<axis>/stop, /<axis>/home (Trigger) or /<axis>/enable (SetBool)."""
    types = {'stop': 'std_srvs/srv/Trigger', 'home': 'std_srvs/srv/Trigger',
             'enable': 'std_srvs/srv/SetBool'}
    if verb not in types:
        raise ValueError(f'{verb!r} is not an axis service ({", ".join(types)})')
    return Service(f'/{_checked_axis(axis)}/{verb}', types[verb])


def axis_node_name(axis):
    """Return the node name an axis runs under: inserter_node, backbone_node, <axis>_node."""
    return f'{_checked_axis(axis)}_node'
