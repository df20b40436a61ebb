"""Schedules read back: typed, self-contained, strict, and fast to load (no scipy)."""

from dataclasses import replace
import pathlib
import subprocess
import sys

import numpy as np
import pytest
from tentacle_planner.errors import PlanInputError
from tentacle_planner.planner import plan_scene
from tentacle_planner.scene import load_scene
from tentacle_planner.schedule_file import read_schedule
from tentacle_planner.schedule_writer import write_schedule_file
import yaml

ROOT = pathlib.Path(__file__).resolve().parents[3]


@pytest.fixture(scope='module')
def planned(tmp_path_factory):
    """Return (schedule path, its document, scene, result): a quick plan of a shipped scene."""
    scene = load_scene(ROOT / 'config' / 'scenes' / 'pancreatic_duct.yaml')
    result = plan_scene(scene, starts=1, iterations=5)
    path = write_schedule_file(tmp_path_factory.mktemp('plan'), result)
    return path, yaml.safe_load(path.read_text()), scene, result


def test_a_written_schedule_reads_back_as_written(planned):
    path, document, scene, result = planned
    schedule = read_schedule(path)
    # the model the plan was made in travels with it: the scene's, with the polish's sub-links
    assert schedule.model == result.planning_model
    assert schedule.model.sublinks > scene.model.sublinks
    assert replace(schedule.model, sublinks=scene.model.sublinks) == scene.model
    assert schedule.scene_name == scene.name and schedule.scene_sha256 == scene.sha256
    assert len(schedule.steps) == len(document['steps'])
    for step, raw in zip(schedule.steps, document['steps']):
        assert step.insertion_m == raw['insertion_m'] and step.key == raw['key']
        assert np.array_equal(step.field_t, raw['field_t'])
        assert np.array_equal(step.predicted_centreline_m, raw['predicted_centreline_m'])
    assert [s.insertion_m for s in schedule.key_steps] == pytest.approx(
        list(scene.insertion_steps_m))
    spec = schedule.tentacle_spec()   # the planned tentacle, parsed as a tentacle file
    assert spec.length_m == pytest.approx(scene.tentacle.length_m)


def test_reading_a_schedule_loads_neither_matplotlib_nor_scipy(planned):
    code = ('import sys; from tentacle_planner.schedule_file import read_schedule; '
            f'read_schedule({str(planned[0])!r}).tentacle_spec(); '
            "print(sorted(m for m in ('scipy', 'matplotlib', 'numba') if m in sys.modules))")
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == '[]'


def _broken(document, change):
    document = yaml.safe_load(yaml.safe_dump(document))
    change(document)
    return document


BAD = [
    (lambda d: d.update(format='tentacle-schedule/9'),
     "format: 'tentacle-schedule/9' is not a format this reader knows"),
    (lambda d: d.pop('model'), 'model: missing: this schedule predates'),
    (lambda d: d['model'].update(dof=2), 'model.dof: expected 1'),
    (lambda d: d['steps'][0]['field_t'].append(0.0), r'steps\[0\].field_t: expected \[x, y, z\]'),
    (lambda d: d['steps'][1].update(insertion_m=-1.0), r'steps\[1\].insertion_m: -1.0 must be'),
    (lambda d: d['steps'][0].update(field_tesla=[0, 0, 0]), r'steps\[0\]: unknown key'),
    (lambda d: d['steps'][0].update(stability='.nan'), r'steps\[0\].stability: expected a'),
    (lambda d: d.update(steps=[]), 'steps: expected a non-empty list'),
    (lambda d: d['steps'].reverse(), r'steps\[1\].insertion_m: .* steps go in insertion order'),
]


@pytest.mark.parametrize('change, message', BAD)
def test_a_bad_schedule_is_refused_naming_the_key(planned, tmp_path, change, message):
    path = tmp_path / 'schedule.yaml'
    path.write_text(yaml.safe_dump(_broken(planned[1], change)))
    with pytest.raises(PlanInputError, match=f'{path}: {message}'):
        read_schedule(path)


def test_a_schedule_that_is_no_file_or_no_yaml_is_refused(tmp_path):
    with pytest.raises(PlanInputError, match='cannot be read|does not exist|No such'):
        read_schedule(tmp_path / 'absent.yaml')
    (tmp_path / 'bad.yaml').write_text('steps: [\n')
    with pytest.raises(PlanInputError, match='not YAML'):
        read_schedule(tmp_path / 'bad.yaml')
    (tmp_path / 'bin.yaml').write_bytes(b'\xff\xfe')
    with pytest.raises(PlanInputError, match='not UTF-8'):
        read_schedule(tmp_path / 'bin.yaml')
