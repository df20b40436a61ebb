"""The tests' node on the simulated rig: the lab's facade (RigCommander) keeping its truth."""

import numpy as np
from tentacle_common import contract
from tentacle_rig.commander_node import RigCommander

FOLLOWED = {'shape': contract.SIM_SHAPE, 'tip': contract.VISION_TIP,
            'contact': contract.SIM_CONTACT, 'markers': contract.SIM_MARKERS}


def stamp_s(msg):
    """Return a message's header stamp, s."""
    return msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec


def points_of(path_msg):
    """Return (N, 3) the positions of a nav_msgs/Path, m."""
    return np.array([[p.pose.position.x, p.pose.position.y, p.pose.position.z]
                     for p in path_msg.poses])


class SimProbe(RigCommander):
    """RigCommander named sim_probe, keeping the simulator's shape, contact and markers."""

    def __init__(self):
        """Start the facade and follow the simulator's topics."""
        super().__init__('sim_probe', axes=('inserter',))
        for key, topic in FOLLOWED.items():
            self.follow(key, topic)

    def shape(self, since=-np.inf):
        """Return the newest /sim/shape points (N, 3) received after a time, or None."""
        msg = self.latest('shape', since)
        return None if msg is None else points_of(msg)


def arc_length_m(points):
    """Return the length of a polyline (N, 3), m."""
    return float(np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1))) if len(points) > 1 \
        else 0.0
