"""scripts/sweep.py under faults, for real: SIGTERM to the local launcher (every running run checkpoints, the sweep
exits 76 and the same command resumes it), two sweeps on one root at once (no run trained twice), and two
evaluations of one panel at once (they take turns)."""

from __future__ import annotations

import csv
import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import yaml

from agents.experiments.launchers import train_run
from agents.experiments.panel import RESULTS_LOCK, evaluate_panel
from agents.experiments.planning import SweepError, load_panel
from agents.experiments.state import FINISHED, prepare_run, run_lock, run_status
from agents.policy.checkpoint import checkpoint_update, latest_checkpoint
from agents.runtime.io import exclusive_lock
from agents.runtime.preemption import EXIT_PREEMPTED
from scripts import sweep as sweep_script
from tests.support.tiny_run import tiny_run, with_run

ROOT = Path(__file__).resolve().parents[2]
TINY = tiny_run(
    {"epochs": 1, "minibatches": 1},
    {
        "total_steps": 3 * 64,
        "torch_threads": 0,  # fixed by the launcher when it creates the run: its share of the cores
        "checkpoint_interval": 0,  # a checkpoint at the end only (and at a pre-emption)
    },
)


def _write(path: Path, seeds: list[int], **run: object) -> Path:
    path.write_text(yaml.safe_dump({**with_run(TINY, **run), "grid": {"run.seed": seeds}}, sort_keys=False))
    return path


def _steps(run_dir: Path) -> list[int]:
    with open(run_dir / "training.csv", newline="") as handle:
        return [int(row["step"]) for row in csv.DictReader(handle)]


def _sweep(config: Path, root: Path, jobs: int) -> subprocess.Popen:
    script = str(ROOT / "scripts" / "sweep.py")
    command = [sys.executable, script, str(config), "--root", str(root), "--jobs", str(jobs)]
    return subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=ROOT)


@pytest.mark.slow
def test_sigterm_to_the_local_launcher_checkpoints_every_running_run(tmp_path: Path) -> None:
    config = _write(tmp_path / "preempt.yaml", [0, 1], total_steps=40 * 64)
    root = tmp_path / "runs"
    runs = load_panel(config, root=root).runs
    sweep = _sweep(config, root, jobs=2)
    try:
        deadline = time.monotonic() + 180
        while not all((run.run_dir / "training.csv").is_file() and _steps(run.run_dir) for run in runs):
            assert sweep.poll() is None and time.monotonic() < deadline, "the runs never started"
            time.sleep(0.05)
        sweep.send_signal(signal.SIGTERM)  # to the launcher only: it passes the signal on
        output, _ = sweep.communicate(timeout=180)
    finally:
        if sweep.poll() is None:
            sweep.kill()
    assert sweep.returncode == EXIT_PREEMPTED, output
    assert "SIGTERM: stopping 2 run(s) at their next checkpoint" in output
    assert output.count("preempted: ") == 2 and "failed" not in output
    for run in runs:
        update = checkpoint_update(latest_checkpoint(run.run_dir))
        assert 1 <= update < 40 and len(_steps(run.run_dir)) == update
        assert f"pre-empted: stopped by SIGTERM after update {update} of 40" in (run.run_dir / "stdout.log").read_text()

    assert sweep_script.main([str(config), "--root", str(root), "--jobs", "2"]) == 0
    for run in runs:
        assert run_status(run).state == FINISHED
        assert _steps(run.run_dir) == [64 * k for k in range(1, 41)]  # nothing lost, nothing twice
        resumed = json.loads((run.run_dir / "run_info.json").read_text())["resumed"]
        assert len(resumed) == 1


@pytest.mark.slow
def test_two_sweeps_on_one_root_never_train_a_run_twice(tmp_path: Path) -> None:
    config = _write(tmp_path / "twice.yaml", [0, 1, 2])
    root = tmp_path / "runs"
    sweeps = [_sweep(config, root, jobs=1), _sweep(config, root, jobs=2)]  # different thread shares
    outputs = [sweep.communicate(timeout=300)[0] for sweep in sweeps]
    assert [sweep.returncode for sweep in sweeps] == [0, 0], outputs
    for run in load_panel(config, root=root).runs:
        assert run_status(run).state == FINISHED
        log = (run.run_dir / "stdout.log").read_text()
        assert log.count("training 3 updates from scratch") == 1, log
        assert "resuming" not in log
        assert _steps(run.run_dir) == [64, 128, 192]
        assert "resumed" not in json.loads((run.run_dir / "run_info.json").read_text())
        threads = yaml.safe_load((run.run_dir / "config.yaml").read_text())["run"]["torch_threads"]
        assert threads >= 1
    assert not [path for path in root.rglob("*.tmp")] and not [path for path in root.rglob("*.new")]


def test_a_busy_run_is_left_alone_and_its_holder_named(tmp_path: Path) -> None:
    (run,) = load_panel(_write(tmp_path / "busy.yaml", [0]), root=tmp_path / "runs").runs
    prepare_run(run)
    said: list[str] = []
    with run_lock(run.run_dir) as held:
        assert held
        assert train_run(run.run_dir, echo=said.append) == "busy"
    assert said == [
        f"{run.run_dir}: another process ({socket.gethostname()} pid {os.getpid()}) is training this run; leaving it"
    ]
    assert not (run.run_dir / "checkpoints").exists()


def test_two_evaluations_of_one_panel_take_turns(tmp_path: Path) -> None:
    """Two sweeps that finish together both evaluate the panel: the second waits for the first's lock and reads the
    runs' states in its turn, so the results it writes last hold every run finished by then."""
    config = tmp_path / "turns.yaml"
    evaluation = {"interval": 3, "seeds": [100_000, 100_002], "repetitions": 1}
    config.write_text(
        yaml.safe_dump(
            {**tiny_run({"epochs": 1, "minibatches": 1}, TINY["run"], evaluation), "grid": {"run.seed": [0, 1]}},
            sort_keys=False,
        )
    )
    panel = load_panel(config, root=tmp_path / "runs")
    with pytest.raises(SweepError, match="turns: no finished run to evaluate \\(2 not finished\\)"):
        evaluate_panel(panel, plots=False, echo=lambda _: None)
    assert not panel.results_dir.exists()  # a refusal leaves nothing behind, not even the lock's file
    first, second = panel.runs
    prepare_run(first)
    assert train_run(first.run_dir, echo=lambda _: None) == "trained"

    waiting = threading.Thread(target=evaluate_panel, args=(panel,), kwargs={"plots": False, "echo": lambda _: None})
    with exclusive_lock(panel.results_dir / RESULTS_LOCK):  # another process evaluating the panel
        waiting.start()
        prepare_run(second)  # a run that finishes while the other evaluation holds the lock
        assert train_run(second.run_dir, echo=lambda _: None) == "trained"
        time.sleep(0.2)
        assert waiting.is_alive() and not (panel.results_dir / "summary.json").exists()
    waiting.join(timeout=120)
    assert not waiting.is_alive()
    summary = json.loads((panel.results_dir / "summary.json").read_text())
    assert summary["unfinished"] == [] and {run["run"] for run in summary["runs"]} == {first.name, second.name}
