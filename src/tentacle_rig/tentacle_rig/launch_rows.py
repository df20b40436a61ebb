"""
The process table as ROS 2 launch rows: what launch/rig.launch.py starts on a lab PC.

A lab PC with ROS 2 Jazzy may start the rig with ``ros2 launch tentacle_rig rig.launch.py``
instead of scripts/rig. The launch file builds its nodes from ``launch_rows`` of the very
table scripts/rig runs (bringup.sim_table or real_table), so the two cannot drift: each
entry's module ``package.executable_node`` is the package's console script of that name,
and its arguments after ``--ros-args`` are the node's ROS arguments. Pure: no rclpy, no
launch (neither is installable here: the rows are what is tested).
"""

ROS_ARGS = '--ros-args'


def launch_row(entry):
    """Return {package, executable, ros_arguments[, additional_env]} of one bringup.Entry."""
    package, _, executable = entry.module.partition('.')
    if not executable or '.' in executable:
        raise ValueError(f'{entry.name}: module {entry.module!r} is not package.executable')
    args = list(entry.args)
    if args and args[0] != ROS_ARGS:
        raise ValueError(f'{entry.name}: arguments before {ROS_ARGS}: {args}')
    row = {'package': package, 'executable': executable, 'ros_arguments': args[1:]}
    if entry.env:
        row['additional_env'] = dict(entry.env)
    return row


def launch_rows(table):
    """Return the launch rows of a process table, in its starting order."""
    return [launch_row(entry) for entry in table]
