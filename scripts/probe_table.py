"""The calibration table of probe runs (novel-seed curves beside a random policy): see agents/cli/probe_table.py."""

import sys

from agents.cli.probe_table import main

if __name__ == "__main__":
    sys.exit(main())
