"""Writing results and saying where they came from: atomic writes, git revision, versions, machine, and where a
result table may be written (:class:`ResultFile`).

Everything that writes a checkpoint, a record or a figure goes through :func:`atomic_write_bytes`, so a reader sees
the old file or the complete new one, never a half-written file. Standard library only at import time (numpy,
gymnasium and torch are looked up inside :func:`versions` and :func:`machine_info`), so the reference tooling can
use it from memory-gym's isolated environment.
"""

from __future__ import annotations

import argparse
import contextlib
import datetime
import hashlib
import importlib.metadata
import json
import os
import platform
import subprocess
import sys
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from agents.runtime.faults import at_write

ROOT = Path(__file__).resolve().parents[2]
COMMITTED_RESULTS = ROOT / "results"  # committed result tables: replaced only where --out names them
SCRATCH = ROOT / "runs"  # git-ignored: where result tables go by default


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    """Write ``data`` to a temporary file next to ``path``, flush it to disk, then rename it over ``path``.

    If anything fails, the temporary file is removed and ``path`` is left as it was.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    at_write(path, "open")  # the fault-injection hooks (MEMGYM_FAULT, agents/runtime/faults.py): no-ops unless set
    handle = tempfile.NamedTemporaryFile("wb", dir=path.parent, prefix=f".{path.name}.", suffix=".tmp", delete=False)
    try:
        with handle:
            view, half = memoryview(data), len(data) // 2  # in two halves: a fault can strike in between
            handle.write(view[:half])
            at_write(path, "data")
            handle.write(view[half:])
            handle.flush()
            at_write(path, "fsync")
            os.fsync(handle.fileno())
        os.chmod(handle.name, 0o666 & ~_umask())  # the mode a plain open() would give, not the temp file's 0600
        at_write(path, "rename")
        os.replace(handle.name, path)
    except BaseException:
        Path(handle.name).unlink(missing_ok=True)
        raise
    at_write(path, "done")


def content_record(data: bytes) -> dict[str, Any]:
    """Size and SHA-256 of some bytes: what a checkpoint or a summary records of a file, so that a truncated or
    corrupted copy is told from an intact one."""
    return {"bytes": len(data), "sha256": hashlib.sha256(data).hexdigest()}


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write_text(path: str | Path, text: str) -> None:
    atomic_write_bytes(path, text.encode())


def create_text_once(path: str | Path, text: str) -> bool:
    """Create ``path`` holding ``text``, complete, unless it exists: of processes that race to create it, exactly one
    does, and the others leave its content alone. Returns whether this call created it."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    handle = tempfile.NamedTemporaryFile("wb", dir=path.parent, prefix=f".{path.name}.", suffix=".new", delete=False)
    try:
        with handle:
            handle.write(text.encode())
            handle.flush()
            os.fsync(handle.fileno())
        os.chmod(handle.name, 0o666 & ~_umask())
        os.link(handle.name, path)  # a hard link fails if the name exists, where a rename would replace the file
        return True
    except FileExistsError:
        return False
    finally:
        Path(handle.name).unlink(missing_ok=True)


@contextlib.contextmanager
def exclusive_lock(path: str | Path) -> Iterator[None]:
    """Hold an exclusive lock on the file ``path`` (created if missing) while the block runs, waiting for another
    process that holds it. The lock goes with the process, however it ends, so a killed holder leaves none behind."""
    import fcntl  # POSIX only; imported here so that importing this module stays portable

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def json_text(data: Any, sort_keys: bool = True) -> str:
    """``data`` as indented JSON with a final newline: the form of every JSON file the project writes."""
    return json.dumps(data, indent=2, sort_keys=sort_keys) + "\n"


def write_json_atomic(path: str | Path, data: Any, sort_keys: bool = True) -> None:
    """``data`` as indented JSON; serialised before the file is touched, so a failure leaves no trace."""
    atomic_write_text(path, json_text(data, sort_keys))


def git_revision() -> dict[str, Any]:
    """The repository's commit and whether the working tree had uncommitted changes ('unknown' outside git)."""
    try:

        def git(*args: str) -> str:
            return subprocess.run(
                ["git", *args], cwd=ROOT, capture_output=True, text=True, check=True, timeout=10
            ).stdout.strip()

        return {
            "revision": git("rev-parse", "HEAD"),
            "dirty": bool(git("status", "--porcelain", "--untracked-files=no")),
        }
    except (OSError, subprocess.SubprocessError):
        return {"revision": "unknown", "dirty": None}


def versions() -> dict[str, str]:
    """Python and the installed versions of the packages that shape results."""
    found = {"python": platform.python_version()}
    for name in ("numpy", "gymnasium", "torch", "pygame", "transformers"):
        try:  # the installed distribution's metadata: nothing is imported
            found[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            continue
    return found


def machine_info() -> dict[str, Any]:
    """Platform, processor, core count and, where torch is loaded, its threads and GPU."""
    info: dict[str, Any] = {
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
    }
    torch = sys.modules.get("torch")  # reported only when the caller uses torch; never imported just for this
    if torch is not None:
        info["torch_threads"] = torch.get_num_threads()
        info["cuda"] = torch.cuda.get_device_name(0) if torch.cuda.is_available() else None
    return info


def provenance() -> dict[str, Any]:
    """What every result file records about how it was made: time, command, versions, git revision, machine."""
    return {
        "time": now(),
        "command": [Path(sys.argv[0]).name, *sys.argv[1:]] if sys.argv and sys.argv[0] else [],
        "versions": versions(),
        "git": git_revision(),
        "machine": machine_info(),
    }


def now() -> str:
    return datetime.datetime.now().astimezone().isoformat(timespec="seconds")


# ----------------------------------------------------------------------------------------------- result tables
class OutputRefused(ValueError):
    """A result table may not be written where it was asked to go (see :class:`ResultFile`)."""


@dataclass(frozen=True)
class ResultFile:
    """Where a script writes a result table (a benchmark, the parity report, a chart of them), and the rule that keeps
    the committed tables whole:

    * without ``--out`` a table goes to its default under ``runs/`` (git-ignored); an existing file under
      ``results/`` is replaced only when ``--out`` names it;
    * a partial run (``partial`` says why, e.g. ``--quick, 1 of 10 ids``; empty for a full run) never replaces a file
      that holds a full table (``holds_full(path)``), whoever named it.

    Scripts check before they measure (:meth:`for_command`: a refusal costs nothing) and write through :meth:`save`
    / :meth:`save_json`, which check again; what is refused then is kept under ``runs/refused/``, not lost."""

    path: Path
    explicit: bool
    holds_full: Callable[[Path], bool]
    committed: Path = COMMITTED_RESULTS
    scratch: Path = SCRATCH

    @classmethod
    def choose(cls, out: str | Path | None, default: Path, holds_full: Callable[[Path], bool]) -> ResultFile:
        """The file ``--out`` names (``out``), else ``default`` (a path under ``runs/``)."""
        return cls(Path(out) if out is not None else Path(default), out is not None, holds_full)

    @classmethod
    def for_command(
        cls,
        parser: argparse.ArgumentParser,
        out: str | Path | None,
        default: Path,
        holds_full: Callable[[Path], bool],
        partial: str,
    ) -> ResultFile:
        """:meth:`choose` and :meth:`check` for a script, before it measures: a refusal costs nothing and ends the
        script through ``parser.error`` (exit status 2)."""
        target = cls.choose(out, default, holds_full)
        try:
            target.check(partial)
        except OutputRefused as err:
            parser.error(str(err))
        return target

    def check(self, partial: str) -> None:
        """:class:`OutputRefused`, with what to do instead, when this run may not replace the file."""
        if not self.path.exists():
            return
        if not self.explicit and self.path.resolve().is_relative_to(self.committed.resolve()):
            raise OutputRefused(f"{self.path} is a committed result: it is replaced only where --out names it")
        if partial and self.holds_full(self.path):
            raise OutputRefused(
                f"{self.path} holds a full table and this run is partial ({partial}): a partial run never replaces "
                "a full table; write it elsewhere with --out PATH"
            )

    def write_bytes(self, data: bytes, partial: str) -> Path:
        """Write ``data`` atomically after :meth:`check`; a refused output goes to ``runs/refused/`` and the error
        says where."""
        try:
            self.check(partial)
        except OutputRefused as err:
            stamp = datetime.datetime.now().strftime("%Y%m%d-%H%M%S")
            kept = self.scratch / "refused" / f"{stamp}-{self.path.name}"
            atomic_write_bytes(kept, data)
            raise OutputRefused(f"{err} (this run's output is kept in {kept})") from None
        atomic_write_bytes(self.path, data)
        return self.path

    def save(self, data: bytes, partial: str) -> Path:
        """:meth:`write_bytes` for a script: a refusal ends it with the message (exit status 1); says where the file
        went."""
        try:
            self.write_bytes(data, partial)
        except OutputRefused as err:
            raise SystemExit(f"error: {err}") from None
        print(f"wrote {self.path}")
        return self.path

    def save_json(self, record: Any, partial: str, sort_keys: bool = True) -> Path:
        return self.save(json_text(record, sort_keys).encode(), partial)


def add_out_argument(parser: argparse.ArgumentParser, default: Path, what: str = "the table") -> None:
    """The ``--out`` option of a script that writes a result table through :meth:`ResultFile.choose`."""
    parser.add_argument(
        "--out",
        type=Path,
        help=f"{what}'s file (default {repo_relative(default)}); a file under results/ only when named here",
    )


def repo_relative(path: Path) -> Path:
    """``path`` relative to the repository when it is inside it (how help texts show default paths)."""
    return path.relative_to(ROOT) if path.is_relative_to(ROOT) else path


def json_table(partial_of: Callable[[dict], str]) -> Callable[[Path], bool]:
    """``holds_full`` of :class:`ResultFile` for a JSON table: the file is a mapping that ``partial_of`` (the reasons
    a record is partial, empty when it is full) finds full. A file that is not such a table holds none."""

    def holds_full(path: Path) -> bool:
        try:
            record = json.loads(Path(path).read_text())
            return isinstance(record, dict) and not partial_of(record)
        except (OSError, ValueError, KeyError, TypeError, AttributeError):  # unreadable, or another kind of file
            return False

    return holds_full
