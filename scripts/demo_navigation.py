#!/usr/bin/env python3
"""
make demo: the pancreatic duct navigation on the simulated rig, in three modes, reported.

See tentacle_rig/demo.py. Runs in a private ROS domain with discovery on this machine only,
so a rig running elsewhere on the network neither sees it nor is commanded by it.
"""

import os
import pathlib
import sys

ROOT = pathlib.Path(__file__).resolve().parent.parent
SOURCES = [str(p) for p in sorted((ROOT / 'src').iterdir()) if (p / 'package.xml').exists()]
sys.path[:0] = SOURCES
os.environ['PYTHONPATH'] = os.pathsep.join(SOURCES + [os.environ.get('PYTHONPATH', '')])
# A domain of its own (not the rig's: a rig may be running) on this machine only.
os.environ.setdefault('ROS_DOMAIN_ID', str(200 + os.getpid() % 30))
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

from tentacle_rig.demo import main  # noqa: E402

if __name__ == '__main__':
    sys.exit(main())
