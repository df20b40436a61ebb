"""The inserter's parameter checks that rcl does not make: the axis name."""

import pytest
from tentacle_common.errors import ConfigError
from tentacle_inserter.params import check_axis


@pytest.mark.parametrize('axis, name', [('inserter', 'inserter'), ('/backbone/', 'backbone'),
                                        ('axis_2', 'axis_2')])
def test_an_axis_name_is_one_ros_name_token(axis, name):
    assert check_axis(axis) == name


@pytest.mark.parametrize('axis', ['in-serter', '2nd', '', 'a/b', 'in serter', 'ü'])
def test_anything_else_is_refused_plainly(axis):
    with pytest.raises(ConfigError, match='is not a ROS name token'):
        check_axis(axis)
