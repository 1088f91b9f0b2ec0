"""The runtime room: what every other room leans on while a run lives and writes, whatever it computes.

* :mod:`agents.runtime.io`: atomic writes, locks, provenance (git revision, versions, machine), result files;
* :mod:`agents.runtime.faults`: fault injection (``MEMGYM_FAULT``), the hooks that make a real run fail on purpose;
* :mod:`agents.runtime.preemption`: SIGTERM / SLURM's warning signal stop work at its next safe point;
* :mod:`agents.runtime.tracking`: TensorBoard and Weights & Biases writers of a run's scalars;
* :mod:`agents.runtime.devices`: the torch device a run computes on, checked once for training and evaluation;
* :mod:`agents.runtime.allocator`: the C allocator keeps freed memory for torch's CPU tensors (set by training).

The first three are standard library only at import time, so that the reference tooling (``scripts/reference/``,
run in memory-gym's own venv) can import them; this face therefore re-exports their names only. Tracking and
devices read the config (a floor below) and torch, so their names are imported from their own modules.
"""

from __future__ import annotations

from agents.runtime.faults import Fault, FaultSpecError, active_faults, parse_faults
from agents.runtime.io import (
    OutputRefused,
    ResultFile,
    atomic_write_bytes,
    atomic_write_text,
    content_record,
    create_text_once,
    exclusive_lock,
    now,
    provenance,
    write_json_atomic,
)
from agents.runtime.preemption import (
    EXIT_PREEMPTED,
    Preempted,
    StopRequests,
    deferred_signals,
    raising_preempted,
    signal_name,
)

__all__ = [
    "EXIT_PREEMPTED",
    "Fault",
    "FaultSpecError",
    "OutputRefused",
    "Preempted",
    "ResultFile",
    "StopRequests",
    "active_faults",
    "atomic_write_bytes",
    "atomic_write_text",
    "content_record",
    "create_text_once",
    "deferred_signals",
    "exclusive_lock",
    "now",
    "parse_faults",
    "provenance",
    "raising_preempted",
    "signal_name",
    "write_json_atomic",
]
