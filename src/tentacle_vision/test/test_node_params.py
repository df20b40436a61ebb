"""The vision nodes' parameters as a lab writes them: checked before rclpy starts, exit 2."""

import os
import threading
import time

import pytest
import rclpy
from rclpy.context import Context
from rclpy.node import Node
from tentacle_common.driver_node import declare_parameters
from tentacle_common.params import check_ros_args
from tentacle_vision import camera_node, tracker_node
from tentacle_vision.params import CAMERA_NODE, CAMERA_PARAMS


def unblock_later(fifo, after_s=5.0):
    """Open a FIFO's writing end after a while and close it: a reader that blocked returns."""
    def writer():
        deadline = time.monotonic() + after_s + 5.0
        time.sleep(after_s)
        while time.monotonic() < deadline:
            try:  # non-blocking: fails at once while nobody reads (the right behaviour)
                os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))
                return
            except OSError:
                time.sleep(0.1)
    threading.Thread(target=writer, daemon=True).start()


def refused(capsys, monkeypatch, main, argv):
    """Return the stderr of a node's main that must exit 2 before starting."""
    def started(*_args, **_kwargs):  # a refusal that comes too late must not spin forever
        raise RuntimeError('rclpy.init reached: the arguments were not refused before it')
    monkeypatch.setattr(rclpy, 'init', started)
    with pytest.raises(SystemExit) as stopped:
        main(argv)
    err = capsys.readouterr().err
    assert stopped.value.code == 2, err
    return err


# (what the lab wrote after --ros-args, with {d} a folder; a piece of the message)
CASES = [
    (['--params-file', '/dev/zero'],
     'params file /dev/zero: not a regular file (a device, FIFO or folder)'),
    (['--params-file', '{d}/fifo.yaml'], 'fifo.yaml: not a regular file'),
    (['--params-file', '{d}/big.yaml'], 'big.yaml: larger than 1048576 bytes'),
    (['--params-file', '{d}/twice.yaml'],
     "twice.yaml: duplicate key 'threshold' at line 4 (first at line 3)"),
    (['--params-file', '{d}/colour.yaml'],
     r'colour.yaml: colour_low: element 0 is 300, outside [0, 255]'),
    (['-p', 'colour_low:=[300,0,0]'], '-p colour_low: element 0 is 300, outside [0, 255]'),
    (['-p', 'colour_high:=[0,0,-1]'], '-p colour_high: element 2 is -1, outside [0, 255]'),
]


@pytest.mark.parametrize('args, message', CASES)
def test_tracker_node_refuses_before_starting(tmp_path, capsys, monkeypatch, args, message):
    os.mkfifo(tmp_path / 'fifo.yaml')
    if 'fifo' in args[-1]:
        unblock_later(tmp_path / 'fifo.yaml')  # were the FIFO opened, the test still ends
    (tmp_path / 'big.yaml').write_text('#' * (1 << 21))
    (tmp_path / 'twice.yaml').write_text(
        'tracker_node:\n  ros__parameters:\n    threshold: 100\n    threshold: 120\n')
    (tmp_path / 'colour.yaml').write_text(
        'tracker_node:\n  ros__parameters:\n    colour_low: [300, 0, 0]\n')
    err = refused(capsys, monkeypatch, tracker_node.main,
                  ['--ros-args'] + [a.format(d=tmp_path) for a in args])
    assert err.startswith('tracker_node: not started: ') and message in err, err
    assert 'Traceback' not in err


def test_camera_source_as_ros_reads_it_an_integer_is_a_device_index():
    # The README's form: ROS parses source:=0 as an integer; the parameter is text.
    argv, warnings, _ = check_ros_args(['--ros-args', '-p', 'source:=0'], CAMERA_NODE,
                                       CAMERA_PARAMS)
    assert warnings == []
    context = Context()
    rclpy.init(context=context, args=[CAMERA_NODE, *argv])
    try:
        node = Node(CAMERA_NODE, context=context)
        assert declare_parameters(node, CAMERA_PARAMS)['source'] == '0'
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)


def test_camera_node_refuses_a_non_integer_number_as_source(capsys, monkeypatch):
    err = refused(capsys, monkeypatch, camera_node.main, ['--ros-args', '-p', 'source:=0.5'])
    assert '-p source: 0.5 is not str' in err
