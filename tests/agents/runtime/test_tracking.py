"""Weights & Biases logging (run.wandb): the TensorBoard scalars, the config and git revision, one W&B run per run
directory that a resume continues; off by default. A fake wandb module records the calls; W&B's offline mode runs
for real where wandb is installed."""

from __future__ import annotations

import json
import re
import sys
import types
from pathlib import Path
from typing import Any

import pytest
import yaml
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from agents.config import ConfigError, config_from_dict, config_to_dict
from agents.policy.checkpoint import check_checkpoint_config
from agents.runtime.io import git_revision
from agents.training.trainer import Trainer
from tests.support.interrupt import kill_after

TINY = {
    "env": {"id": "ProofOfMemory-v0", "options": {"delay": 2}},
    "model": {"memory": "gru", "memory_size": 8, "hidden_size": 8, "vector_encoder_size": 8},
    "ppo": {"epochs": 1, "minibatches": 2},
    "run": {
        "total_steps": 4 * 8 * 3,
        "workers": 4,
        "worker_steps": 8,
        "checkpoint_interval": 1,
        "progress_bar": False,
        "torch_threads": 1,
    },
    "eval": {"interval": 2, "seeds": [100000, 100001], "repetitions": 1},
}
WANDB = ("run.wandb.project=memory-gym-tests", "run.wandb.group=tiny", "run.wandb.mode=offline")


class FakeWandb(types.ModuleType):
    """What the trainer asks of wandb, recorded: init's arguments, every log call, finish."""

    def __init__(self) -> None:
        super().__init__("wandb")
        self.inits: list[dict[str, Any]] = []
        self.logs: list[tuple[dict[str, float], int]] = []
        self.finished = 0

    def init(self, **kwargs: Any) -> Any:
        self.inits.append(kwargs)
        fake = self

        class Run:
            def log(self, data: dict[str, float], step: int) -> None:
                fake.logs.append((dict(data), step))

            def finish(self) -> None:
                fake.finished += 1

        return Run()


def _tensorboard(run_dir: Path) -> dict[tuple[str, int], float]:
    points = {}
    for events in run_dir.glob("events.out.tfevents.*"):
        accumulator = EventAccumulator(str(events))
        accumulator.Reload()
        for tag in accumulator.Tags()["scalars"]:
            points.update({(tag, e.step): e.value for e in accumulator.Scalars(tag)})
    return points


def test_wandb_gets_the_tensorboard_scalars_config_and_revision_and_a_resume_continues_its_run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    fake = FakeWandb()
    monkeypatch.setitem(sys.modules, "wandb", fake)
    config = config_from_dict(TINY, list(WANDB))
    run_dir = tmp_path / "run"
    killed = Trainer(config, run_dir)
    kill_after(killed, 2)
    with pytest.raises(KeyboardInterrupt):
        killed.train()
    assert fake.finished == 1  # closed on the way out, like the TensorBoard writer
    (first,) = fake.inits
    run_id = json.loads((run_dir / "wandb.json").read_text())["id"]
    assert first["id"] == run_id and first["resume"] == "allow" and first["name"] == "run"
    assert (first["project"], first["group"], first["mode"], first["dir"]) == (
        "memory-gym-tests",
        "tiny",
        "offline",
        str(run_dir),
    )
    assert first["config"]["env"]["id"] == "ProofOfMemory-v0" and first["config"]["run"]["wandb"]["group"] == "tiny"
    assert first["config"]["provenance"]["git"] == git_revision()
    logged = {(tag, step): value for data, step in fake.logs for tag, value in data.items()}
    tensorboard = _tensorboard(run_dir)
    assert logged.keys() == tensorboard.keys()  # the same scalars at the same steps
    assert [logged[key] for key in tensorboard] == pytest.approx(list(tensorboard.values()), rel=1e-6)  # float32 there
    assert {"charts/episodic_return", "losses/value_loss", "eval/metric"} <= {tag for tag, _ in logged}

    Trainer.resume(run_dir).train()
    assert [init["id"] for init in fake.inits] == [run_id, run_id] and fake.finished == 2
    assert max(step for _, step in fake.logs) == config.run.total_steps


def test_wandb_is_off_by_default_and_needs_no_install(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "wandb", None)  # importing it fails
    Trainer(config_from_dict(TINY, ["run.total_steps=32"]), tmp_path / "run").train()
    assert not (tmp_path / "run" / "wandb.json").exists()
    with pytest.raises(ImportError, match=r"wandb is not installed: pip install -e '.\[wandb\]'"):
        Trainer(config_from_dict(TINY, ["run.total_steps=32", *WANDB]), tmp_path / "other").train()
    with pytest.raises(
        ConfigError, match="run.wandb.mode='cloud' is invalid; valid choices: online, offline, disabled"
    ):
        config_from_dict(TINY, ["run.wandb.mode=cloud"])


@pytest.mark.slow
def test_wandb_offline_mode_writes_one_local_run_that_a_resume_continues(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    pytest.importorskip("wandb", reason="wandb is an optional extra: pip install -e '.[wandb]'")
    monkeypatch.setenv("WANDB_SILENT", "true")
    monkeypatch.setenv("WANDB_CONSOLE", "off")
    config = config_from_dict(TINY, [*WANDB, "eval.interval=0"])
    run_dir = tmp_path / "run"
    killed = Trainer(config, run_dir)
    kill_after(killed, 2)
    with pytest.raises(KeyboardInterrupt):
        killed.train()
    Trainer.resume(run_dir).train()
    run_id = json.loads((run_dir / "wandb.json").read_text())["id"]
    offline = sorted(path.name for path in (run_dir / "wandb").glob("offline-run-*"))
    # offline-run-<second>-<id>; wandb adds "-1" to the second one when the resume starts within the same second
    assert len(offline) == 2 and all(re.fullmatch(rf"offline-run-\d{{8}}_\d{{6}}-{run_id}(-\d+)?", n) for n in offline)
    assert all(any(path.glob(f"run-{run_id}.wandb")) for path in (run_dir / "wandb").glob("offline-run-*"))


def test_checkpoints_written_before_a_config_field_existed_still_load() -> None:
    """run.wandb was added after runs were checkpointed: their saved configs lack it, and the default keeps them
    the same config (the committed results/popgym runs were trained before it existed)."""
    config = config_from_dict(TINY)
    saved = config_to_dict(config)
    del saved["run"]["wandb"]
    assert check_checkpoint_config({"config": saved}, config, "update_0000001.pt") is None
    saved["run"]["seed"] = 99  # a real difference is still one
    with pytest.raises(ValueError, match=r"different config than the run's config.yaml \(differing: run.seed\)"):
        check_checkpoint_config({"config": saved}, config, "update_0000001.pt")


class FailingWandb(FakeWandb):
    """wandb whose start fails as it does online without an API key."""

    def init(self, **kwargs: Any) -> Any:
        self.inits.append(kwargs)
        raise RuntimeError("No API key configured. Use `wandb login` to log in.\n(a second line of detail)")


def test_wandb_environment_variables_apply_where_the_config_leaves_a_setting_unset(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    fake = FakeWandb()
    monkeypatch.setitem(sys.modules, "wandb", fake)
    for name, value in {"WANDB_MODE": "offline", "WANDB_ENTITY": "team", "WANDB_RUN_GROUP": "g"}.items():
        monkeypatch.setenv(name, value)
    monkeypatch.setenv("WANDB_DIR", str(tmp_path / "wandb-files"))
    Trainer(config_from_dict(TINY, ["run.total_steps=32", "run.wandb.project=p"]), tmp_path / "run").train()
    (unset,) = fake.inits
    # None: W&B reads its own variables (WANDB_MODE, WANDB_ENTITY, WANDB_RUN_GROUP, WANDB_DIR)
    assert (unset["mode"], unset["entity"], unset["group"], unset["dir"]) == (None, None, None, None)
    (start,) = json.loads((tmp_path / "run" / "wandb.json").read_text())["starts"]
    assert {key: start[key] for key in ("mode", "entity", "group", "dir")} == {
        "mode": "offline",
        "entity": "team",
        "group": "g",
        "dir": str(tmp_path / "wandb-files"),
    }
    assert start["from"] == {
        "mode": "WANDB_MODE",
        "entity": "WANDB_ENTITY",
        "group": "WANDB_RUN_GROUP",
        "dir": "WANDB_DIR",
    }

    explicit = ["run.total_steps=32", "run.wandb.project=p", "run.wandb.mode=disabled", "run.wandb.group=mine"]
    Trainer(config_from_dict(TINY, explicit), tmp_path / "other").train()
    assert (fake.inits[1]["mode"], fake.inits[1]["group"]) == ("disabled", "mine")  # the config's own values win
    (start,) = json.loads((tmp_path / "other" / "wandb.json").read_text())["starts"]
    assert (start["mode"], start["from"]["mode"], start["from"]["group"]) == ("disabled", "config", "config")
    monkeypatch.delenv("WANDB_MODE")
    Trainer(config_from_dict(TINY, ["run.total_steps=32", "run.wandb.project=p"]), tmp_path / "third").train()
    (start,) = json.loads((tmp_path / "third" / "wandb.json").read_text())["starts"]
    assert (start["mode"], start["from"]["mode"]) == ("online", "W&B's default")


def test_wandb_mode_from_the_environment_runs_offline_for_real(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The config sets no mode: WANDB_MODE=offline applies (it used to be overridden by the config's 'online', which
    without an API key stopped the run with UsageError)."""
    wandb = pytest.importorskip("wandb", reason="wandb is an optional extra: pip install -e '.[wandb]'")
    wandb.teardown()  # W&B reads its variables once per process, at its first start: here, this test's
    for name, value in {"WANDB_MODE": "offline", "WANDB_SILENT": "true", "WANDB_CONSOLE": "off"}.items():
        monkeypatch.setenv(name, value)
    monkeypatch.delenv("WANDB_API_KEY", raising=False)
    monkeypatch.delenv("WANDB_DIR", raising=False)
    run_dir = tmp_path / "run"
    try:
        config = config_from_dict(TINY, ["run.total_steps=32", "run.wandb.project=x", "eval.interval=0"])
        Trainer(config, run_dir).train()
    finally:
        wandb.teardown()
    run_id = json.loads((run_dir / "wandb.json").read_text())["id"]
    assert [path.name.endswith(run_id) for path in (run_dir / "wandb").glob("offline-run-*")] == [True]
    assert yaml.safe_load((run_dir / "config.yaml").read_text())["run"]["wandb"]["mode"] is None  # unset, as given


def test_a_wandb_start_up_failure_exits_2_in_one_line_before_the_run_directory_exists(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture
) -> None:
    from scripts import train as train_script

    monkeypatch.setitem(sys.modules, "wandb", FailingWandb())
    config_file = tmp_path / "tiny.yaml"
    config_file.write_text(yaml.safe_dump(TINY))
    run_dir = tmp_path / "runs" / "tiny" / "run"
    args = ["--config", str(config_file), "--run-dir", str(run_dir), "--set", "run.wandb.project=x"]
    assert train_script.main(args) == 2
    err = capsys.readouterr().err
    (line,) = err.splitlines()
    assert line.startswith("error: W&B could not start (RuntimeError: No API key configured. Use `wandb login`")
    assert "mode online (W&B's default)" in line and "WANDB_MODE=offline" in line
    assert f"nothing was written to {run_dir}" in line
    assert not (tmp_path / "runs").exists()  # no run directory, so the same command works once W&B can start
    monkeypatch.setitem(sys.modules, "wandb", FakeWandb())
    assert train_script.main(args) == 0


def test_a_wandb_start_up_failure_on_resume_leaves_the_run_resumable(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from agents.runtime.tracking import TrackingError

    monkeypatch.setitem(sys.modules, "wandb", FakeWandb())
    run_dir = tmp_path / "run"
    killed = Trainer(config_from_dict(TINY, list(WANDB)), run_dir)
    kill_after(killed, 2)
    with pytest.raises(KeyboardInterrupt):
        killed.train()
    files = {p: p.read_bytes() for p in run_dir.rglob("*") if p.is_file()}
    monkeypatch.setitem(sys.modules, "wandb", FailingWandb())
    with pytest.raises(
        TrackingError, match=f"the run is unchanged: resume it with scripts/train.py --resume {run_dir}"
    ):
        Trainer.resume(run_dir).train()
    assert {p: p.read_bytes() for p in run_dir.rglob("*") if p.is_file()} == files
    fake = FakeWandb()
    monkeypatch.setitem(sys.modules, "wandb", fake)
    assert Trainer.resume(run_dir).train() and len(fake.inits) == 1
