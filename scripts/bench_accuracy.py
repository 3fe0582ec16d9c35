"""Speed-against-accuracy study (finrft.studies.accuracy): the same as `finrft bench accuracy`."""

import sys

from finrft.cli import main

if __name__ == "__main__":  # worker processes import this module again
    sys.exit(main(["bench", "accuracy", *sys.argv[1:]]))
