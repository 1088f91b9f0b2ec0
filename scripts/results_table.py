"""The results table of an evaluated panel (final scores per method and task, the aggregate, wall times): see
agents/cli/results_table.py."""

import sys

from agents.cli.results_table import main

if __name__ == "__main__":
    sys.exit(main())
