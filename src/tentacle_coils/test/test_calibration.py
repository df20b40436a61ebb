"""Calibration fit against a known matrix, and the file handling around it."""

import shutil

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
