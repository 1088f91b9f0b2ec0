"""scripts/results_table.py: the README's table of a panel (final IQMs per method and task, the aggregate) and the
runs' wall times, read from summary.json and the run directories."""

from __future__ import annotations

import json
from datetime import datetime
from pathlib import Path

from agents.cli.results_table import run_minutes
from scripts import results_table


def _entry(method: str, task: str, step: int, iqm: float, runs: int = 2) -> dict:
    return {"method": method, "task": task, "step": step, "iqm": iqm, "low": iqm - 0.1, "high": iqm + 0.1, "runs": runs}


def _run(root: Path, method: str, task: str, seed: int, minutes: int, resumed: bool = False) -> dict:
    """A finished run of ``minutes`` and 15 updates; resumed: its first process made 5 updates and logged events
    until minute 8, stopped, and a second started at minute 30 (a pause of 22 minutes that the table leaves out)."""
    run = root / "suite" / method / task / f"seed{seed}"
    run.mkdir(parents=True)
    info = {"time": _at(0)}
    if resumed:
        info["resumed"] = [{"time": _at(30), "update": 5}]
        _log_events(run, [_at(5), _at(8)])
    info["finished"] = {"time": _at(minutes + 22 * resumed), "update": 15}
    (run / "run_info.json").write_text(json.dumps(info))
    env_id = {"cue": "ProofOfMemory-v0", "emp": "Endless-MysteryPath-v0"}[task]
    return {"run": f"suite/{method}/{task}/seed{seed}", "method": method, "task": task, "env_id": env_id}


def _at(minute: int) -> str:
    return f"2026-11-29T00:{minute:02d}:00+00:00"


def _log_events(run_dir: Path, times: list[str]) -> None:
    from torch.utils.tensorboard import SummaryWriter

    writer = SummaryWriter(log_dir=str(run_dir))
    for step, time in enumerate(times):
        writer.add_scalar("charts/episodic_return", 0.5, step, walltime=datetime.fromisoformat(time).timestamp())
    writer.close()


def test_a_resumed_runs_minutes_leave_out_its_pauses(tmp_path: Path) -> None:
    _run(tmp_path, "gru", "cue", 0, 20, resumed=True)
    assert run_minutes(tmp_path / "suite/gru/cue/seed0") == (20.0, True, False)
    run = tmp_path / "suite/gru/cue/seed1"  # stopped before it logged anything: its first process counts nothing
    run.mkdir(parents=True)
    info = {"time": _at(0), "resumed": [{"time": _at(30)}], "finished": {"time": _at(45)}}
    (run / "run_info.json").write_text(json.dumps(info))
    assert run_minutes(run) == (15.0, True, False)
    del info["finished"]
    (run / "run_info.json").write_text(json.dumps(info))
    assert run_minutes(run) is None


def test_a_recorded_stop_ends_a_process_and_without_one_its_updates_are_counted_at_the_runs_pace(
    tmp_path: Path,
) -> None:
    run = tmp_path / "suite/gru/cue/seed0"
    run.mkdir(parents=True)
    # 10 updates in a first process, stopped at minute 6 (an event at minute 9 is a later, killed process's), resumed
    # at minute 30, 20 more updates to minute 42: 6 + 12 minutes; without the stop time, 10 updates at 0.6 a minute
    info = {"time": _at(0), "resumed": [{"time": _at(30), "update": 10}], "finished": {"time": _at(42), "update": 30}}
    (run / "run_info.json").write_text(json.dumps(info | {"stopped": [{"time": _at(6), "update": 10}]}))
    _log_events(run, [_at(5), _at(9)])
    assert run_minutes(run) == (18.0, True, False)
    (run / "run_info.json").write_text(json.dumps(info))
    assert run_minutes(run) == (21.0, True, False)  # the last event ends it
    for path in run.glob("events.out.tfevents.*"):
        path.unlink()  # what a fresh clone of committed records holds
    assert run_minutes(run) == (18.0, True, True)


def test_a_stop_in_the_second_the_next_process_started_ends_the_earlier_process(tmp_path: Path) -> None:
    """run_info.json's times are whole seconds: a run stopped and resumed at once records both at the same second."""
    run = tmp_path / "suite/gru/cue/seed0"
    run.mkdir(parents=True)
    info = {
        "time": _at(0),
        "stopped": [{"time": _at(6), "update": 10}, {"time": _at(9), "update": 15}],
        "resumed": [{"time": _at(6), "update": 10}, {"time": _at(9), "update": 15}],  # each at its stop's second
        "finished": {"time": _at(21), "update": 30},
    }
    (run / "run_info.json").write_text(json.dumps(info))
    assert run_minutes(run) == (6.0 + 3.0 + 12.0, True, False)  # nothing estimated: every stop is recorded


def test_the_table_has_a_row_per_method_a_column_per_task_and_the_aggregate(tmp_path: Path, capsys) -> None:
    runs = [_run(tmp_path, "ppo", task, seed, 10 + seed) for task in ("cue", "emp") for seed in (0, 1)]
    runs += runs[:1]  # a run is listed once per evaluated step
    runs += [_run(tmp_path, "gru", "cue", 0, 20, resumed=True), _run(tmp_path, "gru", "cue", 1, 20)]
    runs += [_run(tmp_path, "gru", "emp", 0, 40)]
    aggregate = [_entry("ppo", "cue", 100, 0.1), _entry("ppo", "cue", 200, 0.5), _entry("ppo", "emp", 200, 2.25)]
    aggregate += [_entry("gru", "cue", 200, 0.9), _entry("gru", "emp", 200, 3.0, runs=1)]
    aggregate += [_entry("ppo", "all", 200, 1.0, runs=4)]  # a method's tasks pooled: no column of its own
    methods = {
        "ppo": {"iqm": [0.2, 0.1, 0.3], "improvement_over_gru": [0.25, 0.0, 0.5]},
        "gru": {"iqm": [0.8, 0.7, 0.9]},
    }
    summary = {"runs": runs, "aggregate": aggregate, "across_tasks": {"reference": "gru", "methods": methods}}
    results = tmp_path / "suite" / "results"
    results.mkdir()
    (results / "summary.json").write_text(json.dumps(summary))
    assert results_table.main([str(results), "--out", str(tmp_path / "table.md")]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == (
        "| method | cue (success) | emp (tiles visited) | across tasks: IQM (normalised) | P(better than GRU-PPO) |"
    )
    assert lines[2] == "| PPO | 0.50 [0.40, 0.60] | 2.25 [2.15, 2.35] | 0.20 [0.10, 0.30] | 0.25 [0.00, 0.50] |"
    assert lines[3] == "| GRU-PPO | 0.90 [0.80, 1.00] | 3.00 [2.90, 3.10] (1 run) | 0.80 [0.70, 0.90] |  |"
    assert "| PPO | 10-11 (2) | 10-11 (2) |" in lines and "| GRU-PPO | 20 (2), 1 resumed | 40 (1) |" in lines
    assert (
        lines[-1] == "Minutes per run, start to finish less the pauses of resumed runs (runs). All runs: 2.0 run-hours."
    )
    assert (tmp_path / "table.md").read_text().splitlines() == lines
    for path in (tmp_path / "suite/gru/cue/seed0").glob("events.out.tfevents.*"):
        path.unlink()  # its first process's end now known from nothing: counted at the run's pace, and said so
    assert results_table.main([str(results)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert "| GRU-PPO | 18-20 (2), 1 resumed (1 estimated) | 40 (1) |" in lines  # 5 updates at 12 minutes per 10
    assert lines[-1].startswith("Estimated: a resumed run one of whose processes left no stop time")
    assert results_table.main([str(tmp_path / "none")]) == 2


def test_the_aggregate_column_names_its_tasks_while_one_is_in_progress(tmp_path: Path, capsys) -> None:
    runs = [_run(tmp_path, method, task, 0, 10) for method in ("ppo", "gru") for task in ("cue", "emp")]
    aggregate = [_entry(method, task, 200, 0.5, runs=1) for method in ("ppo", "gru") for task in ("cue", "emp")]
    spanning = {"reference": "gru", "methods": {"gru": {"iqm": [0.8, 0.7, 0.9]}}, "tasks": ["cue"]}
    spanning["tasks_in_progress"] = {"emp": "1 of 3 runs finished"}
    results = tmp_path / "suite" / "results"
    results.mkdir()
    (results / "summary.json").write_text(json.dumps({"runs": runs, "aggregate": aggregate, "across_tasks": spanning}))
    assert results_table.main([str(results)]) == 0
    assert "| across cue: IQM (normalised) |" in capsys.readouterr().out.splitlines()[0]
