"""The worker of a sweep: ``python -m agents.experiments.worker RUN_DIR`` trains one prepared run directory in a
process of its own (what the local launcher starts, :func:`agents.experiments.launchers.train_run`). Exit status: 0
trained or finished already, 1 the run stopped on a non-finite value, a failed write or a damaged checkpoint,
:data:`~agents.experiments.launchers.EXIT_BUSY` another process trains it,
:data:`~agents.runtime.preemption.EXIT_PREEMPTED` pre-empted after a checkpoint. Nothing imports this module (it is
run by ``python -m``), so that it runs as a fresh ``__main__``.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

from agents.experiments.launchers import EXIT_BUSY, train_run
from agents.policy.checkpoint import DamagedCheckpoint
from agents.runtime.preemption import EXIT_PREEMPTED


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m agents.experiments.worker RUN_DIR``: train one prepared run directory (what the local launcher
    runs)."""
    args = list(sys.argv[1:] if argv is None else argv)
    if len(args) != 1:
        print("usage: python -m agents.experiments.worker RUN_DIR", file=sys.stderr)
        return 2
    from agents.runtime.preemption import Preempted
    from agents.training.trainer import TrainingDiverged, WriteFailed

    try:
        result = train_run(args[0], echo=lambda text: print(text, flush=True))
    except Preempted as err:
        print(f"pre-empted: {err}", flush=True)
        return EXIT_PREEMPTED
    except (TrainingDiverged, WriteFailed, DamagedCheckpoint) as err:
        print(f"error: {err}", flush=True)
        return 1
    return EXIT_BUSY if result == "busy" else 0


if __name__ == "__main__":
    sys.exit(main())
