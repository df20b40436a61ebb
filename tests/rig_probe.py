"""The tests' node on the coils: the lab's facade, RigCommander, keeping /coils/currents too."""

from tentacle_common import contract
from tentacle_rig.commander_node import RigCommander


def rig_probe():
    """Return a RigCommander named rig_probe, on no axis, keeping 'currents'; close() it."""
    probe = RigCommander('rig_probe', axes=())
    probe.follow('currents', contract.CURRENTS)
    return probe
