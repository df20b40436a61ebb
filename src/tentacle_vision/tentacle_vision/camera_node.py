"""
Publish camera frames (/camera/image_raw): not built yet.

The executable exists so the package installs and the ament index lists it; a later issue
fills it. Running it says so and exits non-zero rather than pretending to work.
"""

import argparse
import sys


def main(args=None):
    """Parse the command line (``--help`` works) and refuse to run."""
    parser = argparse.ArgumentParser(
        prog='camera_node',
        description='Publish camera frames (/camera/image_raw).'
                    ' Not implemented yet.')
    parser.parse_known_args(args)
    sys.exit('camera_node: not implemented yet (a later issue builds it)')


if __name__ == '__main__':
    main()
