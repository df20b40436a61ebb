"""The params-file and -p checks that run before rcl reads them (pure, no ROS)."""

import pytest
from tentacle_coils.errors import ConfigError
from tentacle_coils.params import check_params_file, check_ros_args
import yaml


def write(tmp_path, text):
    path = tmp_path / 'coils.yaml'
    path.write_text(text)
    return str(path)


def test_integers_in_doubles_become_doubles_and_nothing_else_changes(tmp_path):
    path = write(tmp_path, 'coils_node:\n  ros__parameters:\n'
                 '    actuation_matrix: [0.53e-3, 0, 0, 0, 1.07e-3, 0, 0, 0, 0.65e-3]\n'
                 '    max_current: 40\n    max_field: 2e-2\n    baud: 9600\n'
                 '    ports: [/dev/a, /dev/b, /dev/c]\n'
                 'other_node:\n  ros__parameters:\n    max_current: 3\n')
    document, warnings, changed = check_params_file(path)
    params = document['coils_node']['ros__parameters']
    assert changed and warnings == []
    assert params['actuation_matrix'] == [0.53e-3, 0.0, 0.0, 0.0, 1.07e-3, 0.0, 0.0, 0.0,
                                          0.65e-3]
    assert all(type(v) is float for v in params['actuation_matrix'])
    assert type(params['max_current']) is float and params['max_field'] == 0.02
    assert type(params['baud']) is int
    assert document['other_node']['ros__parameters']['max_current'] == 3  # not ours


def test_a_file_that_needs_nothing_is_passed_as_it_is(tmp_path):
    path = write(tmp_path, '/coils_node:\n  ros__parameters:\n    max_current: 40.0\n')
    assert check_params_file(path)[2] is False


def test_a_misspelt_parameter_is_named_with_a_suggestion(tmp_path):
    path = write(tmp_path, 'coils_node:\n  ros__parameters:\n    max_curent: 1.0\n'
                 '/**:\n  ros__parameters:\n    use_sim_time: false\n')
    _, warnings, _ = check_params_file(path)
    assert warnings == [f'params file {path}: max_curent is not a coils_node parameter '
                        '(did you mean max_current?): ignored']


@pytest.mark.parametrize('line, message', [
    ('max_current: forty', "max_current: 'forty' is not a number"),
    ('max_current: .nan', 'max_current: nan is not finite'),
    ('baud: 9600.0', 'baud: 9600.0 is not an integer'),
    ('clamp: 1', 'clamp: 1 is not bool'),
    ('ports: /dev/a', "ports: '/dev/a' is not a list"),
    ('polarity_inverted: [true, 0, false]', 'polarity_inverted: 0 is not bool'),
    ('max_current: 100000000000000000000', 'too large to be a double exactly')])
def test_a_wrong_type_names_the_file_and_the_parameter(tmp_path, line, message):
    path = write(tmp_path, f'coils_node:\n  ros__parameters:\n    {line}\n')
    with pytest.raises(ConfigError, match=f'params file {path}: .*'):
        check_params_file(path)
    with pytest.raises(ConfigError) as error:
        check_params_file(path)
    assert message in str(error.value)


@pytest.mark.parametrize('text, message', [
    (None, 'cannot be read'), ('coils_node: [1, 2', 'not YAML'),
    ('- a\n- b\n', 'not a mapping'), ('coils_node: 3\n', 'coils_node: no ros__parameters')])
def test_unreadable_or_malformed_files_are_named(tmp_path, text, message):
    path = str(tmp_path / 'missing.yaml') if text is None else write(tmp_path, text)
    with pytest.raises(ConfigError, match=f'params file {path}: {message}'):
        check_params_file(path)


def test_ros_args_are_checked_and_rewritten(tmp_path):
    path = write(tmp_path, 'coils_node:\n  ros__parameters:\n    max_current: 40\n')
    argv, warnings, rewrite = check_ros_args(
        ['--ros-args', '--params-file', path, '-p', 'max_field:=2e-2', '-p', 'slew:=3.0',
         '-p', 'other_node:max_current:=1'])
    assert argv[4] == 'max_field:=0.02' and argv[8] == 'other_node:max_current:=1'
    assert warnings == ['-p slew: not a coils_node parameter (did you mean slew_rate?): ignored']
    assert list(rewrite) == [2]
    assert yaml.safe_load(yaml.safe_dump(rewrite[2]))['coils_node']['ros__parameters'][
        'max_current'] == 40.0
    with pytest.raises(ConfigError, match="-p clamp: 'yes please' is not bool"):
        check_ros_args(['--ros-args', '-p', 'clamp:=yes please'])
