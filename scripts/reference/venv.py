"""The isolated virtual environment of the reference package memory-gym==1.0.2, and the runs started in it.

The reference pins gymnasium 0.29 and pygame 2.4, so it lives in its own venv: ``.venv-reference`` in the repository
root by default, or the directory named by ``MEMORY_GYM_REFERENCE_VENV``. This module runs with the project's python
(standard library only) and starts ``scripts.reference.recorder`` and ``scripts.reference.bench`` as subprocesses
with that venv's python, from the repository root. The command line is ``scripts/reference_traces.py``.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

from scripts.reference import REPO_ROOT

VENV_ENV_VAR = "MEMORY_GYM_REFERENCE_VENV"
REFERENCE_REQUIREMENTS = ["memory-gym==1.0.2", "numpy==2.4.6"]


def reference_venv_path() -> Path:
    """Location of the reference venv: ``$MEMORY_GYM_REFERENCE_VENV`` or ``<repo>/.venv-reference``."""
    return Path(os.environ.get(VENV_ENV_VAR) or REPO_ROOT / ".venv-reference")


def _venv_python(venv: Path) -> Path:
    return venv / ("Scripts/python.exe" if os.name == "nt" else "bin/python")


def reference_python() -> Path | None:
    """Python of the reference venv, or None when the venv (with memory-gym installed) does not exist."""
    venv = reference_venv_path()
    python = _venv_python(venv)
    installed = [
        *venv.glob("lib/python*/site-packages/memory_gym-1.0.2.dist-info"),
        *venv.glob("Lib/site-packages/memory_gym-1.0.2.dist-info"),
    ]
    if not python.exists() or not installed:
        return None
    return python


def _clean_env() -> dict[str, str]:
    """Environment for the venv subprocesses: headless SDL, no pygame banner, nothing leaking from the caller."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "PIP_CONSTRAINT")}
    env.update(SDL_VIDEODRIVER="dummy", SDL_AUDIODRIVER="dummy", PYGAME_HIDE_SUPPORT_PROMPT="1")
    return env


def ensure_reference_venv(path: Path | None = None) -> Path:
    """Create the isolated reference venv with memory-gym==1.0.2 if it is missing; return its python."""
    venv = Path(path) if path is not None else reference_venv_path()
    python = _venv_python(venv)
    if not python.exists():
        subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    probe = subprocess.run([str(python), "-c", "import memory_gym"], check=False, env=_clean_env(), capture_output=True)
    if probe.returncode != 0:
        pip = [str(python), "-m", "pip", "install", "--disable-pip-version-check", "-q", *REFERENCE_REQUIREMENTS]
        subprocess.run(pip, check=True, env=_clean_env())
    return python


def _run_module(python: Path, module: str, *args: str, capture: bool = False) -> subprocess.CompletedProcess[str]:
    """Run ``python -m scripts.reference.<module> args`` from the repository root."""
    cmd = [str(python), "-m", f"scripts.reference.{module}", *args]
    return subprocess.run(cmd, cwd=REPO_ROOT, env=_clean_env(), check=True, text=True, capture_output=capture)


def record_traces(ids: Sequence[str], out: Path) -> None:
    """Record ``<out>/<env_id>.json.gz`` for every id (builds the venv if needed)."""
    _run_module(ensure_reference_venv(), "recorder", "traces", "--ids", *ids, "--out", str(out.resolve()))


def verify_traces(ids: Sequence[str], out: Path) -> None:
    """Replay the recorded traces on the reference; raises CalledProcessError on any mismatch."""
    _run_module(ensure_reference_venv(), "recorder", "verify", "--ids", *ids, "--out", str(out.resolve()))


def record_mp_paths(out: Path) -> None:
    """Record the Mystery Path / Endless Mystery Path layouts to ``out``."""
    _run_module(ensure_reference_venv(), "recorder", "mp-paths", "--out", str(out.resolve()))


def run_reference_bench(ids: Sequence[str], episodes: int = 100) -> dict[str, float] | None:
    """Reference steps/s per id (protocol: ``scripts.reference.bench``); None when the venv is missing."""
    python = reference_python()
    if python is None:
        return None
    proc = _run_module(python, "bench", "--ids", *ids, "--episodes", str(episodes), capture=True)
    rows = [json.loads(line) for line in proc.stdout.splitlines() if line.startswith("{")]
    return {row["id"]: row["steps_per_s"] for row in rows}
