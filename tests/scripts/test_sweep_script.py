"""scripts/sweep.py for real on tiny ProofOfMemory runs: a local sweep end to end with --evaluate (one run failing),
a sweep killed in the middle that the second call finishes without touching the finished run, and the SLURM
launcher through submitit's local executor with a pre-emption, a requeue and a resume."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch
import yaml

from agents.evaluation.records import read_records
from agents.experiments.planning import load_panel
from agents.experiments.slurm import wait_for_jobs
from agents.experiments.state import FINISHED, run_status
from agents.policy.checkpoint import checkpoint_update, latest_checkpoint
from scripts import sweep as sweep_script
from tests.support.tiny_run import tiny_run, with_run

ROOT = Path(__file__).resolve().parents[2]
TINY = tiny_run(
    {"epochs": 1, "minibatches": 1},
    {"total_steps": 3 * 64, "torch_threads": 1, "checkpoint_interval": 1, "keep_checkpoints": 1},
    {"interval": 2, "seeds": [100_000, 100_002], "repetitions": 2},
)


def _write(path: Path, grid: dict, base: dict = TINY) -> Path:
    path.write_text(yaml.safe_dump({**base, "grid": grid}, sort_keys=False))
    return path


def _snapshot(run_dir: Path) -> dict[str, tuple[int, str]]:
    """Every file of a run directory: its modification time and a digest of its contents."""
    return {
        str(path.relative_to(run_dir)): (path.stat().st_mtime_ns, hashlib.sha256(path.read_bytes()).hexdigest())
        for path in sorted(run_dir.rglob("*"))
        if path.is_file()
    }


@pytest.mark.slow
@pytest.mark.skipif(torch.cuda.is_available(), reason="the failing run fails for want of CUDA")
def test_local_sweep_end_to_end_with_evaluate(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    grid = {
        "method": {"broken": {"run.device": "cuda"}, "ppo": {"model.memory": "none"}, "gru": {}},  # broken first:
        "task": {"pom": {}},  # it fails while ppo trains, and gru takes its place
        "run.seed": [7],
    }
    config = _write(tmp_path / "two.yaml", grid)
    root = tmp_path / "runs"
    code = sweep_script.main([str(config), "--root", str(root), "--jobs", "2", "--evaluate"])
    out, err = capsys.readouterr()
    assert code == 1  # one run failed; the others trained and were evaluated all the same
    assert "two/broken/pom/seed7" in err and "CUDA" in err and "re-run the same command" in err
    results = root / "two" / "results"
    names = ["two/ppo/pom/seed7", "two/gru/pom/seed7"]
    summary = json.loads((results / "summary.json").read_text())
    assert summary["panel"] == "two" and summary["unfinished"] == ["two/broken/pom/seed7"]
    assert sorted((run["run"], run["step"], run["episodes"]) for run in summary["runs"]) == sorted(
        (name, step, 6) for name in names for step in (128, 192)
    )
    assert {(row["method"], row["task"], row["runs"]) for row in summary["aggregate"] if row["step"] == 192} == {
        ("ppo", "pom", 1),
        ("gru", "pom", 1),
    }
    assert {path.name for path in (results / "plots").iterdir()} >= {"curves.png", "final.png"}
    records = read_records(results / "episodes.csv")
    assert sorted({(r["run"], r["step"]) for r in records}) == sorted((n, s) for n in names for s in (128, 192))
    assert {r["method"] for r in records} == {"ppo", "gru"} and {r["task"] for r in records} == {"pom"}
    training = (results / "training.csv").read_text().splitlines()
    header = "run,method,task,env_id,step,return,length,metric,config_digest"
    assert training[0] == header and len(training) == 1 + 2 * 3
    for name in names:
        run_dir = root.joinpath(*name.split("/"))
        config_saved = yaml.safe_load((run_dir / "config.yaml").read_text())
        assert config_saved["run"]["torch_threads"] == 1 and config_saved["grid"] == {}
        assert [p.name for p in (run_dir / "checkpoints").iterdir()] == ["update_0000003.pt"]  # only the last one
        assert "finished, update 3 of 3" in (run_dir / "stdout.log").read_text()
        # the final evaluation of the last checkpoint equals the in-training one of the same step
        final = read_records(run_dir / "evaluation" / "episodes.csv")
        in_training = [r for r in read_records(run_dir / "eval" / "episodes.csv") if r["step"] == 192]
        assert final == in_training
    assert (root / "two" / "broken" / "pom" / "seed7" / "stdout.log").is_file()
    assert "plots: " in out and "failed" not in out.split("plots: ")[1].splitlines()[0]

    before = {name: _snapshot(root.joinpath(*name.split("/"))) for name in names}
    assert sweep_script.main([str(config), "--root", str(root), "--no-train", "--evaluate"]) == 0  # nothing launched
    assert "two/broken/pom/seed7" in capsys.readouterr().out  # still listed as not finished
    assert {name: _snapshot(root.joinpath(*name.split("/"))) for name in names} == before  # final evaluations reused
    only_ppo = ["--set", "grid.method={ppo: {model.memory: none}}"]  # (the broken run would fail again)
    assert sweep_script.main([str(config), "--root", str(root), *only_ppo]) == 0
    assert "nothing to train" in capsys.readouterr().out
    assert _snapshot(root / "two" / "ppo" / "pom" / "seed7") == before[names[0]]  # a finished run is not touched
    _write(config, grid, {**TINY, "ppo": {"epochs": 2, "minibatches": 1}})  # changed: refused, naming the runs
    assert sweep_script.main([str(config), "--root", str(root), *only_ppo]) == 2
    err = capsys.readouterr().err
    assert "two/ppo/pom/seed7" in err and "ppo.epochs: saved 1, now 2" in err
    assert {name: _snapshot(root.joinpath(*name.split("/"))) for name in names} == before

    # a committed copy of the runs keeps their records, not their checkpoints: they stay finished, are not trained
    # again, and the panel's results come from their final evaluations
    _write(config, grid)
    for name in names:
        shutil.rmtree(root.joinpath(*name.split("/"), "checkpoints"))
    summary_before = json.loads((results / "summary.json").read_text())
    assert sweep_script.main([str(config), "--root", str(root), *only_ppo, "--evaluate"]) == 0
    assert "nothing to train" in capsys.readouterr().out
    assert not (root / "two" / "ppo" / "pom" / "seed7" / "checkpoints").exists()
    summary_after = json.loads((results / "summary.json").read_text())
    assert summary_after["runs"] == [r for r in summary_before["runs"] if r["run"].startswith("two/ppo/")]


@pytest.mark.slow
def test_the_final_evaluation_keeps_and_ignores_a_users_own_evaluations(tmp_path: Path) -> None:
    """scripts/evaluate.py writes into <run>/evaluation by default: the sweep's final evaluation neither mistakes those
    records (other seeds) for its own nor is refused by them, and leaves them in place."""
    from scripts import evaluate as evaluate_script

    config = _write(tmp_path / "one.yaml", {"method": {"gru": {}}, "task": {"pom": {}}, "run.seed": [3]})
    root = tmp_path / "runs"
    assert sweep_script.main([str(config), "--root", str(root)]) == 0
    run_dir = root / "one" / "gru" / "pom" / "seed3"
    assert evaluate_script.main(["--run", str(run_dir), "--seeds", "200000..200001", "--repetitions", "1"]) == 0
    mine = read_records(run_dir / "evaluation" / "episodes.csv")
    assert {(r["step"], r["seed"]) for r in mine} == {(192, 200_000), (192, 200_001)}
    assert sweep_script.main([str(config), "--root", str(root), "--no-train", "--evaluate"]) == 0
    panel = read_records(root / "one" / "results" / "episodes.csv")
    final = sorted((r["seed"], r["repetition"]) for r in panel if r["step"] == 192)
    assert final == [(seed, rep) for seed in (100_000, 100_001, 100_002) for rep in (0, 1)]
    kept = read_records(run_dir / "evaluation" / "episodes.csv")
    assert [r for r in kept if r["seed"] >= 200_000] == mine


@pytest.mark.slow
def test_a_killed_sweep_finishes_on_the_second_call(tmp_path: Path) -> None:
    grid = {"method": {"short": {"model.memory": "none"}, "long": {"run.total_steps": 30 * 64}}, "run.seed": [0]}
    config = _write(tmp_path / "kill.yaml", grid)
    root = tmp_path / "runs"
    panel = load_panel(config, root=root)
    short, long = panel.runs
    command = [sys.executable, str(ROOT / "scripts" / "sweep.py"), str(config), "--root", str(root), "--jobs", "2"]
    sweep = subprocess.Popen(command, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        while True:  # until the short run is finished and the long one has a checkpoint but is not finished
            latest = latest_checkpoint(long.run_dir) if long.run_dir.is_dir() else None
            short_done = short.run_dir.is_dir() and run_status(short).state == FINISHED
            if short_done and latest is not None and checkpoint_update(latest) < long.config.num_updates:
                break
            assert sweep.poll() is None and time.monotonic() < deadline, "the long run was not caught in the middle"
            time.sleep(0.02)
    finally:
        os.killpg(sweep.pid, signal.SIGKILL)  # the sweep and the run it trains die at once, as in a crash
        sweep.wait()
    assert run_status(short).state == FINISHED and run_status(long).update < long.config.num_updates
    before = _snapshot(short.run_dir)

    assert sweep_script.main([str(config), "--root", str(root)]) == 0
    assert _snapshot(short.run_dir) == before  # the finished run is untouched
    assert run_status(long).state == FINISHED
    resumed = json.loads((long.run_dir / "run_info.json").read_text())["resumed"]
    assert len(resumed) == 1 and 1 <= resumed[0]["update"] < long.config.num_updates
    steps = [int(line.split(",")[4]) for line in (long.run_dir / "training.csv").read_text().splitlines()[1:]]
    assert steps == [64 * k for k in range(1, 31)]  # one row per update: nothing lost, nothing twice
    log = (long.run_dir / "stdout.log").read_text()
    assert "training 30 updates from scratch" in log and f"resuming from update {resumed[0]['update']}" in log


def _task_processes(controller: int) -> list[int]:
    return [int(pid) for pid in Path(f"/proc/{controller}/task/{controller}/children").read_text().split()]


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="finds the job's process through /proc")
def test_slurm_launcher_through_submitit_requeues_and_resumes(tmp_path: Path) -> None:
    pytest.importorskip("submitit")
    from agents.experiments.slurm import launch_slurm

    grid = {"method": {"gru": {}}, "run.seed": [0], "slurm": {"time": "5", "cpus_per_job": 1}}
    config = _write(tmp_path / "cluster.yaml", grid, with_run(TINY, total_steps=24 * 64))
    panel = load_panel(config, root=tmp_path / "runs")
    ((run, job),) = launch_slurm(panel, cluster="local", echo=lambda _: None)
    deadline = time.monotonic() + 120
    while latest_checkpoint(run.run_dir) is None:
        assert not job.done() and time.monotonic() < deadline
        time.sleep(0.02)
    for task in _task_processes(int(job.job_id)):  # the local job's id is its controller's process id
        os.kill(task, signal.SIGUSR2)  # what SLURM sends before a pre-emption or the time limit
    (outcome,) = wait_for_jobs([(run, job)], echo=lambda _: None, poll_s=0.1)
    assert outcome.result == "ok", outcome.detail
    assert run_status(run).state == FINISHED
    resumed = json.loads((run.run_dir / "run_info.json").read_text())["resumed"]
    assert len(resumed) == 1 and resumed[0]["update"] >= 1
    log = "".join(path.read_text() for path in panel.slurm_dir.glob("*_log.*"))
    assert "Calling checkpoint method" in log and "Requeued job" in log
    assert yaml.safe_load((run.run_dir / "config.yaml").read_text())["run"]["torch_threads"] == 1
    submitted = [json.loads(line) for line in (panel.slurm_dir / "submissions.jsonl").read_text().splitlines()]
    assert [(entry["run"], entry["job"]) for entry in submitted] == [(run.name, str(job.job_id))]
    assert launch_slurm(panel, cluster="local", echo=lambda _: None) == []  # nothing left to submit
