"""Pre-emption: SIGTERM, and the warning signal SLURM sends before a job is stopped (SIGUSR2 as submitit asks for it,
or the signal its ``SUBMITIT_PREEMPT_SIGNAL`` names), stop work at its next safe point instead of wherever it is.

* Training (:meth:`agents.training.trainer.Trainer.train`): the signal is noted, the update in progress finishes, a
  checkpoint is written and ``train()`` raises :class:`Preempted`; ``scripts/train.py`` and the sweep's worker then exit
  with :data:`EXIT_PREEMPTED`. If the signal had a Python handler before training began (submitit's, which requeues the
  job), that handler receives it after the checkpoint instead.
* The sweep's local launcher (:func:`agents.experiments.launchers.launch_local`) passes the signal on to every run it
  trains, starts no new one, waits for their checkpoints and reports them as pre-empted (resumable, not failed);
  ``scripts/sweep.py`` exits with :data:`EXIT_PREEMPTED`.
* Evaluation (``scripts/evaluate.py``): the signal ends it with :data:`EXIT_PREEMPTED`, except while its results are
  written (:func:`deferred_signals`): those files are written together, and the signal takes effect right after.

A signal that arrives before this handling starts (while a run is being built) has its usual effect; nothing of the
run is lost then but what it had not checkpointed. A signal that was ignored when the process started stays ignored.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
from collections.abc import Iterator
from types import FrameType
from typing import Any

EXIT_PREEMPTED = 76  # a run stopped by a pre-emption signal after writing its checkpoint: resume it (not a failure)


class Preempted(RuntimeError):
    """Work stopped at a safe point because of a pre-emption signal; the message says what was kept."""

    def __init__(self, message: str, signum: int) -> None:
        super().__init__(message)
        self.signum = signum


def preemption_signals() -> tuple[signal.Signals, ...]:
    """SIGTERM and SLURM's warning signal as submitit configures it (``SUBMITIT_PREEMPT_SIGNAL``, default USR2)."""
    name = os.environ.get("SUBMITIT_PREEMPT_SIGNAL", "USR2")
    warning = getattr(signal, f"SIG{name}", signal.SIGUSR2)
    return tuple(dict.fromkeys((signal.SIGTERM, warning)))


def signal_name(signum: int) -> str:
    return signal.Signals(signum).name


class StopRequests:
    """While active (a context manager), the pre-emption signals are noted instead of acted on; ``received`` holds
    the first one (None before). Handlers can only be set in the main thread: elsewhere nothing changes."""

    def __init__(self) -> None:
        self.received: int | None = None
        self.received_first: int | None = None  # kept when pass_on() forgets ``received``
        self._previous: dict[int, Any] = {}

    def __enter__(self) -> StopRequests:
        if threading.current_thread() is not threading.main_thread():
            return self
        for signum in preemption_signals():
            previous = signal.getsignal(signum)
            if previous == signal.SIG_IGN:
                continue
            self._previous[signum] = previous
            signal.signal(signum, self._note)
        return self

    def _note(self, signum: int, frame: FrameType | None) -> None:
        if self.received is None:
            self.received = signum
            self.received_first = signum

    def __exit__(self, *exc: object) -> None:
        for signum, previous in self._previous.items():
            signal.signal(signum, previous if previous is not None else signal.SIG_DFL)
        self._previous.clear()

    def pass_on(self) -> bool:
        """Give the received signal to the Python handler it had before (submitit's requeue, which exits); returns
        True when that handler returned (it chose to go on: the signal is forgotten), False when there was none."""
        signum = self.received
        previous = self._previous.get(signum) if signum is not None else None
        if signum is None or not callable(previous):
            return False
        self.received = None
        previous(signum, None)
        return True


@contextlib.contextmanager
def deferred_signals() -> Iterator[None]:
    """Hold the pre-emption signals back while the block runs (files that belong together are written together);
    one that arrived is raised again when it ends, and then has whatever effect it would have had."""
    with StopRequests() as stops:
        yield
    if stops.received is not None:
        signal.raise_signal(stops.received)


@contextlib.contextmanager
def raising_preempted(what: str) -> Iterator[None]:
    """Turn a pre-emption signal into :class:`Preempted` (``what`` says what stopped) while the block runs."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def stop(signum: int, frame: FrameType | None) -> None:
        raise Preempted(f"{what} stopped by {signal_name(signum)}", signum)

    ignored = [signum for signum in preemption_signals() if signal.getsignal(signum) == signal.SIG_IGN]
    previous = {signum: signal.signal(signum, stop) for signum in preemption_signals() if signum not in ignored}
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler if handler is not None else signal.SIG_DFL)
