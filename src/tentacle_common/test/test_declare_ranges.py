"""A node's list parameters keep their range element by element, at declare and on set."""

import pytest
import rclpy
from rclpy.context import Context
from rclpy.exceptions import ParameterException
from rclpy.node import Node
from rclpy.parameter import Parameter
from tentacle_common.driver_node import declare_parameters
from tentacle_common.params import Param

TABLE = (
    Param('colour_low', [0, 0, 0], 'lowest blue, green, red', 0, 255),
    Param('gains', [1.0, 1.0], 'gains, 1', 0.0, 10.0),
    Param('rate', 10.0, 'hertz', 0.1, 100.0),
)


@pytest.fixture
def context():
    ctx = Context()
    rclpy.init(context=ctx, args=[])
    yield ctx
    rclpy.shutdown(context=ctx)


def make(context, overrides=(), read_only=True):
    node = Node('range_node', context=context, parameter_overrides=[
        Parameter(name, value=value) for name, value in overrides])
    try:
        return node, declare_parameters(node, TABLE, **({} if read_only else {
            'read_only': False}))
    except BaseException:
        node.destroy_node()
        raise


@pytest.mark.parametrize('overrides, message', [
    ([('colour_low', [300, 0, 0])], r'colour_low: element 0 is 300, outside \[0, 255\]'),
    ([('gains', [1.0, -0.5])], r'gains: element 1 is -0.5, outside \[0, 10\]'),
    ([('rate', 1000.0)], 'rate'),
])
def test_an_out_of_range_override_is_refused_at_declare(context, overrides, message):
    with pytest.raises(ParameterException, match=message):
        make(context, overrides)


def test_in_range_overrides_are_taken(context):
    node, values = make(context, [('colour_low', [10, 20, 255])])
    assert list(values['colour_low']) == [10, 20, 255]
    node.destroy_node()


def test_an_out_of_range_element_is_refused_on_set(context):
    node, _ = make(context, read_only=False)
    result, = node.set_parameters([Parameter('colour_low', value=[0, 256, 0])])
    assert not result.successful and 'colour_low: element 1 is 256' in result.reason
    assert list(node.get_parameter('colour_low').value) == [0, 0, 0]
    result, = node.set_parameters([Parameter('colour_low', value=[5, 6, 7])])
    assert result.successful
    node.destroy_node()
