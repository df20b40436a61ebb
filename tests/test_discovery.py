"""
Who may command the rig: a participant on another domain sees none of it and moves nothing.

The coil driver runs on emulated supplies in this run's private domain with discovery on this
machine only (rig_support: as scripts/rig does by default, tentacle_common.discovery). A
second process on another domain lists what it can see and commands a field for two seconds;
the supplies themselves say whether anything reached them. The same commands from inside the
domain do reach them (the test can fail). LOCALHOST itself keeps other machines out, which one
machine cannot show: the test checks that every process of the rig is started with it.
"""

import os
import subprocess
import sys
import textwrap
import time

import pytest
from rig_support import DOMAIN_ID, ROOT, wait_for
from tentacle_common import contract
from tentacle_common.discovery import DEFAULT_DOMAIN_ID, private_by_default
from tentacle_rig.commander_node import RigCommander

pytestmark = pytest.mark.ros

OUTSIDER = textwrap.dedent("""
    import time
    import rclpy
    from geometry_msgs.msg import Vector3Stamped
    from tentacle_common import contract
    from tentacle_common.driver_node import publisher, subscription
    rclpy.init()
    node = rclpy.create_node('outsider')
    heard = []
    subscription(node, contract.FIELD, heard.append)
    pub = publisher(node, contract.FIELD_CMD)
    end = time.monotonic() + 3.0
    while time.monotonic() < end:
        msg = Vector3Stamped()
        msg.header.frame_id = contract.COILS_FRAME
        msg.vector.y = 0.005
        pub.publish(msg)
        rclpy.spin_once(node, timeout_sec=0.1)
    names = sorted(name for name, _ in node.get_topic_names_and_types())
    print('TOPICS', ','.join(names))
    print('NODES', ','.join(node.get_node_names()))
    print('HEARD', len(heard))
    node.destroy_node()
    rclpy.shutdown()
""")


def outsider(domain):
    """Run the outsider on a domain; return its TOPICS, NODES and HEARD lines."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain))
    done = subprocess.run([sys.executable, '-c', OUTSIDER], env=env, capture_output=True,
                          text=True, timeout=60, cwd=ROOT)
    assert done.returncode == 0, done.stderr
    return dict(line.split(' ', 1) for line in done.stdout.splitlines() if ' ' in line)


def test_another_domain_sees_nothing_of_the_rig_and_commands_nothing(coil_rig):
    emulators, node = coil_rig()
    assert wait_for(lambda: all(emulators.outputs()), 20.0), node.output()
    # What reached the supplies is read from their own logs of set requests: the driver's
    # watchdog ramps a field no longer commanded back to zero 1 s after the outsider stops,
    # which a slow teardown of the outsider's process may outlast.
    before = time.monotonic()
    seen = outsider((DOMAIN_ID + 1) % 233)
    # Its own two topics only: none of the driver's (its currents, its diagnostics), no node.
    assert seen['TOPICS'].split(',') == sorted([contract.FIELD.name, contract.FIELD_CMD.name,
                                                '/parameter_events', '/rosout'])
    assert seen['NODES'] == 'outsider'
    assert seen['HEARD'] == '0'
    sets = emulators.sets_since(before)
    assert not any(abs(current) > 1e-9 for axis in 'xyz' for current in sets[axis]), sets
    # From inside the domain the same commands are heard and obeyed.
    before = time.monotonic()
    inside = outsider(DOMAIN_ID)
    assert 'coils_node' in inside['NODES'] and contract.CURRENTS.name in inside['TOPICS']
    assert int(inside['HEARD']) > 0
    target = 0.005 / 1.07e-3
    assert wait_for(lambda: any(abs(current - target) < 0.01
                                for current in emulators.sets_since(before)['y']), 5.0)


def test_the_rigs_processes_default_to_a_private_domain_on_this_machine():
    environ = {}
    line = private_by_default(environ)
    assert environ == {'ROS_DOMAIN_ID': str(DEFAULT_DOMAIN_ID),
                       'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}
    assert 'this machine only' in line and DEFAULT_DOMAIN_ID != 0
    lab = {'ROS_DOMAIN_ID': '3', 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'SUBNET'}
    assert 'as the environment sets' in private_by_default(lab)
    assert lab == {'ROS_DOMAIN_ID': '3', 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'SUBNET'}
    # The facade keeps what a test (or a lab) chose: this run's private domain.
    with RigCommander('domain_check'):
        assert os.environ['ROS_DOMAIN_ID'] == str(DOMAIN_ID)
