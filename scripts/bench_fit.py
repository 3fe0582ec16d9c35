"""Fit benchmark: the same as `finrft bench fit`."""

import sys

from finrft.cli import main

if __name__ == "__main__":  # worker processes import this module again
    sys.exit(main(["bench", "fit", *sys.argv[1:]]))
