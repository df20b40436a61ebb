"""
Put every package under src/ on the import path, as a colcon --symlink-install would.

Both for this process (sys.path) and for the processes tests start (PYTHONPATH); and give
those processes a working Ctrl-C.
"""

import os
import pathlib
import signal
import sys

ROOT = pathlib.Path(__file__).resolve().parent
SOURCES = [str(p) for p in sorted((ROOT / 'src').iterdir()) if (p / 'package.xml').exists()]
sys.path[:0] = [s for s in SOURCES if s not in sys.path]
os.environ['PYTHONPATH'] = os.pathsep.join(
    SOURCES + [os.environ.get('PYTHONPATH', '')]).rstrip(os.pathsep)

# A run started in the background (`make test &`, nohup, some CI runners) inherits SIGINT
# ignored, and so would every process a test starts: Ctrl-C tests would then test nothing.
# A handled signal is reset to its default at exec, so the children get a working Ctrl-C.
if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)
