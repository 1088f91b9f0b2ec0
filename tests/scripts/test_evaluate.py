"""scripts/evaluate.py on tiny trained runs: merging into a results directory, run names, training logs for the
curves, argument checks and the printed seed range."""

from __future__ import annotations

import copy
import csv
import json
import shutil
from pathlib import Path

import pytest
import torch

from agents.analysis.plots import curves_figure
from agents.analysis.results import read_episodes, read_results
from agents.config import config_from_dict
from agents.evaluation.records import read_records
from agents.evaluation.runs import evaluate_runs, unique_run_names
from agents.training.trainer import Trainer
from scripts import evaluate as evaluate_script
from tests.agents.evaluation.test_evaluation import TINY

QUIET = ["--no-progress"]


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A GRU-PPO and a memory-less PPO run (checkpoints at steps 64 and 128), and two GRU runs (the first copied,
    and one of another seed) in two directories both named seed1."""
    root = tmp_path_factory.mktemp("runs")
    ppo = copy.deepcopy(TINY)
    ppo["model"] = {"memory": "none", "hidden_size": 8}
    other_seed = copy.deepcopy(TINY)
    other_seed["run"]["seed"] = TINY["run"]["seed"] + 1
    Trainer(config_from_dict(TINY), root / "gru" / "seed1").train()
    Trainer(config_from_dict(ppo), root / "ppo" / "seed1").train()
    shutil.copytree(root / "gru" / "seed1", root / "a" / "seed1")
    Trainer(config_from_dict(other_seed), root / "b" / "seed1").train()  # the same run twice would be refused
    return {name: root / name / "seed1" for name in ("gru", "ppo", "a", "b")}


def evaluate(*args: str) -> int:
    return evaluate_script.main([*args, *QUIET])


def keys(directory: Path) -> set[tuple]:
    return {
        (r["method"], r["run"], r["step"], r["seed"], r["repetition"]) for r in read_records(directory / "episodes.csv")
    }


def test_a_second_run_evaluated_into_the_same_directory_keeps_the_first_one_s_records(
    runs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """B5: rows of other runs and checkpoints stay; rows of the same key are replaced only with --force, and the
    summary covers all the records."""
    out = tmp_path / "results"
    assert evaluate("--run", str(runs["ppo"]), "--out", str(out)) == 0
    assert evaluate("--run", str(runs["gru"]), "--out", str(out), "--checkpoints", "64") == 0
    assert "kept 12 earlier record(s), replaced 0, added 12" in capsys.readouterr().out
    both = keys(out)
    assert {(method, step) for method, _, step, _, _ in both} == {("ppo", 128), ("gru", 64)} and len(both) == 24
    summary = json.loads((out / "summary.json").read_text())
    assert sorted((row["method"], row["step"]) for row in summary["runs"]) == [("gru", 64), ("ppo", 128)]
    assert len(summary["earlier_evaluations"]) == 1

    files = {name: (out / name).read_bytes() for name in ("episodes.csv", "training.csv", "summary.json")}
    assert evaluate("--run", str(runs["gru"]), "--out", str(out), "--checkpoints", "64,128") == 2
    error = capsys.readouterr().err
    assert "already holds 12 of the records" in error and "run=seed1, step=64" in error
    assert "give --force to replace them, or another --out directory" in error
    assert {name: (out / name).read_bytes() for name in files} == files, "a refused evaluation changes nothing"

    assert evaluate("--run", str(runs["gru"]), "--out", str(out), "--checkpoints", "64,128", "--force") == 0
    assert "kept 12 earlier record(s), replaced 12, added 12" in capsys.readouterr().out
    assert len(keys(out)) == 36 == len(read_records(out / "episodes.csv"))  # replaced, not doubled
    assert len(read_episodes(out)) == 36


def test_runs_in_directories_of_the_same_name_get_distinct_names(runs: dict[str, Path], tmp_path: Path) -> None:
    """C7: runs/a/seed1 and runs/b/seed1, together or one after the other, never read as one run twice."""
    together = tmp_path / "together"
    assert evaluate("--run", str(runs["a"]), str(runs["b"]), "--out", str(together)) == 0
    assert {r["run"] for r in read_records(together / "episodes.csv")} == {"a/seed1", "b/seed1"}
    assert len(read_episodes(together)) == 24
    training = read_results(together).training
    assert training is not None and set(training["run"].tolist()) == {"a/seed1", "b/seed1"}

    apart = tmp_path / "apart"
    assert evaluate("--run", str(runs["a"]), "--out", str(apart)) == 0
    assert evaluate("--run", str(runs["b"]), "--out", str(apart)) == 0  # no --force needed: another run
    assert evaluate("--run", str(runs["a"]), "--out", str(apart)) == 2  # the same run again: refused
    assert {r["run"] for r in read_records(apart / "episodes.csv")} == {"seed1", "b/seed1"}
    assert len(read_episodes(apart)) == 24
    summary = json.loads((apart / "summary.json").read_text())
    assert {entry["run"]: entry["directory"] for entry in summary["run_directories"]} == {
        "seed1": str(runs["a"].resolve()),
        "b/seed1": str(runs["b"].resolve()),
    }
    assert evaluate("--run", str(runs["a"]), str(runs["a"].parent / ".." / "a" / "seed1"), "--out", str(apart)) == 2


def test_run_names_stay_short_where_method_or_task_tell_runs_apart() -> None:
    sweep = [Path("/r/panel/gru/T/seed0"), Path("/r/panel/ppo/T/seed0"), Path("/r/panel/gru/T/seed1")]
    assert unique_run_names(sweep, [("gru", "T"), ("ppo", "T"), ("gru", "T")]) == ["seed0", "seed0", "seed1"]
    nested = [Path("/x/a/seed1"), Path("/y/x/a/seed1"), Path("/z/b/seed1")]
    assert unique_run_names(nested, [("m", "T")] * 3) == ["/x/a/seed1", "y/x/a/seed1", "b/seed1"]
    taken = {("m", "T", "seed1"): "/elsewhere/seed1", ("m", "T", "b/seed1"): "/z/b/seed1"}
    assert unique_run_names([Path("/z/b/seed1"), Path("/w/seed1")], [("m", "T")] * 2, taken) == ["b/seed1", "w/seed1"]


def test_the_readme_workflow_gives_curves_with_both_panels(runs: dict[str, Path], tmp_path: Path) -> None:
    """C9: evaluate --out DIR, then plot DIR: the runs' training logs are there under the episodes' run names."""
    out = tmp_path / "mine"
    assert evaluate("--run", str(runs["gru"]), str(runs["ppo"]), "--checkpoints", "all", "--out", str(out)) == 0
    with (runs["gru"] / "training.csv").open() as handle:
        logged = len(list(csv.DictReader(handle)))
    loaded = read_results(out)
    assert loaded.training is not None and len(loaded.training) == 2 * logged
    assert set(loaded.training["run"].tolist()) == set(loaded.episodes["run"].tolist()) == {"seed1"}
    assert set(loaded.training["method"].tolist()) == {"gru", "ppo"}
    figure = curves_figure(loaded.episodes, loaded.training, reps=20)
    titles = [axes.get_title() for axes in figure.axes]
    assert any(title.endswith("training seeds") for title in titles), titles
    assert any(title.endswith("novel seeds") for title in titles), titles
    # a second evaluation of the same run merges the log instead of repeating it
    assert evaluate("--run", str(runs["gru"]), "--checkpoints", "128", "--out", str(out), "--force") == 0
    assert len(read_results(out).training) == 2 * logged


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--repetitions", "0"], "argument --repetitions: '0' is invalid: expected a whole number >= 1"),
        (["--repetitions", "-1"], "argument --repetitions: '-1' is invalid: expected a whole number >= 1"),
        (["--repetitions", "2.5"], "argument --repetitions: '2.5' is invalid"),
        (["--videos", "0"], "argument --videos: '0' is invalid: expected a whole number >= 1"),
        (["--sampling-seed", "-3"], "argument --sampling-seed: '-3' is invalid: expected a whole number in [0, "),
        (["--sampling-seed", str(2**64)], "argument --sampling-seed"),
        (["--seeds", "10:10"], "argument --seeds: '10:10' is invalid: expected LOW..HIGH (both ends included"),
        (["--seeds", "5-9"], "LOW:HIGH (HIGH excluded"),
        (["--device", "gpu"], "argument --device: device 'gpu' is invalid; valid choices: 'cpu', 'cuda', 'cuda:N'"),
        (["--device", "cuda:x"], "valid choices: 'cpu', 'cuda', 'cuda:N'"),
    ],
)
def test_bad_numbers_and_devices_are_refused_by_name(
    runs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], message: str
) -> None:
    """D11: exit status 2 and a message naming the argument, the value and what is valid; nothing written."""
    with pytest.raises(SystemExit) as exit_info:
        evaluate("--run", str(runs["gru"]), "--out", str(tmp_path / "e"), *args)
    assert exit_info.value.code == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "e").exists()


@pytest.mark.skipif(torch.cuda.is_available(), reason="CUDA is available here")
def test_cuda_on_a_machine_without_it_is_refused_cleanly(runs: dict[str, Path], capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit) as exit_info:
        evaluate("--run", str(runs["gru"]), "--device", "cuda")
    assert exit_info.value.code == 2
    assert "argument --device: device 'cuda', but CUDA is not available here; use 'cpu'" in capsys.readouterr().err
    with pytest.raises(ValueError, match="CUDA is not available"):
        evaluate_runs([runs["gru"]], runs["gru"] / "evaluation", device="cuda:0")


def test_zero_repetitions_are_refused_by_the_library_too(runs: dict[str, Path], tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="repetitions=0 is invalid"):
        evaluate_runs([runs["gru"]], tmp_path / "e", repetitions=0)


@pytest.mark.parametrize(
    ("seeds", "printed"),
    [
        ([], "novel seeds 1000..1003 (4 seeds) x 3 repetitions"),  # the run's eval.seeds: [1000, 1003]
        (["--seeds", "2000..2002"], "novel seeds 2000..2002 (3 seeds) x 3 repetitions"),
        (["--seeds", "2000:2003"], "novel seeds 2000..2002 (3 seeds) x 3 repetitions"),
        (["--seeds", "2000..2000"], "novel seeds 2000..2000 (1 seed) x 3 repetitions"),
    ],
)
def test_the_resolved_inclusive_seed_range_is_printed(
    runs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str], seeds: list[str], printed: str
) -> None:
    """D16: both conventions resolve to one printed inclusive range, and the records hold exactly those seeds."""
    out = tmp_path / "e"
    assert evaluate("--run", str(runs["gru"]), "--out", str(out), *seeds) == 0
    assert f"run seed1 ({runs['gru']}): {printed}, checkpoint(s) at step(s) 128" in capsys.readouterr().out
    low, high = (int(n) for n in printed.split()[2].split(".."))
    assert {r["seed"] for r in read_records(out / "episodes.csv")} == set(range(low, high + 1))


def test_the_help_says_which_end_of_a_seed_range_is_included(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        evaluate_script.main(["--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "LOW..HIGH, both ends included" in text and "LOW:HIGH with HIGH excluded" in text
