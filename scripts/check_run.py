"""Check that a committed run regenerates byte for byte: see agents/cli/check_run.py."""

import sys

from agents.cli.check_run import main

if __name__ == "__main__":
    sys.exit(main())
