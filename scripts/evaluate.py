"""The command ``memgym-evaluate``, run from a checkout: ``python scripts/evaluate.py --help`` says what it does (its
code is agents/cli/evaluate.py; ``pip install -e .`` makes both this script and the command work).
"""

import sys

from agents.cli.evaluate import main

if __name__ == "__main__":
    sys.exit(main())
