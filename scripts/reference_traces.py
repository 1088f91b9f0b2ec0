"""Ground-truth traces from the reference package memory-gym==1.0.2, recorded in an isolated venv.

This module only uses the standard library; it runs with the project's python. The reference package (which pins
gymnasium 0.29 and pygame 2.4) lives in its own virtual environment, ``.venv-reference`` in the repository root by
default or the directory named by ``MEMORY_GYM_REFERENCE_VENV``. The recording itself (``reference_recorder.py``)
and the throughput benchmark (``reference_bench.py``) run as subprocesses with that venv's python.

    python scripts/reference_traces.py                     # build the venv if missing, record everything
    python scripts/reference_traces.py --ids MysteryPath-v0 --no-mp-paths
    python scripts/reference_traces.py --verify-only       # replay the committed traces on the reference
    python scripts/reference_traces.py --bench             # reference steps/s per id
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parent.parent
VENV_ENV_VAR = "MEMORY_GYM_REFERENCE_VENV"
REFERENCE_REQUIREMENTS = ["memory-gym==1.0.2", "numpy==2.4.6"]
ALL_IDS = [
    "MortarMayhem-v0",
    "MortarMayhem-Grid-v0",
    "MortarMayhemB-v0",
    "MortarMayhemB-Grid-v0",
    "MysteryPath-v0",
    "MysteryPath-Grid-v0",
    "SearingSpotlights-v0",
    "Endless-MortarMayhem-v0",
    "Endless-MysteryPath-v0",
    "Endless-SearingSpotlights-v0",
]


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
    """Run ``python -m scripts.<module> args`` from the repository root."""
    cmd = [str(python), "-m", f"scripts.{module}", *args]
    return subprocess.run(cmd, cwd=REPO_ROOT, env=_clean_env(), check=True, text=True, capture_output=capture)


def record_traces(ids: list[str], out: Path) -> None:
    """Record ``<out>/<env_id>.json.gz`` for every id (builds the venv if needed)."""
    _run_module(ensure_reference_venv(), "reference_recorder", "traces", "--ids", *ids, "--out", str(out.resolve()))


def verify_traces(ids: list[str], out: Path) -> None:
    """Replay the recorded traces on the reference; raises CalledProcessError on any mismatch."""
    _run_module(ensure_reference_venv(), "reference_recorder", "verify", "--ids", *ids, "--out", str(out.resolve()))


def record_mp_paths(out: Path) -> None:
    """Record the Mystery Path / Endless Mystery Path layouts to ``out``."""
    _run_module(ensure_reference_venv(), "reference_recorder", "mp-paths", "--out", str(out.resolve()))


def run_reference_bench(ids: list[str], episodes: int = 100) -> dict[str, float] | None:
    """Reference steps/s per id (see ``reference_bench.py`` for the protocol); None when the venv is missing."""
    python = reference_python()
    if python is None:
        return None
    proc = _run_module(python, "reference_bench", "--ids", *ids, "--episodes", str(episodes), capture=True)
    rows = [json.loads(line) for line in proc.stdout.splitlines() if line.startswith("{")]
    return {row["id"]: row["steps_per_s"] for row in rows}


def main(argv: list[str] | None = None) -> None:
    """CLI entry point."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ids", nargs="+", default=ALL_IDS, choices=ALL_IDS)
    parser.add_argument("--out", type=Path, default=REPO_ROOT / "tests" / "data" / "traces")
    parser.add_argument("--mp-paths", type=Path, default=REPO_ROOT / "tests" / "data" / "mp_paths.json.gz")
    parser.add_argument("--no-mp-paths", action="store_true", help="do not (re)record the Mystery Path layouts")
    parser.add_argument("--verify-only", action="store_true", help="only replay the traces in --out on the reference")
    parser.add_argument("--bench", action="store_true", help="only print the reference steps/s per id")
    args = parser.parse_args(argv)
    if args.bench:
        ensure_reference_venv()
        print(json.dumps(run_reference_bench(args.ids), indent=1))
        return
    if not args.verify_only:
        record_traces(args.ids, args.out)
        if not args.no_mp_paths:
            record_mp_paths(args.mp_paths)
    verify_traces(args.ids, args.out)


if __name__ == "__main__":
    main()
