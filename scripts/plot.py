"""The command ``memgym-plot``, run from a checkout: ``python scripts/plot.py --help`` says what it does (its code is
agents/cli/plot.py; ``pip install -e .`` makes both this script and the command work).
"""

import sys

from agents.cli.plot import main

if __name__ == "__main__":
    sys.exit(main())
