"""Modelling-choice benchmark: the same as `finrft bench modelling`."""

import sys

from finrft.cli import main

if __name__ == "__main__":  # worker processes import this module again
    sys.exit(main(["bench", "modelling", *sys.argv[1:]]))
