"""
Simulate the rig: physics and rendered camera: not built yet.

The executable exists so the package installs and the ament index lists it; a later issue
fills it. Running it says so and exits non-zero rather than pretending to work.
"""

import argparse
import sys


def main(args=None):
    """Parse the command line (``--help`` works) and refuse to run."""
    parser = argparse.ArgumentParser(
        prog='sim_node',
        description='Simulate the rig: physics and rendered camera.'
                    ' Not implemented yet.')
    parser.parse_known_args(args)
    sys.exit('sim_node: not implemented yet (a later issue builds it)')


if __name__ == '__main__':
    main()
