"""
The lab-PC route: colcon builds ros_ws, executables land where `ros2 run` looks for them.

There is no ros2 command line on PyPI, so `ros2 run` is exercised through what it relies on:
the install layout and the ament index, via scripts/ros2_run in a freshly sourced shell.
"""

import os
import pathlib
import re
import signal
import subprocess
import sys
import time

import pytest
from rig_support import ROOT

pytestmark = pytest.mark.ros

EXECUTABLES = {  # DESIGN.md, "Packages" ('-': a package without executables)
    'tentacle_common': [],
    'tentacle_coils': ['coils_node'],
    'tentacle_inserter': ['inserter_node'],
    'tentacle_vision': ['camera_node', 'tracker_node'],
    'tentacle_model': ['tentacle-statics'],
    'tentacle_planner': ['tentacle-plan', 'player_node'],
    'tentacle_sim': ['sim_node', 'supply_emulator', 'stage_emulator'],
}
MORE_EXECUTABLES = {  # ours beyond DESIGN.md's table
    'tentacle_coils': ['calibrate_coils'],
    'tentacle_vision': ['calibrate_camera'],
    'tentacle_rig': ['rig', 'rig_command', 'recorder_node'],
    'tentacle_studies': ['tentacle-sweep', 'tentacle-inverse'],
}
# beyond DESIGN.md's table: the rig as a whole, design studies (DESIGN.md: tentacle-sweep)
MORE_PACKAGES = ['tentacle_rig', 'tentacle_studies']
COLCON = str(pathlib.Path(sys.executable).parent / 'colcon')


def test_design_table_matches_this_list():
    design = (ROOT.parent / 'shared' / 'DESIGN.md')
    if not design.exists():
        pytest.skip('shared/DESIGN.md is not beside this checkout')
    rows = re.findall(r'^\| (tentacle_\w+) \|[^|]*\| ([^|]+) \|$', design.read_text(), re.M)
    from_design = {pkg: [e.strip().split(' ')[0] for e in exes.split(',')
                         if e.strip() != '-'] for pkg, exes in rows}
    assert from_design == EXECUTABLES


@pytest.fixture(scope='module', params=['merge', 'isolated'])
def workspace(request, tmp_path_factory):
    """Build ros_ws once per layout into a temporary base; return its install directory."""
    base = tmp_path_factory.mktemp(f'colcon_{request.param}')
    argv = [COLCON, '--log-base', str(base / 'log'), 'build', '--build-base',
            str(base / 'build'), '--install-base', str(base / 'install')]
    if request.param == 'merge':
        argv.append('--merge-install')
    done = subprocess.run(argv, cwd=ROOT / 'ros_ws', capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    return request.param, base / 'install'


def lib_dir(layout, install, package):
    return install / 'lib' / package if layout == 'merge' else \
        install / package / 'lib' / package


def sourced(install, command, env_extra=None, **kwargs):
    """Run a shell command in a clean environment with the workspace sourced."""
    # As a lab user would have it: the venv's bin first on PATH (or ROS's own python3).
    env = {'HOME': os.environ.get('HOME', '/root'),
           'PATH': f'{pathlib.Path(sys.executable).parent}:/usr/bin:/bin',
           **(env_extra or {})}
    script = f'source {install}/setup.bash && {command}'
    return subprocess.Popen(['bash', '--norc', '-c', script], env=env, cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            start_new_session=True, **kwargs)


def test_every_package_is_ament_python():
    listing = subprocess.run([COLCON, 'list'], cwd=ROOT / 'ros_ws', capture_output=True,
                             text=True, timeout=60).stdout
    for package in [*EXECUTABLES, *MORE_PACKAGES]:
        assert re.search(rf'^{package}\s+src/{package}\s+\(ros\.ament_python\)$', listing,
                         re.M), listing


def test_executables_are_installed_and_indexed(workspace):
    layout, install = workspace
    for package, executables in [*EXECUTABLES.items(), *((p, MORE_EXECUTABLES.get(p, []))
                                                         for p in MORE_PACKAGES)]:
        marker = (install if layout == 'merge' else install / package) / \
            'share/ament_index/resource_index/packages' / package
        assert marker.exists(), f'{package} is not in the ament index'
        for executable in executables:
            path = lib_dir(layout, install, package) / executable
            assert path.exists() and os.access(path, os.X_OK), f'{path} missing'
    share = install if layout == 'merge' else install / 'tentacle_rig'
    assert (share / 'share/tentacle_rig/launch/rig.launch.py').is_file()   # for ros2 launch


def test_every_executable_answers_help_through_the_ament_index(workspace):
    layout, install = workspace
    every = [(p, e) for table in (EXECUTABLES, MORE_EXECUTABLES) for p, es in table.items()
             for e in es]
    for package, executable in every:
        proc = sourced(install, f'{ROOT}/scripts/ros2_run {package} {executable} --help')
        out, _ = proc.communicate(timeout=60)
        assert proc.returncode == 0, f'{package} {executable}: {out}'
        assert 'usage' in out.lower(), out


def run_from_install(install, emulator_command, node_command, started, stopped):
    """
    Run an emulator and a node through ros2_run, and stop the node with SIGINT.

    The node is stopped once it says ``started`` and that it runs (a SIGINT before it spins
    would interrupt its construction, which is not what is tested here); it must exit 0
    saying ``stopped``. Both are killed if anything hangs.
    """
    env = {k: os.environ[k] for k in ('ROS_DOMAIN_ID', 'ROS_AUTOMATIC_DISCOVERY_RANGE')}
    emulator = sourced(install, f'{ROOT}/scripts/ros2_run {emulator_command}', env,
                       stdin=subprocess.PIPE)
    node = None
    try:
        assert '"ready": true' in emulator.stdout.readline()
        node = sourced(install, f'exec {ROOT}/scripts/ros2_run {node_command}', env)
        lines = []
        deadline = time.monotonic() + 20

        def up():   # said `started`, and spins: its signal handling is in place
            text = ''.join(lines)
            return started in text and ': running' in text
        while time.monotonic() < deadline and not up():
            lines.append(node.stdout.readline())
        assert up(), ''.join(lines)
        node.send_signal(signal.SIGINT)
        out, _ = node.communicate(timeout=20)
        assert node.returncode == 0, out
        assert stopped in out
    finally:
        for proc in (node, emulator):
            if proc is not None and proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
            if proc is not None:
                proc.wait()


def test_coils_node_starts_and_stops_cleanly_from_the_install(workspace, tmp_path):
    layout, install = workspace
    ports = '[' + ','.join(f'{tmp_path}/coil_{n}' for n in 'xyz') + ']'
    run_from_install(install, f'tentacle_sim supply_emulator --baud 115200 --link-dir {tmp_path}',
                     f'tentacle_coils coils_node --ros-args --params-file '
                     f'{ROOT}/config/coils.yaml -p "ports:={ports}" -p baud:=115200',
                     'auto_enable', 'outputs zero and off')


def test_inserter_node_runs_its_axis_process_from_the_install(workspace, tmp_path):
    layout, install = workspace
    # 'connected: axis stopped' is said by the axis process: it found its packages.
    run_from_install(install, f'tentacle_sim stage_emulator --link-dir {tmp_path}',
                     f'tentacle_inserter inserter_node --ros-args -p port:={tmp_path}/inserter',
                     'connected: axis stopped', 'inserter_node: axis stopped')
