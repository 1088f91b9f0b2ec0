"""The command ``memgym-sweep``, run from a checkout: ``python scripts/sweep.py --help`` says what it does (its code is
agents/cli/sweep.py; ``pip install -e .`` makes both this script and the command work).
"""

import sys

from agents.cli.sweep import main

if __name__ == "__main__":
    sys.exit(main())
