"""Check that the committed example run (results/examples/proof_of_memory/) regenerates from its config:

    python scripts/check_example_run.py [--reference DIR] [--results DIR] [--root DIR] [--jobs 2] [--keep]

It runs ``python scripts/sweep.py configs/examples/proof_of_memory.yaml --root ROOT --jobs 2 --evaluate`` into a
temporary root (minutes), then compares the panel's ``episodes.csv`` and ``training.csv`` byte for byte with the
committed ones and ``summary.json`` in every key but its evaluation's provenance (time, command, versions, git
revision, machine); exit status 0 the same, 1 a difference (printed), 2 bad arguments or a failed sweep.
``--reference DIR`` compares with another results directory instead (a regeneration made before a change: another
machine or PyTorch build may round differently from the one that made the committed files), ``--results DIR``
compares a results directory made before without running the sweep. The code is agents/cli/check_example_run.py
(the comparison: agents/analysis/compare.py); ``--help`` says the same.
"""

import sys

from agents.cli.check_example_run import main

if __name__ == "__main__":
    sys.exit(main())
