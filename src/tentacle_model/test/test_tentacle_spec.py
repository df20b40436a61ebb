"""Tentacle files: the shipped ones load, bad ones are refused naming file and field."""

import math
import pathlib

import numpy as np
import pytest
from tentacle_model.chain import discretise
from tentacle_model.statics import solve
from tentacle_model.tentacle_spec import (load_tentacle, MAX_FILE_BYTES, MU0, parse_tentacle,
                                          SpecError)
import yaml

GOOD = {
    'name': 't',
    'segments': [{'length_m': 0.02, 'section': {'diameter_m': 0.002},
                  'youngs_modulus_pa': 1.0e5, 'density_kg_m3': 1400.0,
                  'magnetisation': {'remanence_t': 0.107, 'direction': [1.0, 0.0, 0.0]}}],
}


def with_change(path, value):
    doc = yaml.safe_load(yaml.safe_dump(GOOD))
    target = doc
    for key in path[:-1]:
        target = target[key]
    if value is KeyError:
        del target[path[-1]]
    else:
        target[path[-1]] = value
    return doc


def test_cantilever_file_has_the_issue_numbers(cantilever):
    spec, length, ei, ma = cantilever
    assert length == 0.02
    assert ei == pytest.approx(1.0e5 * math.pi * 0.002 ** 4 / 64, rel=1e-9, abs=0)
    assert ma == pytest.approx(0.107 / MU0 * math.pi * 0.001 ** 2, rel=1e-9, abs=0)
    np.testing.assert_allclose(spec.base_rotation, np.eye(3))
    assert spec.segments[0].radius_m == 0.001


def test_rectangular_section_and_anisotropic_moduli():
    doc = with_change(['segments', 0, 'section'], {'width_m': 0.004, 'height_m': 0.001})
    doc['segments'][0]['youngs_modulus_pa'] = {'bend_1': 5e5, 'bend_2': 5e5, 'twist': 1e7}
    segment = parse_tentacle(doc).segments[0]
    in_plane, out_of_plane, twist = segment.bend_stiffness_n_m2
    assert in_plane == pytest.approx(5e5 * 0.001 * 0.004 ** 3 / 12, rel=1e-9, abs=0)
    assert out_of_plane == pytest.approx(5e5 * 0.004 * 0.001 ** 3 / 12, rel=1e-9, abs=0)
    polar = (0.001 * 0.004 ** 3 + 0.004 * 0.001 ** 3) / 12
    assert twist == pytest.approx(1e7 * polar, rel=1e-9, abs=0)
    assert segment.radius_m == pytest.approx(math.hypot(0.004, 0.001) / 2)  # the corner


@pytest.mark.parametrize('path, value, message', [
    (['segments', 0, 'length_m'], -0.01, r'segments\[0\].length_m: -0.01 must be positive'),
    (['segments', 0, 'length_m'], 0.0, r'segments\[0\].length_m: 0.0 must be positive'),
    (['segments', 0, 'youngs_modulus_pa'], 0, 'youngs_modulus_pa: 0.0 must be positive'),
    (['segments', 0, 'density_kg_m3'], float('nan'), 'density_kg_m3: nan is not finite'),
    (['segments', 0, 'magnetisation', 'direction'], [0, 0, 0], 'zero-length direction'),
    (['segments', 0, 'colour'], 'red', r"unknown key\(s\) \['colour'\]"),
    (['segments', 0, 'section'], KeyError, r"missing key\(s\) \['section'\]"),
    (['segments'], [], 'non-empty list'),
    (['base'], {'direction': [1, 0, 0], 'normal': [2, 0, 0]}, 'parallel'),
    (['name'], None, 'name: expected a non-empty string, got None'),
    (['name'], '', "name: expected a non-empty string, got ''"),
    (['name'], 42, 'name: expected a non-empty string, got 42'),
])
def test_bad_fields_are_named(path, value, message):
    with pytest.raises(SpecError, match=f'my.yaml: .*{message}'):
        parse_tentacle(with_change(path, value), 'my.yaml')


def test_unknown_keys_of_mixed_types_are_named():
    doc = with_change(['segments', 0, 1], 'one')  # YAML keys need not be strings
    doc['segments'][0]['colour'] = 'red'
    with pytest.raises(SpecError, match=r"segments\[0\]: unknown key\(s\) \['colour', 1\]"):
        parse_tentacle(doc, 'my.yaml')


def test_file_errors_name_the_file(tmp_path):
    with pytest.raises(SpecError, match='missing.yaml'):
        load_tentacle(tmp_path / 'missing.yaml')
    bad = tmp_path / 'bad.yaml'
    bad.write_text('segments: [length_m: 1, {')
    with pytest.raises(SpecError, match='bad.yaml: not valid YAML'):
        load_tentacle(bad)


@pytest.mark.parametrize('name', ['cantilever', 'vsr_chapter6', 'braided_chapter5'])
def test_shipped_tentacles_load_and_solve(name):
    path = pathlib.Path(__file__).resolve().parents[3] / f'config/tentacles/{name}.yaml'
    spec = load_tentacle(path)
    eq = solve(discretise(spec, sublinks=2), [0.0, 0.01, 0.0], dof=3)
    assert eq.converged, eq.reason


def test_file_size_is_capped_without_reading_past_the_cap(tmp_path):
    text = yaml.safe_dump(GOOD)
    fits = tmp_path / 'fits.yaml'
    fits.write_text(text + '#' * (MAX_FILE_BYTES - len(text)))
    assert fits.stat().st_size == MAX_FILE_BYTES
    assert load_tentacle(fits).name == 't'
    over = tmp_path / 'over.yaml'
    over.write_text(text + '#' * (MAX_FILE_BYTES + 1 - len(text)))
    with pytest.raises(SpecError, match=f'over.yaml: larger than {MAX_FILE_BYTES // 1024} KiB'):
        load_tentacle(over)  # /dev/zero, endless: test_cli_limits.py


def test_binary_files_are_refused_naming_the_file(tmp_path):
    path = tmp_path / 'random.yaml'
    path.write_bytes(np.random.default_rng(3).bytes(1000))
    with pytest.raises(SpecError, match='random.yaml: not UTF-8 text'):
        load_tentacle(path)
    path.write_text('name: caf\u00e9\n', encoding='latin-1')
    with pytest.raises(SpecError, match=r'random.yaml: not UTF-8 text \(invalid'):
        load_tentacle(path)
