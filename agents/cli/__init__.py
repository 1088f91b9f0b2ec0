"""The command lines: ``memgym-train``, ``memgym-evaluate``, ``memgym-sweep`` and ``memgym-plot`` (pyproject's
console commands, the same programs as ``python scripts/train.py`` etc.), each a ``main(argv)`` that parses its
arguments, calls the rooms below and turns their errors into exit statuses (2: bad input, 76: pre-empted).

* :mod:`agents.cli.train`: train one config, resume or lengthen a run, or train one run of a grid;
* :mod:`agents.cli.evaluate`: score trained runs on novel seeds into a results directory;
* :mod:`agents.cli.sweep`: train and evaluate the grids of config files (local processes or SLURM);
* :mod:`agents.cli.plot`: the figures and table of results directories.

The top floor of the package; only ``scripts/`` (thin wrappers) stands above it. The modules are not imported
here: a command imports what it runs.
"""

from __future__ import annotations

__all__ = ["evaluate", "plot", "sweep", "train"]
