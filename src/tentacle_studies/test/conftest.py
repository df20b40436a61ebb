"""Study files written for a test: the braided tentacle of config/tentacles."""

import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[3]
TENTACLE = ROOT / 'config' / 'tentacles' / 'braided_chapter5.yaml'


@pytest.fixture
def write_study(tmp_path):
    """Return write(text) -> path of a study file whose tentacle: is the braided one."""
    def write(text, name='study.yaml'):
        path = tmp_path / name
        path.write_text(f'tentacle: {TENTACLE}\n' + text)
        return path
    return write
