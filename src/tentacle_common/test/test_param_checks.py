"""Parameter checking against a table: files read bounded, unknown names, list ranges."""

import os
import threading

import pytest
from tentacle_common.errors import ConfigError
from tentacle_common.params import check_params_file, check_ros_args, Param, resolve

NODE = 'demo_node'
TABLE = (
    Param('source', '0', 'a device number or a path'),
    Param('speed_m_per_s', 0.01, 'speed, metre per second', 0.0, 0.1),
    Param('colour_low', [0, 0, 0], 'lowest blue, green, red', 0, 255),
    Param('gains', [1.0, 1.0], 'gains, 1', 0.0, 10.0),
    Param('names', ['a', 'b'], 'names'),
)


def write(tmp_path, body, name='p.yaml'):
    path = tmp_path / name
    path.write_text(f'{NODE}:\n  ros__parameters:\n' + ''.join(f'    {b}\n' for b in body))
    return str(path)


# (params file lines, the message resolve() must give, or None: accepted)
RESOLVE_CASES = [
    (['speed_m_per_s: 0.05'], None),
    (['sped_m_per_s: 0.05'], 'sped_m_per_s is not a demo_node parameter '
                             r'\(did you mean speed_m_per_s\?\)'),
    (['colour_low: [300, 0, 0]'], r'colour_low: element 0 is 300, outside \[0, 255\]'),
    (['colour_low: [0, -1, 0]'], r'colour_low: element 1 is -1, outside \[0, 255\]'),
    (['gains: [1, 11]'], r'gains: element 1 is 11.0, outside \[0, 10\]'),
    (['speed_m_per_s: 0.5'], r'speed_m_per_s: 0.5 is outside \[0, 0.1\]'),
    (['speed_m_per_s: 0.05', 'speed_m_per_s: 0.02'],
     "duplicate key 'speed_m_per_s' at line 4 \\(first at line 3\\)"),
    (['source: 2'], None),
]


@pytest.mark.parametrize('body, message', RESOLVE_CASES)
def test_resolve_checks_a_params_file(tmp_path, body, message):
    path = write(tmp_path, body)
    if message is None:
        resolve(TABLE, NODE, path)
        return
    with pytest.raises(ConfigError, match=f'params file {path}: {message}'):
        resolve(TABLE, NODE, path)


def test_resolve_checks_list_overrides_and_turns_an_index_into_text():
    with pytest.raises(ConfigError, match=r'colour_low: element 2 is 256, outside \[0, 255\]'):
        resolve(TABLE, NODE, overrides={'colour_low': [0, 0, 256]})
    assert resolve(TABLE, NODE, overrides={'colour_low': [1, 2, 255]})['colour_low'] == [
        1, 2, 255]
    assert resolve(TABLE, NODE, overrides={'source': 1})['source'] == '1'


def test_a_node_is_only_warned_of_an_unknown_name(tmp_path):
    path = write(tmp_path, ['sped_m_per_s: 0.05'])
    _, warnings, _ = check_params_file(path, NODE, TABLE)
    assert warnings == [f'params file {path}: sped_m_per_s is not a demo_node parameter '
                        '(did you mean speed_m_per_s?): ignored']


@pytest.mark.parametrize('arg, message', [
    ('colour_low:=[300,0,0]', r'-p colour_low: element 0 is 300, outside \[0, 255\]'),
    ('gains:=[1.0, -0.5]', r'-p gains: element 1 is -0.5, outside \[0, 10\]'),
    ('speed_m_per_s:=1.0', r'-p speed_m_per_s: 1.0 is outside \[0, 0.1\]'),
    ('source:=1.5', '-p source: 1.5 is not str'),
    ('source:=true', '-p source: True is not str'),
])
def test_ros_args_out_of_range_or_wrong_type_are_refused(arg, message):
    with pytest.raises(ConfigError, match=message):
        check_ros_args(['--ros-args', '-p', arg], NODE, TABLE)


def test_an_integer_device_index_is_taken_as_text(tmp_path):
    # ROS reads source:=0 (the README's form) as an integer; the parameter is text.
    argv, warnings, _ = check_ros_args(['--ros-args', '-p', 'source:=0'], NODE, TABLE)
    assert argv[2] == 'source:="0"' and warnings == []
    path = write(tmp_path, ['source: 0'])
    document, _, changed = check_params_file(path, NODE, TABLE)
    assert changed and document[NODE]['ros__parameters']['source'] == '0'


def test_devices_fifos_and_large_files_are_refused_naming_the_file(tmp_path):
    for path in ('/dev/zero', str(tmp_path)):
        with pytest.raises(ConfigError, match=f'params file {path}: not a regular'):
            resolve(TABLE, NODE, path)
    fifo = str(tmp_path / 'fifo.yaml')
    os.mkfifo(fifo)
    errors = []

    def read():
        try:
            check_params_file(fifo, NODE, TABLE)
        except ConfigError as exc:
            errors.append(str(exc))
    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    reader.join(5.0)
    assert errors and 'not a regular file' in errors[0], 'a FIFO blocked the read'
    big = tmp_path / 'big.yaml'
    big.write_text(f'{NODE}:\n  ros__parameters:\n' + '#' * (2 << 20) + '\n')
    with pytest.raises(ConfigError, match=f'params file {big}: larger than'):
        check_params_file(str(big), NODE, TABLE)


def test_resolve_refuses_a_params_file_without_this_nodes_section(tmp_path):
    # A tool reading the backbone's file as the inserter's would run on the defaults.
    path = tmp_path / 'backbone.yaml'
    path.write_text('backbone_node:\n  ros__parameters:\n    speed_m_per_s: 0.05\n')
    with pytest.raises(ConfigError, match=f'no {NODE} section \\(it has: backbone_node\\)'):
        resolve(TABLE, NODE, str(path))
    assert resolve(TABLE, 'backbone_node', str(path))['speed_m_per_s'] == 0.05
