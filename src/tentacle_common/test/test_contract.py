"""The rig contract: every row resolves to a real interface and a QoS rclpy accepts."""

import pytest
from rclpy.qos import DurabilityPolicy, ReliabilityPolicy
from tentacle_common import contract
from tentacle_common.driver_node import interface, node_name_of, qos_profile

ROWS = [v for v in vars(contract).values() if isinstance(v, (contract.Topic, contract.Service))]


@pytest.mark.parametrize('row', ROWS, ids=lambda r: r.name)
def test_every_row_names_an_interface_that_exists(row):
    kind = row.msg_type if isinstance(row, contract.Topic) else row.srv_type
    assert interface(kind).__name__ == kind.split('/')[-1]
    assert row.name.startswith('/') and len({r.name for r in ROWS}) == len(ROWS)


def test_the_estop_is_latched_and_frames_keep_the_latest_two_reliably():
    estop = qos_profile(contract.ESTOP.qos)
    assert (estop.durability, estop.reliability, estop.depth) == (
        DurabilityPolicy.TRANSIENT_LOCAL, ReliabilityPolicy.RELIABLE, 1)
    frames = qos_profile(contract.IMAGE.qos)
    assert (frames.durability, frames.reliability, frames.depth) == (
        DurabilityPolicy.VOLATILE, ReliabilityPolicy.RELIABLE, 2)


def test_axis_topics_and_node_names():
    assert contract.axis_target('backbone').name == '/backbone/target'
    assert contract.axis_state('inserter').msg_type == 'sensor_msgs/msg/JointState'
    assert contract.axis_service('backbone', 'enable').srv_type == 'std_srvs/srv/SetBool'
    assert contract.axis_node_name('backbone') == 'backbone_node'
    with pytest.raises(ValueError, match='not one ROS name token'):
        contract.axis_target('in-serter')
    with pytest.raises(ValueError, match='not an axis service'):
        contract.axis_service('inserter', 'jump')


@pytest.mark.parametrize('argv, name', [
    ([], 'inserter_node'),
    (['--ros-args', '-r', '__node:=backbone_node'], 'backbone_node'),
    (['--ros-args', '--remap', 'inserter_node:__node:=b2'], 'b2'),
    (['-r', '__node:=x', '--ros-args', '-p', 'a:=1'], 'inserter_node'),  # not a ROS argument
    (['--ros-args', '-r', '/old:=/new'], 'inserter_node'),               # a topic remap
])
def test_the_node_name_is_the_remapped_one(argv, name):
    assert node_name_of(argv, 'inserter_node') == name
