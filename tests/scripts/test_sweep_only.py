"""scripts/sweep.py --only on tiny ProofOfMemory runs: the local launcher trains the selected cells only, --evaluate
writes the whole panel's results, the dry run lists the selection, SLURM submits the selected runs only, and a bad
selection exits 2 naming the valid values."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from agents.experiments.planning import load_panel
from agents.experiments.state import FINISHED, NEW, statuses
from scripts import sweep as sweep_script

TINY = {
    "env": {"id": "ProofOfMemory-v0", "options": {"delay": 3}},
    "model": {"memory": "gru", "memory_size": 16, "hidden_size": 16, "vector_encoder_size": 8},
    "ppo": {"epochs": 1, "minibatches": 1},
    "run": {"total_steps": 2 * 64, "workers": 4, "worker_steps": 16, "torch_threads": 1, "progress_bar": False},
    "eval": {"seeds": [100_000, 100_001], "repetitions": 1},
}
ROOT = Path(__file__).resolve().parents[2]
GRID = {"method": {"ppo": {"model.memory": "none"}, "gru": {}}, "task": {"pom": {}}, "run.seed": [0, 1]}


def _config(tmp_path: Path) -> Path:
    path = tmp_path / "cells.yaml"
    path.write_text(yaml.safe_dump({**TINY, "grid": GRID}, sort_keys=False))
    return path


def _states(config: Path, root: Path) -> dict[str, str]:
    return {status.run.name: status.state for status in statuses(load_panel(config, root=root).runs)}


@pytest.mark.slow
def test_local_sweep_trains_only_the_selected_cells_and_evaluates_the_whole_panel(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    config, root = _config(tmp_path), tmp_path / "runs"
    args = [str(config), "--root", str(root)]
    assert sweep_script.main([*args, "--only", "method=ppo,seed=1", "--evaluate"]) == 0
    assert _states(config, root) == {
        "cells/ppo/pom/seed0": NEW,
        "cells/ppo/pom/seed1": FINISHED,
        "cells/gru/pom/seed0": NEW,
        "cells/gru/pom/seed1": NEW,
    }
    assert not (root / "cells" / "gru").exists()  # nothing of the runs left out was created
    summary = json.loads((root / "cells" / "results" / "summary.json").read_text())
    assert {run["run"] for run in summary["runs"]} == {"cells/ppo/pom/seed1"}
    assert sorted(summary["unfinished"]) == ["cells/gru/pom/seed0", "cells/gru/pom/seed1", "cells/ppo/pom/seed0"]
    named = "cells/ppo/pom/seed0, cells/gru/pom/seed0, cells/gru/pom/seed1"
    assert f"cells: 3 run(s) not finished and left out: {named}" in capsys.readouterr().out  # a few, one by one

    # another cell: trained alone, and the panel's results gather both finished runs (never a part of the panel)
    assert sweep_script.main([*args, "--only", "method=gru,seed=0", "--evaluate"]) == 0
    assert [name for name, state in _states(config, root).items() if state == FINISHED] == [
        "cells/ppo/pom/seed1",
        "cells/gru/pom/seed0",
    ]
    summary = json.loads((root / "cells" / "results" / "summary.json").read_text())
    assert {run["run"] for run in summary["runs"]} == {"cells/ppo/pom/seed1", "cells/gru/pom/seed0"}
    out = capsys.readouterr().out
    assert "start: cells/gru/pom/seed0" in out and "cells/ppo/pom/seed1" not in out.split("final evaluation")[0]

    # the dry run lists the selection with its states; repeated --only adds runs
    assert sweep_script.main([*args, "--dry-run", "--only", "method=gru", "--only", "seed=1,method=ppo"]) == 0
    out = capsys.readouterr().out
    assert "panel cells: 3 runs selected by --only method=gru --only seed=1,method=ppo" in out
    rows = {line.split()[0]: line.split()[1] for line in out.splitlines() if line.startswith("  cells/")}
    assert rows == {"cells/ppo/pom/seed1": FINISHED, "cells/gru/pom/seed0": FINISHED, "cells/gru/pom/seed1": NEW}


def test_many_runs_left_out_of_an_evaluation_are_counted_by_task(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """One run of a big grid evaluated alone (a one-run sweep, or scripts/check_run.py on its scratch root): the runs
    left out are counted per task, not listed one by one; summary.json still names each."""
    config, root = tmp_path / "many.yaml", tmp_path / "runs"
    grid = {"task": {"short": {}, "long": {"env.options.delay": 4}}, "run.seed": list(range(5))}
    config.write_text(yaml.safe_dump({**TINY, "grid": grid}, sort_keys=False))
    assert sweep_script.main([str(config), "--root", str(root), "--only", "task=short,seed=0", "--evaluate"]) == 0
    out = capsys.readouterr().out
    counted = "many: 9 run(s) not finished and left out: short: 1 of 5 runs finished; long: 0 of 5 runs finished"
    assert f'{counted} (named in summary.json\'s "unfinished")' in out
    assert "many/gru/long/seed0" not in out
    summary = json.loads((root / "many" / "results" / "summary.json").read_text())
    assert len(summary["unfinished"]) == 9 and "many/gru/long/seed4" in summary["unfinished"]


def test_a_bad_selection_exits_2_and_names_the_valid_values(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    config, root = _config(tmp_path), tmp_path / "runs"
    assert sweep_script.main([str(config), "--root", str(root), "--only", "method=lstm"]) == 2
    assert "no run of cells has method=lstm; valid values: ppo, gru" in capsys.readouterr().err
    assert sweep_script.main([str(config), "--root", str(root), "--only", "seed=5", "--dry-run"]) == 2
    assert "valid values: 0, 1" in capsys.readouterr().err
    assert not root.exists()  # refused before anything was created
    # restating a named axis as a list of its names is refused, and the message points at --only
    assert sweep_script.main([str(config), "--root", str(root), "--dry-run", "--set", "grid.method=[gru]"]) == 2
    assert "select them by name: --only method=NAME" in capsys.readouterr().err


def test_slurm_submits_only_the_selected_runs(tmp_path: Path) -> None:
    pytest.importorskip("submitit")
    config, root = _config(tmp_path), tmp_path / "runs"
    args = [str(config), "--root", str(root), "--launcher", "slurm", "--slurm-cluster", "debug", "--slurm-cpus", "1"]
    # in a process of its own: submitit's debug executor runs the jobs in its caller and rewires its logging there;
    # in the whole suite that left a handler on a closed capture stream, and pytest lost its stderr
    done = subprocess.run(
        [
            sys.executable,
            str(ROOT / "scripts" / "sweep.py"),
            *args,
            "--only",
            "method=gru,seed=1",
            "--only",
            "method=ppo,seed=0",
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr
    submitted = [json.loads(line) for line in (root / "cells" / "slurm" / "submissions.jsonl").read_text().splitlines()]
    assert [entry["run"] for entry in submitted] == ["cells/ppo/pom/seed0", "cells/gru/pom/seed1"]
    assert sorted(str(path.relative_to(root)) for path in root.glob("cells/*/pom/seed*")) == [
        "cells/gru/pom/seed1",
        "cells/ppo/pom/seed0",
    ]  # only the submitted runs were prepared
    assert "submitted job" in done.stdout
