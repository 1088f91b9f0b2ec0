"""Fault injection: make a real run fail at a chosen point, to test what survives it.

The environment variable ``MEMGYM_FAULT`` holds one fault or several separated by ``;``. Nothing happens while it
is unset or empty; a malformed value is a :class:`FaultSpecError` naming the bad part and the valid choices. The
hooks are read by :func:`agents.runtime.io.atomic_write_bytes` (every checkpoint, record and summary goes through it)
and by the trainer's update (:meth:`agents.training.trainer.Trainer.train_update`), so a test outside the repository can
set the variable on a ``scripts/train.py``, ``scripts/sweep.py`` or ``scripts/evaluate.py`` process and inject:

``write:<glob>:<n>:<stage>:<action>``
    at the ``n``-th atomic write (1-based, counted per process) of a file whose name matches ``<glob>`` (fnmatch on
    the file name, e.g. ``update_*.pt``, ``training.csv``, ``*``), at ``<stage>``: ``open`` (before the temporary
    file exists), ``data`` (half of the bytes written), ``fsync`` (all written, not yet flushed to disk), ``rename``
    (flushed, not yet in place) or ``done`` (in place); do ``<action>``: ``kill`` (SIGKILL this process), ``enospc``
    (fail with ``OSError`` ENOSPC, as a full disk does) or ``eio`` (fail with ``OSError`` EIO, as a failing fsync
    does), or ``sigterm`` / ``sigusr2`` (send that signal to this process and go on: a pre-emption that arrives in
    the middle of a write). Example: ``write:update_*.pt:2:fsync:eio``.
``update:<n>:<target>:<value>``
    at update ``n`` (1-based) put ``<value>`` (``nan`` or ``inf``) into ``<target>``: ``loss`` (the rollout's
    advantages and returns, so the PPO loss is non-finite) or ``params`` (one weight, after the update's last
    optimizer step). Example: ``update:3:params:nan``.
``signal:<n>:<name>``
    during update ``n`` (after its rollout) send the signal ``<name>`` (``SIGTERM``, ``SIGUSR2``, ``SIGINT``,
    ``SIGKILL``) to this process. Example: ``signal:2:SIGTERM``.

Counters are per process: a resumed run (a new process) starts counting again.
"""

from __future__ import annotations

import errno
import fnmatch
import os
import signal
from dataclasses import dataclass
from pathlib import Path

ENV_VARIABLE = "MEMGYM_FAULT"
WRITE_STAGES = ("open", "data", "fsync", "rename", "done")
WRITE_ACTIONS = ("kill", "enospc", "eio", "sigterm", "sigusr2")
UPDATE_TARGETS = ("loss", "params")
UPDATE_VALUES = {"nan": float("nan"), "inf": float("inf")}
SIGNALS = ("SIGTERM", "SIGUSR2", "SIGINT", "SIGKILL")


class FaultSpecError(ValueError):
    """``MEMGYM_FAULT`` does not parse; the message names the bad part and the valid choices."""


@dataclass(frozen=True)
class Fault:
    """One parsed entry of ``MEMGYM_FAULT`` (``site`` is write, update or signal; unused fields stay empty)."""

    site: str
    count: int
    pattern: str = ""
    stage: str = ""
    action: str = ""


def parse_faults(text: str) -> list[Fault]:
    """The faults of a ``MEMGYM_FAULT`` value (see the module docstring)."""
    faults = []
    for entry in filter(None, (part.strip() for part in text.split(";"))):
        site, *fields = entry.split(":")
        if site == "write" and len(fields) == 4:
            pattern, count, stage, action = fields
            _choose(entry, "stage", stage, WRITE_STAGES)
            _choose(entry, "action", action, WRITE_ACTIONS)
            faults.append(Fault("write", _count(entry, count), pattern or "*", stage, action))
        elif site == "update" and len(fields) == 3:
            count, target, value = fields
            _choose(entry, "target", target, UPDATE_TARGETS)
            _choose(entry, "value", value, tuple(UPDATE_VALUES))
            faults.append(Fault("update", _count(entry, count), stage=target, action=value))
        elif site == "signal" and len(fields) == 2:
            count, name = fields
            _choose(entry, "signal", name, SIGNALS)
            faults.append(Fault("signal", _count(entry, count), action=name))
        else:
            raise FaultSpecError(
                f"{ENV_VARIABLE}: {entry!r} is not a fault; expected write:<glob>:<n>:<stage>:<action>, "
                "update:<n>:<target>:<value> or signal:<n>:<name>"
            )
    return faults


def _choose(entry: str, what: str, value: str, valid: tuple[str, ...]) -> None:
    if value not in valid:
        raise FaultSpecError(f"{ENV_VARIABLE}: {entry!r}: {what} {value!r} is invalid; valid: {', '.join(valid)}")


def _count(entry: str, text: str) -> int:
    if not text.isdigit() or int(text) < 1:
        raise FaultSpecError(f"{ENV_VARIABLE}: {entry!r}: {text!r} is invalid; expected a whole number >= 1")
    return int(text)


_parsed: tuple[str, list[Fault]] = ("", [])
_writes: dict[Fault, int] = {}  # matching writes seen so far, per write fault


def active_faults() -> list[Fault]:
    """The faults ``MEMGYM_FAULT`` asks for now (parsed once per value; a new value restarts the write counts)."""
    global _parsed
    text = os.environ.get(ENV_VARIABLE, "")
    if text != _parsed[0]:
        _parsed = (text, parse_faults(text))
        _writes.clear()
    return _parsed[1]


def reset() -> None:
    """Forget the parsed value and the write counts: a process (a test) that sets the same value again starts
    counting afresh."""
    global _parsed
    _parsed = ("", [])
    _writes.clear()


def at_write(path: Path, stage: str) -> None:
    """The atomic write's hook: called at each stage of writing ``path``; fails or kills where a fault says so."""
    for fault in active_faults():
        if fault.site != "write" or not fnmatch.fnmatch(path.name, fault.pattern):
            continue
        if stage == "open":  # every write passes "open" first: count it there
            _writes[fault] = _writes.get(fault, 0) + 1
        if fault.stage != stage or _writes.get(fault) != fault.count:
            continue
        if fault.action == "kill":
            os.kill(os.getpid(), signal.SIGKILL)
        if fault.action in ("sigterm", "sigusr2"):
            os.kill(os.getpid(), getattr(signal, fault.action.upper()))
            continue
        code = errno.ENOSPC if fault.action == "enospc" else errno.EIO
        raise OSError(code, f"{os.strerror(code)} (injected by {ENV_VARIABLE} at {stage})", str(path))


def update_value(update: int, target: str) -> float | None:
    """The value to put into ``target`` (loss or params) at ``update`` (1-based), or None."""
    for fault in active_faults():
        if fault.site == "update" and fault.count == update and fault.stage == target:
            return UPDATE_VALUES[fault.action]
    return None


def signal_during(update: int) -> None:
    """Send the signal a ``signal:<n>:<name>`` fault names for ``update`` (1-based) to this process."""
    for fault in active_faults():
        if fault.site == "signal" and fault.count == update:
            os.kill(os.getpid(), getattr(signal, fault.action))
