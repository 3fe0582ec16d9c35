"""Backend and batch benchmark: the same as `finrft bench backends`."""

import sys

from finrft.cli import main

if __name__ == "__main__":  # worker processes import this module again
    sys.exit(main(["bench", "backends", *sys.argv[1:]]))
