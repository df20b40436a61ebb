"""Short plans for the tests that play them: shipped scenes cut short, planned quickly."""

from rig_support import ROOT
from tentacle_planner.planner import plan_scene
from tentacle_planner.scene import load_scene
from tentacle_planner.schedule_writer import write_schedule_file
import yaml


def _planned(folder, scene, tentacle, **changes):
    """Return (scene file, schedule file): a shipped scene with changes, planned (1 start)."""
    document = yaml.safe_load((ROOT / 'config/scenes' / scene).read_text())
    document.update(changes, tentacle=str(ROOT / 'config/tentacles' / tentacle))
    scene_file = folder / f'{document["name"]}.yaml'
    scene_file.write_text(yaml.safe_dump(document))
    result = plan_scene(load_scene(scene_file), starts=1, iterations=30)
    assert not result.flags, result.flags
    return scene_file, write_schedule_file(folder, result)


def short_duct(folder, steps_mm=(4, 8)):
    """
    Return (scene file, schedule file): the pancreatic duct to its last key step, planned.

    Its stated mismatch kept; played every 1 mm (the scene's playback step). The tentacle
    file's magnetisation is given (the tip segment axial): on the duct's straight first
    8 mm any direction of the tip's fits at zero field, and one across the channel's plane
    leaves the closed loop no torque to bend the body back in it.
    """
    whole = yaml.safe_load((ROOT / 'config/scenes/pancreatic_duct.yaml').read_text())
    return _planned(folder, 'pancreatic_duct.yaml', 'braided_chapter5.yaml',
                    name=f'pancreatic_duct_{steps_mm[-1]}mm',
                    insertion_steps_m=[s * 1e-3 for s in steps_mm],
                    magnetisation={**whole['magnetisation'], 'given': True})


def short_ch6(folder, steps=6, mismatch=None):
    """
    Return (scene file, schedule file): thesis chapter 6's coiling, its first backbone steps.

    The backbone withdrawn 2.5 mm a step from 77.5 mm: six steps coil the strip to about
    100 deg. ``mismatch``: the scene's mismatch (the simulated rig unlike the plan).
    """
    whole = yaml.safe_load((ROOT / 'config/scenes/ch6_coiling.yaml').read_text())
    return _planned(folder, 'ch6_coiling.yaml', 'vsr_chapter6_80mm.yaml',
                    name=f'ch6_coiling_{steps}_steps',
                    backbone_steps_m=whole['backbone_steps_m'][:steps],
                    **({'mismatch': mismatch} if mismatch else {}))
