"""Robot benchmark: the same as `finrft bench robot`."""

import sys

from finrft.cli import main

if __name__ == "__main__":  # worker processes import this module again
    sys.exit(main(["bench", "robot", *sys.argv[1:]]))
