"""The sweep's worker entry point, ``python -m agents.experiments.worker RUN_DIR`` (what the local launcher starts)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from agents.experiments.launchers import worker_command


def test_the_launcher_starts_the_worker_module() -> None:
    assert worker_command(Path("runs/p/m/t/seed0"))[1:] == ["-m", "agents.experiments.worker", "runs/p/m/t/seed0"]


@pytest.mark.slow
def test_the_worker_runs_as_a_fresh_main_and_says_its_usage(tmp_path: Path) -> None:
    """Nothing imports the worker module, so python -m runs it without runpy's warning of a module imported twice."""
    done = subprocess.run(
        [sys.executable, "-m", "agents.experiments.worker"], cwd=tmp_path, capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 2
    assert done.stderr == "usage: python -m agents.experiments.worker RUN_DIR\n"
