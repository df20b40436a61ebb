"""scripts/ros2_run's own usage errors: exit 2 and a message, as the project's other tools."""

import os
import pathlib
import subprocess
import sys

import pytest
from rig_support import ROOT

VENV_BIN = str(pathlib.Path(sys.executable).parent)

VENV = str(pathlib.Path(sys.executable).parents[1])

# (arguments, the ament index's search path, exit status, a piece of the output); no
# workspace sourced: at most the venv's own packages indexed
CASES = [
    ([], None, 2, 'a PACKAGE and an EXECUTABLE are needed'),
    (['tentacle_coils'], None, 2, 'a PACKAGE and an EXECUTABLE are needed'),
    (['tentacle_coils', 'coils_node'], None, 2,
     'AMENT_PREFIX_PATH is not set: source ros_ws/install/setup.bash first'),
    (['no_such_package', 'node'], VENV, 2,
     "package 'no_such_package' not found in the ament index (did you source"),
    (['a/b', 'node'], VENV, 2, "package 'a/b' not found"),
    (['rclpy', 'no_such_node'], VENV, 2, "no executable 'no_such_node' in"),
    (['--help'], None, 0, 'usage: ros2_run PACKAGE EXECUTABLE'),
]


@pytest.mark.parametrize('args, index, status, message', CASES)
def test_usage_errors_exit_2(args, index, status, message):
    env = {'PATH': f'{VENV_BIN}:/usr/bin:/bin', 'HOME': os.environ.get('HOME', '/root'),
           **({'AMENT_PREFIX_PATH': index} if index else {})}
    done = subprocess.run([str(ROOT / 'scripts' / 'ros2_run'), *args], capture_output=True,
                          text=True, timeout=60, env=env)
    assert done.returncode == status, done.stdout + done.stderr
    assert message in (done.stdout if status == 0 else done.stderr)
    assert 'Traceback' not in done.stderr
