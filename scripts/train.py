"""The command ``memgym-train``, run from a checkout: ``python scripts/train.py --help`` says what it does (its code is
agents/cli/train.py; ``pip install -e .`` makes both this script and the command work).
"""

import sys

from agents.cli.train import main

if __name__ == "__main__":
    sys.exit(main())
