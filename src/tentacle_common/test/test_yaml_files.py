"""Params files on disk: bounded reads, strict parsing, line-level edits that keep comments."""

import os
import threading

import pytest
from tentacle_common.yaml_files import (
    FileRefused, load, MAX_FILE_BYTES, read_text, set_flow_list)
import yaml


@pytest.mark.parametrize('text, message', [
    ('a: 1\na: 2\n', "duplicate key 'a' at line 2 (first at line 1)"),
    ('seg:\n  length_m: 0.1\n  d_m: 0.002\n  length_m: 0.1\n',
     "duplicate key 'length_m' at line 4 (first at line 2)"),
    ('{x: 1, y: 2, x: 3}', "duplicate key 'x' at line 1"),
    ('a: [1\n', 'not YAML'),
])
def test_a_key_given_twice_is_refused_naming_it_and_its_lines(text, message):
    with pytest.raises(FileRefused, match=message.replace('(', r'\(').replace(')', r'\)')):
        load(text)


def test_merge_keys_and_plain_documents_still_load():
    assert load('base: &b {a: 1, b: 2}\nnode:\n  <<: *b\n  a: 3\n') == {
        'base': {'a': 1, 'b': 2}, 'node': {'a': 3, 'b': 2}}
    assert load('') is None


def test_devices_fifos_folders_and_large_files_are_refused_before_reading(tmp_path):
    for path in ('/dev/zero', str(tmp_path)):
        with pytest.raises(FileRefused, match='not a regular file'):
            read_text(path)
    fifo = tmp_path / 'fifo.yaml'
    os.mkfifo(fifo)
    outcome = []
    reader = threading.Thread(target=lambda: outcome.append(
        pytest.raises(FileRefused, read_text, fifo)), daemon=True)
    reader.start()
    reader.join(5.0)
    assert outcome, 'reading a FIFO blocked'
    big = tmp_path / 'big.yaml'
    big.write_bytes(b'#' * (MAX_FILE_BYTES + 1))
    with pytest.raises(FileRefused, match=f'larger than {MAX_FILE_BYTES} bytes'):
        read_text(big)
    latin = tmp_path / 'latin.csv'
    latin.write_bytes(b'a,b\n\xe9,1\n')
    with pytest.raises(FileRefused, match='not UTF-8 text .byte 0xe9 at offset 4'):
        read_text(latin)
    bom = tmp_path / 'bom.csv'
    bom.write_bytes(b'\xef\xbb\xbfa,b\n')
    assert read_text(bom, encoding='utf-8-sig') == 'a,b\n'


COMMENTED = """# WARNING: keep this line
tracker_node:
  ros__parameters:
    base_px: [10.0, 20.0]   # the insertion point
    # the homography, fitted by calibrate_camera
    homography: [1.0, 0.0, 0.0,
                 0.0, 1.0, 0.0,
                 0.0, 0.0, 1.0]   # fitted
    dark: true
coils_node:
  ros__parameters:
    max_current: 42.0   # ampere
"""


@pytest.mark.parametrize('text, node', [
    (COMMENTED, 'tracker_node'),
    (COMMENTED.replace('    homography: [1.0, 0.0, 0.0,\n                 0.0, 1.0, 0.0,\n'
                       '                 0.0, 0.0, 1.0]   # fitted\n', ''), 'tracker_node'),
    (COMMENTED, 'camera_node'),
    (COMMENTED.replace('tracker_node:\n  ros__parameters:\n', 'tracker_node:  # bench 2\n'
                       '  ros__parameters:   # as fitted\n'), 'tracker_node'),
    (yaml.safe_dump({'tracker_node': {'ros__parameters': {'homography': [0.5] * 9,
                                                          'dark': True}}}), 'tracker_node'),
])
def test_only_the_key_changes_and_comments_survive(text, node):
    values = [1e-5, -2.5e-5, 3.0, 0.0, 1.0, 2.0, 3.0, 4.0, 1.0]
    edited = set_flow_list(text, node, 'homography', values)
    expected = load(text)
    expected.setdefault(node, {}).setdefault('ros__parameters', {})['homography'] = values
    assert load(edited) == expected
    kept = [line for line in text.splitlines() if line.lstrip().startswith('#')]
    assert all(line in edited.splitlines() for line in kept)


@pytest.mark.parametrize('text, message', [
    ('tracker_node: {ros__parameters: {homography: [1]}}\n', 'not in block style'),
    ('tracker_node:\n  ros__parameters: {dark: true}\n', 'no block-style ros__parameters'),
    ('- a\n', 'not a mapping'),
    ('tracker_node:\n  ros__parameters:\n    homography: [1]\n    homography: [2]\n',
     'duplicate key'),
    ('tracker_node:\n  ros__parameters:\n    homography: &h [1.0]\n'
     'camera_node:\n  ros__parameters:\n    h: *h\n', 'can edit safely'),
])
def test_a_layout_it_cannot_edit_safely_is_refused(text, message):
    with pytest.raises(FileRefused, match=message):
        set_flow_list(text, 'tracker_node', 'homography', [1.0] * 9)
