"""scripts/train.py on a grid config: --only (scripts/sweep.py's selection) picks the one run to train; without it,
or when it picks several runs or none, the command stops with exit status 2 and says what it can select."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from agents.config import load_config
from agents.experiments.planning import load_panel, select_runs
from scripts import train as train_script

TINY = {
    "env": {"id": "ProofOfMemory-v0", "options": {"delay": 3}},
    "model": {"memory": "gru", "memory_size": 8, "hidden_size": 8, "vector_encoder_size": 8},
    "ppo": {"epochs": 1, "minibatches": 1},
    "run": {"total_steps": 64, "workers": 4, "worker_steps": 16, "torch_threads": 1, "progress_bar": False},
}
GRID = {"method": {"ppo": {"model.memory": "none"}, "gru": {}}, "run.seed": [0, 1], "ppo.gamma": [0.9, 0.99]}
ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def grid_config(tmp_path: Path) -> Path:
    path = tmp_path / "configs" / "cells.yaml"
    path.parent.mkdir()
    path.write_text(yaml.safe_dump({**TINY, "grid": GRID}, sort_keys=False))
    return path


def test_only_trains_the_one_selected_run_of_a_grid_as_the_sweep_expands_it(
    tmp_path: Path, grid_config: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture
) -> None:
    monkeypatch.chdir(tmp_path)  # the default run directory is relative: runs/<config name>/...
    only = "method=gru,seed=1,ppo.gamma=0.9"
    assert train_script.main(["--config", str(grid_config), "--only", only]) == 0
    out = capsys.readouterr().out
    assert "training one run of the grid: cells/gru+ppo.gamma=0.9/ProofOfMemory-v0+delay=3/seed1" in out
    (run_dir,) = (tmp_path / "runs" / "cells" / "gru+ppo.gamma=0.9" / "ProofOfMemory-v0+delay=3").iterdir()
    assert run_dir.name.endswith("-seed1")
    (panel,) = select_runs([load_panel(grid_config)], [only])
    (expected,) = panel.runs
    assert load_config(run_dir / "config.yaml") == expected.config  # the sweep's point, names and all
    assert (load_config(run_dir / "config.yaml").ppo.gamma, expected.config.method) == (0.9, "gru+ppo.gamma=0.9")


@pytest.mark.parametrize(
    ("only", "message"),
    [
        (
            [],
            "error: {config} has a grid: block (8 runs): train one of them with --only KEY=VALUE[,KEY=VALUE...] "
            "(e.g. --only method=ppo,seed=0,ppo.gamma=0.9; method: ppo, gru; task: ProofOfMemory-v0+delay=3; seed: "
            "0, 1; ppo.gamma: 0.9, 0.99), or all of them with python scripts/sweep.py {config}",
        ),
        (
            ["method=gru"],
            "error: --only method=gru selects 4 runs of {config}, expected one: "
            "cells/gru+ppo.gamma=0.9/ProofOfMemory-v0+delay=3/seed0, "
            "cells/gru+ppo.gamma=0.99/ProofOfMemory-v0+delay=3/seed0, "
            "cells/gru+ppo.gamma=0.9/ProofOfMemory-v0+delay=3/seed1, "
            "cells/gru+ppo.gamma=0.99/ProofOfMemory-v0+delay=3/seed1; "
            "add pairs that tell them apart (seed: 0, 1; ppo.gamma: 0.9, 0.99)",
        ),
        (
            ["method=lstm,seed=0"],
            "error: --only method=lstm,seed=0: no run of cells has method=lstm; valid values: ppo, gru",
        ),
    ],
)
def test_a_grid_needs_only_to_select_exactly_one_run(
    tmp_path: Path, grid_config: Path, capsys: pytest.CaptureFixture, only: list[str], message: str
) -> None:
    args = ["--config", str(grid_config), "--run-dir", str(tmp_path / "run")]
    assert train_script.main([*args, *(x for item in only for x in ("--only", item))]) == 2
    assert capsys.readouterr().err == message.format(config=grid_config) + "\n"
    assert not (tmp_path / "run").exists()


def test_only_needs_a_grid_and_no_resume(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    plain = tmp_path / "plain.yaml"
    plain.write_text(yaml.safe_dump(TINY))
    assert train_script.main(["--config", str(plain), "--only", "seed=0"]) == 2
    assert capsys.readouterr().err == (
        f"error: --only selects a run of a grid config, and {plain} has no grid: block (train it without --only)\n"
    )
    with pytest.raises(SystemExit):
        train_script.main(["--resume", str(tmp_path), "--only", "seed=0"])


def test_the_gymnasium_pages_popgym_configs_say_what_to_select() -> None:
    """docs/gymnasium.md trains one run of configs/popgym/repeat_previous_easy.yaml with train.py --only."""
    page = (ROOT / "docs" / "gymnasium.md").read_text()
    command = "python scripts/train.py --config configs/popgym/repeat_previous_easy.yaml --only method=gru,seed=1"
    assert command in page
    (panel,) = select_runs(
        [load_panel(ROOT / "configs" / "popgym" / "repeat_previous_easy.yaml")], ["method=gru,seed=1"]
    )
    assert [run.name for run in panel.runs] == ["repeat_previous_easy/gru/popgym-RepeatPreviousEasy-v0/seed1"]
