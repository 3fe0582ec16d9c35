"""Speed-against-accuracy study: the same as `finrft bench accuracy`."""

import sys

from finrft.cli import main

if __name__ == "__main__":  # worker processes import this module again
    sys.exit(main(["bench", "accuracy", *sys.argv[1:]]))
