"""scripts/check_example_run.py: exit status 0 when results are the committed ones, 1 naming a difference, 2 on bad
input (the sweep it runs by default is the example's own, checked by hand: minutes on two cores)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from agents.runtime.io import ROOT
from scripts import check_example_run

EXAMPLE = ROOT / "results" / "examples" / "proof_of_memory"


def test_the_committed_results_are_the_same_as_themselves(capsys: pytest.CaptureFixture) -> None:
    assert check_example_run.main(["--results", str(EXAMPLE)]) == 0
    assert capsys.readouterr().out.endswith(f"{EXAMPLE} is the same as {EXAMPLE}\n")


def test_a_difference_exits_1_and_is_printed(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    produced = Path(shutil.copytree(EXAMPLE, tmp_path / "results"))
    text = (produced / "episodes.csv").read_text()
    (produced / "episodes.csv").write_text(text.replace("\n", "\n ", 1))
    assert check_example_run.main(["--results", str(produced)]) == 1
    out = capsys.readouterr().out
    assert out.startswith("episodes.csv: line 2 differs") and f"{produced} differs from {EXAMPLE}" in out


def test_a_reference_without_results_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert check_example_run.main(["--results", str(EXAMPLE), "--reference", str(tmp_path)]) == 2
    assert "holds no results (summary.json)" in capsys.readouterr().err
