"""Writing results and saying where they came from: atomic writes, git revision, versions, machine.

Everything that writes a checkpoint, a record or a figure goes through :func:`atomic_write_bytes`, so a reader sees
the old file or the complete new one, never a half-written file. Standard library only at import time (numpy,
gymnasium and torch are looked up inside :func:`versions` and :func:`machine_info`), so the reference tooling can
use it from memory-gym's isolated environment.
"""

from __future__ import annotations

import datetime
import importlib.metadata
import json
import os
import platform
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    """Write ``data`` to a temporary file next to ``path``, flush it to disk, then rename it over ``path``.

    If anything fails, the temporary file is removed and ``path`` is left as it was.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    handle = tempfile.NamedTemporaryFile("wb", dir=path.parent, prefix=f".{path.name}.", suffix=".tmp", delete=False)
    try:
        with handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
        os.chmod(handle.name, 0o666 & ~_umask())  # the mode a plain open() would give, not the temp file's 0600
        os.replace(handle.name, path)
    except BaseException:
        Path(handle.name).unlink(missing_ok=True)
        raise


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write_text(path: str | Path, text: str) -> None:
    atomic_write_bytes(path, text.encode())


def write_json_atomic(path: str | Path, data: Any, sort_keys: bool = True) -> None:
    """``data`` as indented JSON; serialised before the file is touched, so a failure leaves no trace."""
    atomic_write_text(path, json.dumps(data, indent=2, sort_keys=sort_keys) + "\n")


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
