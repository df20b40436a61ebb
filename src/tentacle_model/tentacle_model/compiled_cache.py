"""
Keep numba's on-disk cache of a module true to the compiled functions it calls elsewhere.

numba keys a cached function on its own source file only: a function that calls a compiled
function of another module keeps the old callee's machine code after that module changes
(numba's documented limitation), so an updated checkout could run a stale kernel without a
word. A module whose compiled functions call other modules' calls ``fresh(__file__, ...)``
at import: when any of those modules' sources differ from the ones its cache was built with,
its cache files are removed and numba compiles them again.
"""

import hashlib
import pathlib


def fresh(module_file, *dependencies):
    """
    Remove module_file's numba cache if a module it compiles in has changed since.

    :param module_file: the calling module's __file__
    :param dependencies: the modules whose compiled functions it calls
    """
    module = pathlib.Path(module_file)
    cache = module.parent / '__pycache__'
    digest = hashlib.sha256()
    for dependency in dependencies:
        digest.update(pathlib.Path(dependency.__file__).read_bytes())
    stamp = cache / f'{module.stem}.dependencies'
    try:
        if stamp.read_text() == digest.hexdigest():
            return
    except OSError:
        pass   # no stamp yet: the cache (if any) predates this guard
    try:
        for cached in cache.glob(f'{module.stem}.*.nb[ic]'):
            cached.unlink(missing_ok=True)
        cache.mkdir(exist_ok=True)
        stamp.write_text(digest.hexdigest())
    except OSError:
        pass   # a read-only install: numba caches elsewhere, or not at all
