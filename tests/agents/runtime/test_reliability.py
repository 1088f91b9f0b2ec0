"""What survives a fault: kills at every stage of a checkpoint write, pre-emption signals, truncated and corrupted
checkpoints and records, a full disk, a failing fsync, NaN/Inf in the loss or the weights, and two evaluations
writing into one directory. Faults are injected through MEMGYM_FAULT (agents/runtime/faults.py), into real runs; a
resumed run must end bit for bit as an uninterrupted one."""

from __future__ import annotations

import csv
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import torch
import yaml

from agents.cli.results_table import run_minutes
from agents.config import config_from_dict
from agents.evaluation import runs as evaluation_runs
from agents.evaluation.records import read_records
from agents.evaluation.runs import evaluate_runs
from agents.policy.checkpoint import DamagedCheckpoint, latest_checkpoint, read_checkpoint, write_checkpoint
from agents.runtime import faults
from agents.runtime.faults import FaultSpecError, parse_faults
from agents.runtime.preemption import EXIT_PREEMPTED, Preempted, deferred_signals, raising_preempted
from agents.training.logs import training_log_text
from agents.training.trainer import Trainer, TrainingDiverged, WriteFailed
from scripts import train as train_script
from tests.support.interrupt import kill_after
from tests.support.tiny_run import tiny_run, with_run

ROOT = Path(__file__).resolve().parents[3]
TINY = tiny_run(
    {"epochs": 2, "minibatches": 2},
    {"total_steps": 6 * 64, "seed": 3, "torch_threads": 1, "checkpoint_interval": 2},  # 6 updates
    {"interval": 3, "seeds": [100_000, 100_002], "repetitions": 2},
)


@pytest.fixture(autouse=True)
def _fresh_fault_counts(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(faults.ENV_VARIABLE, raising=False)
    faults.reset()


def _config(**run: object):
    return config_from_dict(with_run(TINY, **run))


def _config_file(tmp_path: Path, **run: object) -> Path:
    """The tiny run's config as a YAML file in ``tmp_path``."""
    config_path = tmp_path / "tiny.yaml"
    config_path.write_text(yaml.safe_dump(with_run(TINY, **run)))
    return config_path


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The reference: the tiny run trained without a fault (its directory is named ``run``, as every other)."""
    run_dir = tmp_path_factory.mktemp("uninterrupted") / "run"
    Trainer(_config(), run_dir).train()
    return run_dir


def _assert_same_run(expected: Path, found: Path) -> None:
    """Bit for bit: the last checkpoint's weights and optimizer state, training.csv and the evaluation records."""
    a, b = read_checkpoint(latest_checkpoint(expected)), read_checkpoint(latest_checkpoint(found))
    assert a["update"] == b["update"]
    for name, tensor in a["model"].items():
        assert torch.equal(tensor, b["model"][name]), name
    for key, state in a["optimizer"]["state"].items():
        for name, value in state.items():
            assert torch.equal(value, b["optimizer"]["state"][key][name]), (key, name)
    assert (expected / "training.csv").read_text() == (found / "training.csv").read_text()
    assert (expected / "eval" / "episodes.csv").read_text() == (found / "eval" / "episodes.csv").read_text()


def _no_debris(run_dir: Path) -> None:
    assert not [path for path in run_dir.rglob("*.tmp")], "a temporary file of a failed write was left behind"


# ------------------------------------------------------------------------------------------------ the spec
@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ("write:*.pt:1:fsync:explode", "action 'explode' is invalid; valid: kill, enospc, eio, sigterm, sigusr2"),
        ("write:*.pt:1:middle:kill", "stage 'middle' is invalid; valid: open, data, fsync, rename, done"),
        ("write:*.pt:0:data:kill", "'0' is invalid; expected a whole number >= 1"),
        ("update:2:weights:nan", "target 'weights' is invalid; valid: loss, params"),
        ("update:2:loss:zero", "value 'zero' is invalid; valid: nan, inf"),
        ("signal:2:SIGHUP", "signal 'SIGHUP' is invalid; valid: SIGTERM, SIGUSR2, SIGINT, SIGKILL"),
        ("crash:now", "'crash:now' is not a fault; expected write:"),
    ],
)
def test_a_bad_fault_spec_names_the_part_and_the_choices(spec: str, message: str) -> None:
    with pytest.raises(FaultSpecError, match="MEMGYM_FAULT") as caught:
        parse_faults(spec)
    assert message in str(caught.value)


def test_a_bad_fault_spec_stops_the_scripts_before_any_work(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture
) -> None:
    config_path = _config_file(tmp_path)
    monkeypatch.setenv(faults.ENV_VARIABLE, "write:*.pt:1:fsync:explode")
    assert train_script.main(["--config", str(config_path), "--run-dir", str(tmp_path / "run")]) == 2
    assert "error: MEMGYM_FAULT: 'write:*.pt:1:fsync:explode': action 'explode' is invalid" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


def test_fault_specs_parse() -> None:
    found = parse_faults(" write:update_*.pt:2:fsync:eio ; update:3:params:inf;signal:4:SIGUSR2 ")
    assert [(f.site, f.count, f.pattern, f.stage, f.action) for f in found] == [
        ("write", 2, "update_*.pt", "fsync", "eio"),
        ("update", 3, "", "params", "inf"),
        ("signal", 4, "", "", "SIGUSR2"),
    ]
    assert parse_faults("") == []


# ------------------------------------------------------------------------------------ damaged checkpoints
def test_a_checkpoint_truncated_or_corrupted_anywhere_is_never_loaded(tmp_path: Path) -> None:
    path = write_checkpoint(tmp_path / "update_0000001.pt", {"weights": torch.arange(5000.0), "update": 1})
    data = path.read_bytes()
    assert read_checkpoint(path)["update"] == 1
    damaged = tmp_path / "damaged.pt"
    rng = random.Random(0)
    for length in [0, 5, 19, 25, len(data) - 1, *rng.sample(range(len(data)), 30)]:
        damaged.write_bytes(data[:length])
        with pytest.raises(DamagedCheckpoint, match="damaged.pt"):
            read_checkpoint(damaged)
    for position in rng.sample(range(len(data)), 30):  # one flipped byte, in the header or the payload
        damaged.write_bytes(data[:position] + bytes([data[position] ^ 0xFF]) + data[position + 1 :])
        with pytest.raises(DamagedCheckpoint, match="damaged.pt"):
            read_checkpoint(damaged)


def _killed_after(config, run_dir: Path, updates: int) -> None:
    """Train until ``updates`` updates are done, then die as a killed process would (no checkpoint of its own)."""
    trainer = Trainer(config, run_dir)
    kill_after(trainer, updates)
    with pytest.raises(KeyboardInterrupt):
        trainer.train()


def test_resume_falls_back_to_the_newest_intact_checkpoint_and_says_so(tmp_path: Path, uninterrupted: Path) -> None:
    run_dir = tmp_path / "run"
    _killed_after(_config(), run_dir, 5)  # checkpoints at updates 2 and 4
    newest = run_dir / "checkpoints" / "update_0000004.pt"
    newest.write_bytes(newest.read_bytes()[:-100])
    resumed = Trainer.resume(run_dir)
    assert resumed.update == 2
    assert (
        "update_0000004.pt is damaged" in resumed.resume_notes[0]
        and "moved to update_0000004.pt.damaged" in (resumed.resume_notes[0])
    )
    assert resumed.resume_notes[-1] == "resuming from update_0000002.pt"
    resumed.train()
    _assert_same_run(uninterrupted, run_dir)


def test_a_finished_run_whose_last_checkpoint_is_damaged_is_not_taken_as_finished(
    tmp_path: Path, uninterrupted: Path, capsys: pytest.CaptureFixture
) -> None:
    run_dir = tmp_path / "run"
    shutil.copytree(uninterrupted, run_dir)
    last = run_dir / "checkpoints" / "update_0000006.pt"
    last.write_bytes(last.read_bytes()[:1000])
    assert train_script.main(["--resume", str(run_dir)]) == 0
    error = capsys.readouterr().err
    assert (
        "warning: " in error and "update_0000006.pt is damaged" in error and "resuming from update_0000004.pt" in error
    )
    _assert_same_run(uninterrupted, run_dir)


def test_resume_refuses_when_no_checkpoint_is_intact(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    run_dir = tmp_path / "run"
    _killed_after(_config(), run_dir, 5)
    for path in (run_dir / "checkpoints").glob("*.pt"):
        path.write_bytes(path.read_bytes()[: len(path.read_bytes()) // 2])
    assert train_script.main(["--resume", str(run_dir)]) == 2
    error = capsys.readouterr().err
    assert "no intact checkpoint to resume from" in error
    assert "update_0000002.pt is damaged" in error and "update_0000004.pt is damaged" in error


def test_a_truncated_training_log_is_never_continued(tmp_path: Path) -> None:
    """training.csv cut at random lengths: resume continues from the newest checkpoint whose rows are all still
    there (falling back past the others), or refuses naming the file; a garbled row is refused too."""
    killed = tmp_path / "killed" / "run"
    _killed_after(_config(), killed, 5)
    text = (killed / "training.csv").read_text()
    needed = {update: len(training_log_text(killed / "training.csv", 64 * update)) for update in (2, 4)}
    rng = random.Random(1)
    for length in sorted({*rng.sample(range(len(text)), 8), needed[2] - 1, needed[4] - 1, needed[4]}):
        run_dir = tmp_path / f"cut{length}" / "run"
        shutil.copytree(killed, run_dir)
        (run_dir / "training.csv").write_text(text[:length])
        usable = [update for update in (4, 2) if length >= needed[update]]
        if not usable:
            with pytest.raises(DamagedCheckpoint, match="training.csv"):
                Trainer.resume(run_dir)
            continue
        resumed = Trainer.resume(run_dir)
        assert resumed.update == usable[0], length
        if usable[0] == 2:
            assert "training.csv" in resumed.resume_notes[0]
    garbled = tmp_path / "garbled" / "run"
    shutil.copytree(killed, garbled)
    (garbled / "training.csv").write_text(text.replace(",128,", ",129,"))
    with pytest.raises(DamagedCheckpoint, match="training.csv"):
        Trainer.resume(garbled)


def test_corrupted_evaluation_records_of_a_run_are_never_continued(tmp_path: Path, uninterrupted: Path) -> None:
    """Records of the evaluation at update 3 cut short: checkpoint 4 (which holds them) is passed over for
    checkpoint 2 (which holds none), and the resumed run evaluates again."""
    run_dir = tmp_path / "run"
    _killed_after(_config(), run_dir, 5)  # evaluated at update 3, checkpointed at 2 and 4
    records = run_dir / "eval" / "episodes.csv"
    records.write_text(records.read_text()[:-30])
    resumed = Trainer.resume(run_dir)
    assert resumed.update == 2 and "eval/episodes.csv does not hold what it recorded" in resumed.resume_notes[0]
    resumed.train()
    _assert_same_run(uninterrupted, run_dir)


# ------------------------------------------------------------------------------ full disk, failing fsync
@pytest.mark.parametrize(
    ("fault", "reason"), [("data:enospc", "No space left on device"), ("fsync:eio", "Input/output error")]
)
def test_a_failed_checkpoint_write_keeps_the_previous_checkpoint_and_stops_clearly(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, uninterrupted: Path, fault: str, reason: str
) -> None:
    run_dir = tmp_path / "run"
    monkeypatch.setenv(faults.ENV_VARIABLE, f"write:update_*.pt:2:{fault}")
    with pytest.raises(WriteFailed) as caught:
        Trainer(_config(), run_dir).train()
    message = str(caught.value)
    assert f"writing {run_dir / 'checkpoints' / 'update_0000004.pt'} failed" in message and reason in message
    assert "last good checkpoint is" in message and "update_0000002.pt" in message and "--resume" in message
    assert [path.name for path in (run_dir / "checkpoints").iterdir()] == ["update_0000002.pt"]
    _no_debris(run_dir)
    monkeypatch.delenv(faults.ENV_VARIABLE)
    resumed = Trainer.resume(run_dir)
    assert resumed.update == 2
    resumed.train()
    _assert_same_run(uninterrupted, run_dir)


def test_train_script_reports_a_full_disk_without_a_traceback(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture
) -> None:
    config_path = _config_file(tmp_path)
    monkeypatch.setenv(faults.ENV_VARIABLE, "write:episodes.csv:1:rename:enospc")
    assert train_script.main(["--config", str(config_path), "--run-dir", str(tmp_path / "run")]) == 1
    error = capsys.readouterr().err
    assert error.startswith("error: training stopped at update 3: writing ") and "episodes.csv failed" in error
    assert "No space left on device" in error and "Traceback" not in error


# -------------------------------------------------------------------------------------------- NaN and Inf
@pytest.mark.parametrize(
    ("fault", "message"),
    [
        (
            "update:3:params:nan",
            r"update 3: non-finite parameters after its optimizer steps \(image_encoder\.convs\.0\.weight\)",
        ),
        ("update:3:params:inf", r"update 3: non-finite parameters"),
        ("update:3:loss:nan", r"update 3: non-finite loss"),
        ("update:3:loss:inf", r"update 3: non-finite loss"),
    ],
)
def test_a_non_finite_loss_or_weight_stops_at_its_update_with_the_last_good_checkpoint(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, fault: str, message: str
) -> None:
    """A NaN that the last optimizer step puts into a weight used to pass and crash the next rollout's sampling."""
    monkeypatch.setenv(faults.ENV_VARIABLE, fault)
    trainer = Trainer(_config(), tmp_path / "run")
    with pytest.raises(TrainingDiverged, match=message + r".*last good checkpoint is .*update_0000002\.pt"):
        trainer.train()
    assert trainer.update == 2  # stopped inside update 3: nothing of it counted, and no checkpoint after it
    assert [path.name for path in (tmp_path / "run" / "checkpoints").iterdir()] == ["update_0000002.pt"]
    state = read_checkpoint(tmp_path / "run" / "checkpoints" / "update_0000002.pt")
    assert all(torch.isfinite(tensor).all() for tensor in state["model"].values())


# ----------------------------------------------------------------------------------- real kills, signals
def _train_command(tmp_path: Path, run_dir: Path, **run: object) -> list[str]:
    config_path = _config_file(tmp_path, **run)
    return [sys.executable, str(ROOT / "scripts" / "train.py"), "--config", str(config_path), "--run-dir", str(run_dir)]


def _run(command: list[str], fault: str = "") -> subprocess.CompletedProcess:
    env = {**os.environ, faults.ENV_VARIABLE: fault}
    return subprocess.run(command, env=env, capture_output=True, text=True, timeout=300, cwd=ROOT)


@pytest.mark.parametrize(
    "fault",
    [
        *(f"write:update_*.pt:2:{stage}:kill" for stage in faults.WRITE_STAGES),
        "write:episodes.csv:1:data:kill",
        "write:training.csv:1:rename:kill",
    ],
)
@pytest.mark.slow
def test_a_run_killed_at_any_stage_of_a_write_resumes_bit_for_bit(tmp_path: Path, uninterrupted: Path, fault: str):
    run_dir = tmp_path / "run"
    killed = _run(_train_command(tmp_path, run_dir), fault)
    assert killed.returncode == -signal.SIGKILL, killed.stderr
    if latest_checkpoint(run_dir) is None:  # killed before the first checkpoint: a new attempt starts over
        shutil.rmtree(run_dir)
        Trainer(_config(), run_dir).train()
    else:
        Trainer.resume(run_dir).train()
    _assert_same_run(uninterrupted, run_dir)
    assert not [path for path in (run_dir / "checkpoints").iterdir() if path.suffix == ".damaged"]


@pytest.mark.slow
@pytest.mark.parametrize("name", ["SIGTERM", "SIGUSR2"])
def test_a_preempted_run_checkpoints_exits_76_and_resumes_bit_for_bit(
    tmp_path: Path, uninterrupted: Path, name: str
) -> None:
    run_dir = tmp_path / "run"
    stopped = _run(_train_command(tmp_path, run_dir), f"signal:3:{name}")
    assert stopped.returncode == EXIT_PREEMPTED == 76, stopped.stderr
    assert f"pre-empted: stopped by {name} after update 3 of 6" in stopped.stderr
    assert latest_checkpoint(run_dir).name == "update_0000003.pt"  # the update in progress finished, then saved
    (stop,) = json.loads((run_dir / "run_info.json").read_text())["stopped"]  # the committed records' stop time
    assert (stop["update"], stop["signal"]) == (3, name)
    Trainer.resume(run_dir).train()
    _assert_same_run(uninterrupted, run_dir)
    timed = run_minutes(run_dir)
    assert timed is not None and timed.resumed and not timed.estimated


@pytest.mark.slow
def test_a_signal_in_the_middle_of_a_checkpoint_write_stops_after_it(tmp_path: Path, uninterrupted: Path) -> None:
    run_dir = tmp_path / "run"
    stopped = _run(_train_command(tmp_path, run_dir), "write:update_*.pt:2:data:sigterm")
    assert stopped.returncode == EXIT_PREEMPTED, stopped.stderr
    assert "stopped by SIGTERM after update 4 of 6" in stopped.stderr
    names = sorted(path.name for path in (run_dir / "checkpoints").iterdir())
    assert names == ["update_0000002.pt", "update_0000004.pt"]
    Trainer.resume(run_dir).train()
    _assert_same_run(uninterrupted, run_dir)


@pytest.mark.slow
def test_sigterm_from_outside_stops_at_the_next_update(tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    command = _train_command(tmp_path, run_dir, total_steps=40 * 64, checkpoint_interval=0)
    process = subprocess.Popen(command, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True, cwd=ROOT)
    try:
        deadline = time.monotonic() + 120
        while not (run_dir / "training.csv").is_file() or len(_rows(run_dir / "training.csv")) < 2:
            assert process.poll() is None and time.monotonic() < deadline
            time.sleep(0.02)
        process.send_signal(signal.SIGTERM)
        _, error = process.communicate(timeout=120)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == EXIT_PREEMPTED, error
    update = int(error.split("after update ")[1].split(" ")[0])
    assert 2 <= update < 40
    assert latest_checkpoint(run_dir).name == f"update_{update:07d}.pt"
    assert len(_rows(run_dir / "training.csv")) == update


def _rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))


def test_deferred_signals_wait_until_the_block_is_done() -> None:
    events = []
    with pytest.raises(Preempted, match="work stopped by SIGUSR2"), raising_preempted("work"):
        with deferred_signals():
            os.kill(os.getpid(), signal.SIGUSR2)
            time.sleep(0.05)
            events.append("written")
        time.sleep(1)  # never reached: the signal is raised as the block ends
        events.append("after")
    assert events == ["written"]


# ------------------------------------------------------------------------------------ evaluation --out
@pytest.fixture(scope="module")
def two_runs(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    base = tmp_path_factory.mktemp("two_runs")
    runs = []
    for seed in (0, 1):
        run_dir = base / f"seed{seed}"
        Trainer(_config(seed=seed, total_steps=2 * 64), run_dir).train()
        runs.append(run_dir)
    return runs


def _evaluate_command(run_dir: Path, out: Path) -> list[str]:
    return [sys.executable, str(ROOT / "scripts" / "evaluate.py"), "--run", str(run_dir), "--out", str(out)]


@pytest.mark.slow
@pytest.mark.parametrize(("write", "runs"), [(1, {"seed0"}), (2, {"seed0", "seed1"})])
def test_a_preempted_evaluation_leaves_its_files_whole_and_together(
    tmp_path: Path, two_runs: list[Path], write: int, runs: set[str]
) -> None:
    """SIGTERM while the merged records are checked (the 1st episodes.csv written, in a scratch directory) stops
    the evaluation before out is touched; while out's episodes.csv is half written (the 2nd), it is held back until
    summary.json is written too."""
    out = tmp_path / "out"
    evaluate_runs([two_runs[0]], out)
    stopped = _run(_evaluate_command(two_runs[1], out), f"write:episodes.csv:{write}:data:sigterm")
    assert stopped.returncode == EXIT_PREEMPTED, stopped.stderr
    assert "pre-empted: evaluation stopped by SIGTERM" in stopped.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert {entry["run"] for entry in summary["run_directories"]} == runs
    evaluation_runs._existing(out)  # every file is what summary.json recorded
    assert {record["run"] for record in read_records(out / "episodes.csv")} == runs


@pytest.mark.slow
def test_an_evaluation_killed_between_its_writes_is_refused_by_name(tmp_path: Path, two_runs: list[Path]) -> None:
    out = tmp_path / "out"
    evaluate_runs([two_runs[0]], out)
    before = (out / "summary.json").read_text()
    killed = _run(_evaluate_command(two_runs[1], out), "write:summary.json:1:rename:kill")
    assert killed.returncode == -signal.SIGKILL, killed.stderr
    assert (out / "summary.json").read_text() == before  # episodes.csv was replaced, summary.json not
    with pytest.raises(ValueError, match=r"episodes.csv is not what summary.json recorded.*killed between"):
        evaluate_runs([two_runs[1]], out, force=True)


def test_two_evaluations_into_one_directory_at_once_keep_every_record(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, two_runs: list[Path]
) -> None:
    """Both evaluations read the (empty) directory before either writes: the second to write merges into what the
    first wrote instead of replacing it."""
    both_read = threading.Barrier(2, timeout=60)
    play = evaluation_runs.evaluate

    def evaluate_after_both_read(*args, **kwargs):
        both_read.wait()
        return play(*args, **kwargs)

    monkeypatch.setattr(evaluation_runs, "evaluate", evaluate_after_both_read)
    out = tmp_path / "out"
    errors: list[BaseException] = []

    def evaluate_one(run_dir: Path) -> None:
        try:
            evaluate_runs([run_dir], out)
        except BaseException as err:  # noqa: BLE001 (reported by the test below)
            errors.append(err)

    threads = [threading.Thread(target=evaluate_one, args=(run_dir,)) for run_dir in two_runs]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert not errors, errors
    records = read_records(out / "episodes.csv")
    assert sorted({record["run"] for record in records}) == ["seed0", "seed1"]
    assert len(records) == 2 * 3 * 2
    summary = json.loads((out / "summary.json").read_text())
    assert {entry["run"] for entry in summary["run_directories"]} == {"seed0", "seed1"}


def test_truncated_or_corrupted_evaluation_files_are_refused_by_name(tmp_path: Path, two_runs: list[Path]) -> None:
    out = tmp_path / "out"
    evaluate_runs([two_runs[0]], out)
    intact = {name: (out / name).read_bytes() for name in ("episodes.csv", "training.csv", "summary.json")}
    rng = random.Random(2)
    for name, data in intact.items():
        for length in rng.sample(range(len(data) - 1), 5):  # without its last newline, JSON would still be whole
            (out / name).write_bytes(data[:length])
            with pytest.raises(ValueError, match=name):
                evaluate_runs([two_runs[1]], out)
            (out / name).write_bytes(data)
    episodes = intact["episodes.csv"]
    (out / "episodes.csv").write_bytes(episodes.replace(b",100001,", b",100002,", 1))
    with pytest.raises(ValueError, match=r"episodes.csv is not what summary.json recorded"):
        evaluate_runs([two_runs[1]], out)
    (out / "episodes.csv").write_bytes(episodes)
    evaluate_runs([two_runs[1]], out)  # intact again: merged
    assert {record["run"] for record in read_records(out / "episodes.csv")} == {"seed0", "seed1"}
