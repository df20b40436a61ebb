"""
Put every package under src/ on the import path, as a colcon --symlink-install would.

Both for this process (sys.path) and for the processes tests start (PYTHONPATH).
"""

import os
import pathlib
import sys

ROOT = pathlib.Path(__file__).resolve().parent
SOURCES = [str(p) for p in sorted((ROOT / 'src').iterdir()) if (p / 'package.xml').exists()]
sys.path[:0] = [s for s in SOURCES if s not in sys.path]
os.environ['PYTHONPATH'] = os.pathsep.join(
    SOURCES + [os.environ.get('PYTHONPATH', '')]).rstrip(os.pathsep)
