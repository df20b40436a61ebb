"""Calibration fit against a known matrix, and the file handling around it."""

import shutil
import subprocess

import numpy as np
import pytest
from tentacle_coils.calibration import COLUMNS, fit, main, read_measurements
from tentacle_coils.errors import ConfigError
from tentacle_coils.field_map import ActuationMap
import yaml

TRUE_A = np.array([[0.53e-3, 0.02e-3, -0.01e-3], [0.03e-3, 1.07e-3, 0.0],
                   [-0.02e-3, 0.01e-3, 0.65e-3]])
TRUE_B0 = np.array([2e-5, -4e-5, 1e-5])


def measurements(n=40, noise_t=0.0, seed=3):
    rng = np.random.default_rng(seed)
    currents = rng.uniform(-20, 20, (n, 3))
    fields = currents @ TRUE_A.T + TRUE_B0 + noise_t * rng.standard_normal((n, 3))
    return currents, fields


def write_csv(path, currents, fields):
    rows = [','.join(COLUMNS)] + [','.join(f'{v:.9g}' for v in np.r_[i, b])
                                  for i, b in zip(currents, fields)]
    path.write_text('\n'.join(rows) + '\n')


def test_exact_data_recovers_matrix_and_offset():
    result = fit(*measurements())
    np.testing.assert_allclose(result.matrix_t_per_a, TRUE_A, atol=1e-15)
    np.testing.assert_allclose(result.offset_t, TRUE_B0, atol=1e-15)
    assert result.residual_max_t < 1e-15


def test_noisy_data_residual_matches_the_noise():
    noise = 5e-6
    result = fit(*measurements(n=400, noise_t=noise))
    np.testing.assert_allclose(result.residual_rms_t, noise, rtol=0.15)
    np.testing.assert_allclose(result.matrix_t_per_a, TRUE_A, atol=2e-7)


def test_rank_deficient_and_too_few_samples_are_refused():
    currents, fields = measurements()
    currents[:, 2] = 0.0  # z never excited
    with pytest.raises(ConfigError, match='rank deficient'):
        fit(currents, fields)
    with pytest.raises(ConfigError, match='cannot fit 4 unknowns'):
        fit(*[a[:3] for a in measurements()])


def test_bad_csv_names_file_and_line(tmp_path):
    path = tmp_path / 'bad.csv'
    path.write_text(','.join(COLUMNS) + '\n1,2,3,1e-3,2e-3,3e-3\n1,2,x,1e-3,2e-3,3e-3\n')
    with pytest.raises(ConfigError, match=r'bad.csv:3: not a number'):
        read_measurements(path)
    path.write_text('current_x_a,field_x_t\n1,2\n')
    with pytest.raises(ConfigError, match='missing column'):
        read_measurements(path)
    path.write_text(','.join(COLUMNS) + '\n1,2,3,nan,2e-3,3e-3\n')
    with pytest.raises(ConfigError, match='bad.csv:2: value not finite'):
        read_measurements(path)


def test_command_line_writes_config_keeping_comments(tmp_path, capsys):
    csv_path = tmp_path / 'm.csv'
    write_csv(csv_path, *measurements())
    config = tmp_path / 'coils.yaml'
    shutil.copy('config/coils.yaml', config)
    assert main([str(csv_path), '--write', str(config)]) == 0
    out = capsys.readouterr().out
    assert 'residual RMS (uT)' in out and 'diagonal (mT/A): x 0.5300' in out
    text = config.read_text()
    assert 'WARNING: the dxkdp wire dialect' in text  # comments survive
    params = yaml.safe_load(text)['coils_node']['ros__parameters']
    amap = ActuationMap(params['actuation_matrix'], params['field_offset'])
    np.testing.assert_allclose(amap.matrix, TRUE_A, rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(amap.offset, TRUE_B0, rtol=1e-6, atol=1e-12)
    assert main([str(tmp_path / 'missing.csv')]) == 2


def csv_text(columns=COLUMNS, extra=None, n=40):
    """Return a measurements CSV; extra = (column name, values function of the row)."""
    currents, fields = measurements(n)
    by_name = dict(zip(COLUMNS, np.column_stack([currents, fields]).T))
    names = list(columns) + ([extra[0]] if extra else [])
    rows = [[by_name[c][k] if c in by_name else 0.0 for c in columns]
            + ([extra[1](k)] if extra else []) for k in range(n)]
    return ','.join(names) + '\n' + ''.join(
        ','.join(f'{v:.9g}' for v in row) + '\n' for row in rows)


def scaled_x(text, factor):
    lines = text.splitlines()
    out = [lines[0]]
    for line in lines[1:]:
        v = line.split(',')
        v[3] = f'{float(v[3]) * factor:.9g}'
        out.append(','.join(v))
    return '\n'.join(out) + '\n'


GOOD = csv_text()
# (CSV bytes, extra arguments, the exit status, a piece of the message or report)
CLI_CASES = [
    ('repeated field_x_t', csv_text(extra=('field_x_t', lambda k: 0.0)).encode(), [], 2,
     'column field_x_t given 2 times (columns 4, 7); each must be given once'),
    ('zero x field', scaled_x(GOOD, 0.0).encode(), [], 2,
     'singular or ill-conditioned: condition number'),
    ('weak x field', scaled_x(GOOD, 1e-3).encode(), [], 2,
     'ill-conditioned: condition number 2.02e+03, limit 100'),
    ('weak x, limit raised', scaled_x(GOOD, 1e-3).encode(), ['--max-condition', '1e4'], 0,
     'diagonal (mT/A): x 0.0005'),
    ('latin-1 byte', GOOD.replace('current_x_a', 'current_x_a\xe9', 1).encode('latin-1'), [],
     2, 'not UTF-8 text (byte 0xe9 at offset 11); save it as "CSV UTF-8"'),
    ('excel BOM', b'\xef\xbb\xbf' + GOOD.encode(), [], 0, 'diagonal (mT/A): x 0.5300'),
    ('columns reordered, extra column', csv_text(COLUMNS[::-1], ('time_s', float)).encode(),
     [], 0, 'diagonal (mT/A): x 0.5300'),
    ('missing column', csv_text(COLUMNS[:5]).encode(), [], 2, 'missing column(s) field_z_t'),
    ('row too long', (GOOD + '1,2,3,4,5,6,7\n').encode(), [], 2,
     ':42: 7 fields where the header has 6'),
    ('bad number', GOOD.replace('\n', '\n1,2,x,1e-3,2e-3,3e-3\n', 1).encode(), [], 2,
     ":2: not a number in column current_z_a: 'x'"),
    ('bad max-condition', GOOD.encode(), ['--max-condition', '0.5'], 2, 'at least 1'),
]


@pytest.mark.parametrize('name, data, extra, status, message', CLI_CASES,
                         ids=[c[0] for c in CLI_CASES])
def test_command_line_cases_and_a_refused_fit_is_never_written(
        tmp_path, capsys, name, data, extra, status, message):
    csv_path = tmp_path / 'm.csv'
    csv_path.write_bytes(data)
    config = tmp_path / 'coils.yaml'
    shutil.copy('config/coils.yaml', config)
    before = config.read_text()
    if status == 2 and extra and extra[0] == '--max-condition':
        with pytest.raises(SystemExit) as usage:  # argparse's own usage error
            main([str(csv_path), *extra])
        assert usage.value.code == 2 and message in capsys.readouterr().err
        return
    assert main([str(csv_path), '--write', str(config), *extra]) == status
    out, err = capsys.readouterr()
    assert message in (out if status == 0 else err), out + err
    if status == 2:
        assert err.startswith(f'calibrate_coils: {csv_path}:')
        assert config.read_text() == before  # nothing written
        assert 'Traceback' not in err
    else:
        assert config.read_text() != before


@pytest.mark.parametrize('target, message', [
    ('folder', 'not a regular file'),
    ('/dev/zero', 'not a regular file'),
    ('missing.yaml', 'cannot be read: No such file or directory'),
    ('other.yaml', 'no coils_node section (is this the coils params file?)'),
])
def test_write_targets_that_are_refused(tmp_path, capsys, target, message):
    csv_path = tmp_path / 'm.csv'
    csv_path.write_text(GOOD)
    (tmp_path / 'folder').mkdir()
    (tmp_path / 'other.yaml').write_text('# mine\ntracker_node:\n  ros__parameters: {}\n')
    path = target if target.startswith('/') else str(tmp_path / target)
    assert main([str(csv_path), '--write', path]) == 2
    assert f'calibrate_coils: {path}: {message}' in capsys.readouterr().err
    assert (tmp_path / 'other.yaml').read_text().startswith('# mine\n')


def test_help_works_without_a_sourced_workspace():
    # As a lab user runs it: a fresh shell, no setup.bash, no PYTHONPATH.
    done = subprocess.run(['scripts/calibrate_coils', '--help'], capture_output=True,
                          text=True, timeout=60, env={'PATH': '/usr/bin:/bin'})
    assert done.returncode == 0 and 'usage: calibrate_coils' in done.stdout, done.stderr
