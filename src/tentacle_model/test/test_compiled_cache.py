"""A compiled function's numba cache follows the compiled functions it calls in other modules."""

import pathlib
import subprocess
import sys
import textwrap

import tentacle_model

LEAF = textwrap.dedent("""
    import numba


    @numba.njit(cache=True)
    def value():
        return {value}
""")
CALLER = textwrap.dedent("""
    import numba
    {guard}
    import leaf


    @numba.njit(cache=True)
    def twice():
        return 2 * leaf.value()
""")
GUARD = ('from tentacle_model import compiled_cache\nimport leaf\n'
         'compiled_cache.fresh(__file__, leaf)')


def run(directory):
    """Return what caller.twice() gives in a fresh process (numba's cache on disk)."""
    source = str(pathlib.Path(tentacle_model.__file__).parents[1])
    out = subprocess.run([sys.executable, '-c', 'import caller; print(caller.twice())'],
                         cwd=directory, env={'PYTHONPATH': f'{directory}:{source}'},
                         capture_output=True, text=True, timeout=120, check=True)
    return int(out.stdout)


def test_a_changed_callee_in_another_module_is_compiled_again(tmp_path):
    # numba keys a cache on the function's own file: without the guard the caller kept
    # the old callee (1 * 2) after the callee's module changed.
    (tmp_path / 'caller.py').write_text(CALLER.format(guard=GUARD))
    (tmp_path / 'leaf.py').write_text(LEAF.format(value=1))
    assert run(tmp_path) == 2
    assert list((tmp_path / '__pycache__').glob('caller.twice-*.nbc'))   # cached
    (tmp_path / 'leaf.py').write_text(LEAF.format(value=1000))
    assert run(tmp_path) == 2000
    assert run(tmp_path) == 2000   # and cached again
