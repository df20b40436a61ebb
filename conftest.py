"""Put every package under src/ on the import path, as a colcon --symlink-install would."""

import pathlib
import sys

ROOT = pathlib.Path(__file__).resolve().parent
for package in sorted((ROOT / 'src').iterdir()):
    if (package / 'package.xml').exists() and str(package) not in sys.path:
        sys.path.insert(0, str(package))
