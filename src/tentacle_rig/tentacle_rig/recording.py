"""
A run's recording: a rosbag2 directory (metadata.yaml and one MCAP file).

As ``ros2 bag`` writes it and Foxglove opens it, written and read with the rosbags package
(no ROS needed).

``Recording`` takes serialized (CDR) messages of the contract's topics, each under its
type's Jazzy definition and its QoS, and is closed into a bag that ``ros2 bag info`` and
``read_bag`` read back. Camera frames go in as sensor_msgs/CompressedImage on
``/camera/image_raw/compressed`` (image_transport's name: JPEG or PNG), decimated to a rate
(``FrameGate``); everything else is recorded whole. Pure: no rclpy.
"""

import pathlib

from rosbags.highlevel import AnyReader
from rosbags.interfaces import (Qos, QosDurability, QosHistory, QosLiveliness,
                                QosReliability, QosTime)
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import get_typestore, Stores

COMPRESSED_SUFFIX = '/compressed'   # image_transport's compressed frames
COMPRESSED_TYPE = 'sensor_msgs/msg/CompressedImage'
BAG_VERSION = 9                      # Jazzy's rosbag2 metadata version
_FOREVER = QosTime(0x7FFFFFFF, 0xFFFFFFFF)   # rosbag2's "infinite" duration


def typestore():
    """Return rosbags' ROS 2 Jazzy type store: message definitions and CDR codecs."""
    return get_typestore(Stores.ROS2_JAZZY)


def offered_qos(qos):
    """Return the rosbags Qos of a contract.Qos row (what the bag says was offered)."""
    return Qos(QosHistory.KEEP_LAST, qos.depth,
               QosReliability.RELIABLE if qos.reliable else QosReliability.BEST_EFFORT,
               QosDurability.TRANSIENT_LOCAL if qos.latched else QosDurability.VOLATILE,
               _FOREVER, _FOREVER, QosLiveliness.AUTOMATIC, _FOREVER, False)


class Recording:
    """One bag directory being written."""

    def __init__(self, path, topics):
        """
        Create the bag directory (it must not exist) with a connection per topic.

        :param path: the bag directory: metadata.yaml and <name>_0.mcap go in it
        :param topics: contract.Topic rows; a topic of sensor_msgs/Image is recorded as its
            CompressedImage on <name>/compressed
        :raises FileExistsError: the directory exists (a run never overwrites another)
        """
        self.path = pathlib.Path(path)
        if self.path.exists():
            raise FileExistsError(f'{self.path} exists: a recording never overwrites another')
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.store = typestore()
        self.writer = Writer(self.path, version=BAG_VERSION, storage_plugin=StoragePlugin.MCAP)
        self.writer.open()
        self.connections, self.counts = {}, {}
        for topic in topics:
            name, msg_type = self.recorded_as(topic)
            self.connections[topic.name] = self.writer.add_connection(
                name, msg_type, typestore=self.store,
                offered_qos_profiles=[offered_qos(topic.qos)])
            self.counts[topic.name] = 0
        self.closed = False

    @staticmethod
    def recorded_as(topic):
        """Return (topic name, type) a contract topic is recorded under."""
        if topic.msg_type == 'sensor_msgs/msg/Image':
            return topic.name + COMPRESSED_SUFFIX, COMPRESSED_TYPE
        return topic.name, topic.msg_type

    def write(self, topic_name, time_ns, cdr):
        """Add one serialized message of a topic, received at time_ns (ns since the epoch)."""
        if self.closed:
            return
        self.writer.write(self.connections[topic_name], int(time_ns), bytes(cdr))
        self.counts[topic_name] += 1

    def close(self):
        """Finish the MCAP file and write metadata.yaml; return {topic: messages written}."""
        if not self.closed:
            self.closed = True
            self.writer.close()
        return dict(self.counts)


class FrameGate:
    """Let a frame through at most every 1/rate seconds (rate 0: none; None: every one)."""

    def __init__(self, rate_hz):
        """Fix the rate, Hz."""
        if rate_hz is None:
            self.period_s = None
        else:
            self.period_s = float('inf') if rate_hz <= 0 else 1.0 / rate_hz
        self._next = -float('inf')

    def passes(self, time_s):
        """Return whether a frame received at time_s (s) is recorded."""
        if self.period_s is None:
            return True
        if time_s < self._next:
            return False
        self._next = time_s + self.period_s
        return True


def read_bag(path, topics=None):
    """
    Return {topic: [(receive time ns, message)]} of a bag directory, in time order.

    :param topics: only these topic names (default every one)
    :raises rosbags errors: a bag that is not there or not readable
    """
    out = {}
    with AnyReader([pathlib.Path(path)], default_typestore=typestore()) as reader:
        connections = [c for c in reader.connections if topics is None or c.topic in topics]
        for connection, time_ns, raw in reader.messages(connections=connections):
            out.setdefault(connection.topic, []).append(
                (time_ns, reader.deserialize(raw, connection.msgtype)))
    return out
