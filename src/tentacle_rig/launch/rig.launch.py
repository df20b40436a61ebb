"""
Launch the rig on a lab PC with ROS 2 Jazzy: the process table scripts/rig runs.

    ros2 launch tentacle_rig rig.launch.py config:=/path/to/lab/config    # the real rig
    ros2 launch tentacle_rig rig.launch.py scene:=config/scenes/pancreatic_duct.yaml
    ... schedule:=out/schedule.yaml record:=out/bags/today               # player, recorder

The nodes are tentacle_rig.bringup's table (real_table for ``config``, sim_table for
``scene``) through tentacle_rig.launch_rows, so this file and scripts/rig start the same
nodes with the same parameters. ``root`` is the project folder holding config/ (default:
where ros2 launch runs). Launch stops every node at once on Ctrl-C, each driver to its own
safe state; scripts/rig stops them in order (the player first, the simulator last): prefer
it where the order matters (the simulated rig, whose devices go with the simulator).
"""

import os

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from tentacle_rig.bringup import real_table, sim_table
from tentacle_rig.launch_rows import launch_rows

ARGUMENTS = {'config': "a folder of the lab's params files: the real rig",
             'scene': 'a scene file: the simulated rig', 'schedule': 'run player_node for it',
             'record': 'record into this rosbag2 directory', 'root': 'the project folder'}


def nodes(context):
    """Return the Node actions of the table the launch arguments name."""
    value = {name: LaunchConfiguration(name).perform(context) or None for name in ARGUMENTS}
    root = value['root'] or os.getcwd()
    if bool(value['config']) == bool(value['scene']):
        raise RuntimeError('rig.launch.py: give config:=FOLDER (real rig) or scene:=FILE '
                           '(simulated rig), one of them')
    if value['config']:
        table = real_table(value['config'], root, value['schedule'], None, value['record'])
    else:
        table = sim_table(value['scene'], root, None, True, value['schedule'], None,
                          value['record'])
    return [Node(output='screen', **row) for row in launch_rows(table)]


def generate_launch_description():
    """Declare the arguments; build the nodes from the process table when launched."""
    return LaunchDescription(
        [DeclareLaunchArgument(name, default_value='', description=text)
         for name, text in ARGUMENTS.items()] + [OpaqueFunction(function=nodes)])
