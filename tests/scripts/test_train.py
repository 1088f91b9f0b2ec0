"""scripts/train.py: what the command line says and does around the trainer (notices, errors, resuming)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

from scripts import train as train_script

TINY = {
    "env": {"id": "ProofOfMemory-v0", "options": {"delay": 3}},
    "model": {"memory": "gru", "memory_size": 8, "hidden_size": 8, "vector_encoder_size": 8},
    "ppo": {"epochs": 1, "minibatches": 2, "learning_rate": {"initial": 1.0e-3, "final": 1.0e-4}},
    "run": {
        "total_steps": 4 * 16 * 2,
        "workers": 4,
        "worker_steps": 16,
        "seed": 1,
        "progress_bar": False,
        "torch_threads": 1,
        "checkpoint_interval": 0,
    },
}


@pytest.fixture
def config_file(tmp_path: Path) -> Path:
    path = tmp_path / "tiny.yaml"
    path.write_text(yaml.safe_dump(TINY))
    return path


def test_rounding_down_to_whole_updates_is_announced(
    tmp_path: Path, config_file: Path, capsys: pytest.CaptureFixture
) -> None:
    run_dir = tmp_path / "run"
    args = ["--config", str(config_file), "--run-dir", str(run_dir), "--set", "run.total_steps=1.5e2"]
    assert train_script.main(args) == 0
    out = capsys.readouterr().out
    assert (
        "note: run.total_steps=150 is not a whole number of updates of 64 steps (run.workers x run.worker_steps = "
        "4 x 16): training 2 updates, 128 steps"
    ) in out
    assert train_script.main(["--config", str(config_file), "--run-dir", str(tmp_path / "exact")]) == 0
    assert "note:" not in capsys.readouterr().out


def test_a_yaml_syntax_error_exits_2_naming_file_line_and_column(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    path = tmp_path / "broken.yaml"
    path.write_text("run:\n  seed: 1\nppo: {gamma: 0.99\n")
    assert train_script.main(["--config", str(path), "--run-dir", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {path}: line 4, column 1: invalid YAML:") and "Traceback" not in err
    assert not (tmp_path / "run").exists()


def test_a_fractional_integer_override_exits_2_naming_the_key(
    tmp_path: Path, config_file: Path, capsys: pytest.CaptureFixture
) -> None:
    args = ["--config", str(config_file), "--run-dir", str(tmp_path / "run"), "--set", "ppo.epochs=1.5e0"]
    assert train_script.main(args) == 2
    assert "ppo.epochs='1.5e0' is invalid: expected an int in [1, inf]; 1.5 is not a whole number" in (
        capsys.readouterr().err
    )


def _snapshot(run_dir: Path) -> dict[str, bytes]:
    return {str(p.relative_to(run_dir)): p.read_bytes() for p in sorted(run_dir.rglob("*")) if p.is_file()}


def _trained(tmp_path: Path, config_file: Path) -> Path:
    run_dir = tmp_path / "run"
    assert train_script.main(["--config", str(config_file), "--run-dir", str(run_dir)]) == 0
    return run_dir


def test_resuming_a_finished_run_says_so_and_changes_nothing(
    tmp_path: Path, config_file: Path, capsys: pytest.CaptureFixture
) -> None:
    """No 'resumed' entry in run_info.json, no new (empty) event file, no rewritten log: the directory stays
    byte for byte what it was, and the trainer itself does nothing either."""
    from agents.training.trainer import Trainer

    run_dir = _trained(tmp_path, config_file)
    capsys.readouterr()
    before = _snapshot(run_dir)
    assert train_script.main(["--resume", str(run_dir)]) == 0
    out = capsys.readouterr().out
    assert f"{run_dir}: already finished (128 steps of 128); nothing changed" in out
    assert f"--resume {run_dir} --set run.total_steps=N (N >= 192)" in out
    assert _snapshot(run_dir) == before
    trainer = Trainer.resume(run_dir)
    assert trainer.finished and trainer.train() == []
    assert _snapshot(run_dir) == before


def test_extending_a_finished_run_trains_exactly_the_added_updates(
    tmp_path: Path, config_file: Path, capsys: pytest.CaptureFixture
) -> None:
    run_dir = _trained(tmp_path, config_file)
    rows_before = (run_dir / "training.csv").read_text().splitlines()
    capsys.readouterr()
    assert train_script.main(["--resume", str(run_dir), "--set", "run.total_steps=2.5e2"]) == 0
    out = capsys.readouterr().out
    assert (
        "lengthening the run from run.total_steps=128 (2 updates) to 250 (3 updates), from update 2 (step 128) on"
    ) in out
    assert "note: run.total_steps=250 is not a whole number of updates of 64 steps" in out
    rows = (run_dir / "training.csv").read_text().splitlines()
    assert rows[:3] == rows_before and len(rows) == 1 + 3 and rows[-1].split(",")[4] == "192"
    assert sorted(p.name for p in (run_dir / "checkpoints").iterdir()) == ["update_0000002.pt", "update_0000003.pt"]
    info = json.loads((run_dir / "run_info.json").read_text())
    (extension,) = info["extended"]
    assert {k: extension[k] for k in ("update", "step", "total_steps", "num_updates")} == {
        "update": 2,
        "step": 128,
        "total_steps": [128, 250],
        "num_updates": [2, 3],
    }
    assert info["finished"]["update"] == 3 and info["num_updates"] == 3
    assert yaml.safe_load((run_dir / "config.yaml").read_text())["run"]["total_steps"] == 250
    assert train_script.main(["--resume", str(run_dir)]) == 0
    assert "already finished (192 steps of 192)" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("override", "message"),
    [
        ("ppo.gamma=0.9", "ppo.gamma cannot be changed on resume"),
        ("run.seed=4", "run.seed cannot be changed on resume"),
        ("run.total_steps=128", "run.total_steps=128 does not lengthen the run: it is 2 updates of 64 steps"),
        ("run.total_steps=190", "give at least 192 to add an update"),
        ("run.total_steps=1.5e2", "run.total_steps=150 does not lengthen the run"),
        ("run.total_steps=fast", "run.total_steps='fast' is invalid: expected an int"),
        ("run.device=cuda:7", "run.device cannot be changed on resume"),
        ("run.device=cuda:7", "another device computes other floats"),
        ("run.method=other", "run.method cannot be changed on resume"),
        ("eval.interval=1", "eval.interval cannot be changed on resume"),
        ("grid.run.seed=[1, 2]", "grid.run.seed cannot be changed on resume"),
    ],
)
def test_a_resume_refuses_any_other_change_naming_the_key(
    tmp_path: Path, config_file: Path, capsys: pytest.CaptureFixture, override: str, message: str
) -> None:
    run_dir = _trained(tmp_path, config_file)
    capsys.readouterr()
    before = _snapshot(run_dir)
    assert train_script.main(["--resume", str(run_dir), "--set", override]) == 2
    assert message in capsys.readouterr().err
    assert _snapshot(run_dir) == before


def test_a_resume_names_every_key_it_refuses_and_what_it_takes(
    tmp_path: Path, config_file: Path, capsys: pytest.CaptureFixture
) -> None:
    run_dir = _trained(tmp_path, config_file)
    capsys.readouterr()
    args = ["--resume", str(run_dir), "--set", "ppo.gamma=0.9", "--set", "run.progress_bar=true", "--set", "run.seed=3"]
    assert train_script.main(args) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith("error: ppo.gamma, run.seed cannot be changed on resume")
    assert "run.total_steps (to lengthen the run)" in line and "run.progress_bar" in line and "run.wandb" in line


RESUMABLE = [  # 4 updates, a checkpoint every 2, an evaluation (2 records) after every update
    "run.total_steps=256",
    "run.checkpoint_interval=2",
    "eval.interval=1",
    "eval.seeds=[100000, 100001]",
    "eval.repetitions=1",
]


def test_a_resume_takes_the_settings_no_record_depends_on_and_ends_as_an_uninterrupted_run(
    tmp_path: Path, config_file: Path, capsys: pytest.CaptureFixture
) -> None:
    """run.progress_bar, run.checkpoint_interval, run.keep_checkpoints and run.wandb change on resume; the records
    come out byte for byte those of the run trained in one go with the old settings. The command says which
    checkpoint it resumes from and what it dropped past it (one row of training.csv, one evaluation's records)."""
    from agents.config import load_config
    from agents.training.trainer import Trainer
    from tests.support.interrupt import kill_after

    whole = tmp_path / "whole" / "run"
    sets = [item for setting in RESUMABLE for item in ("--set", setting)]
    assert train_script.main(["--config", str(config_file), "--run-dir", str(whole), *sets]) == 0
    run_dir = tmp_path / "killed" / "run"
    killed = Trainer(load_config(config_file, [*RESUMABLE, "run.progress_bar=true"]), run_dir)
    kill_after(killed, 3)  # past the checkpoint of update 2: update 3's row and evaluation are logged
    with pytest.raises(KeyboardInterrupt):
        killed.train()
    capsys.readouterr()
    changes = [
        "run.progress_bar=false",
        "run.checkpoint_interval=1",
        "run.keep_checkpoints=0",
        "run.wandb.mode=disabled",
    ]
    assert train_script.main(["--resume", str(run_dir), *(x for c in changes for x in ("--set", c))]) == 0
    out = capsys.readouterr().out
    assert f"resuming from {run_dir / 'checkpoints' / 'update_0000002.pt'} (update 2 of 4, step 128)" in out
    assert "dropped what the run logged after it: 1 row of training.csv, 2 records of eval/episodes.csv" in out
    assert "run.progress_bar: true -> false" in out and "run.wandb.mode: null -> disabled" in out
    for name in ("training.csv", "eval/episodes.csv"):
        assert (run_dir / name).read_bytes() == (whole / name).read_bytes()
    saved = yaml.safe_load((run_dir / "config.yaml").read_text())["run"]
    assert (saved["progress_bar"], saved["checkpoint_interval"], saved["keep_checkpoints"]) == (False, 1, 0)
    assert saved["wandb"]["mode"] == "disabled"
    (resumed,) = json.loads((run_dir / "run_info.json").read_text())["resumed"]
    assert resumed["changed"] == {
        "run.checkpoint_interval": [2, 1],
        "run.keep_checkpoints": [2, 0],
        "run.progress_bar": [True, False],
        "run.wandb.mode": [None, "disabled"],
    }
    assert [p.name for p in sorted((run_dir / "checkpoints").iterdir())] == [f"update_{u:07d}.pt" for u in (2, 3, 4)]
    assert train_script.main(["--resume", str(run_dir), "--set", "run.progress_bar=true"]) == 0
    assert "already finished (256 steps of 256); nothing changed" in capsys.readouterr().out


def test_a_resume_by_hand_takes_another_thread_count_and_says_it_ends_bit_exactness(
    tmp_path: Path, config_file: Path, capsys: pytest.CaptureFixture
) -> None:
    """A job restarted on a machine with other cores: run.torch_threads is outside the experiment (the config
    digest), so a resume takes it, says that the run's floats now differ from an uninterrupted run's, records it,
    and the checkpoint written before still loads under the new config.yaml."""
    from agents.config import load_config
    from agents.training.trainer import Trainer
    from tests.support.interrupt import kill_after

    run_dir = tmp_path / "run"
    killed = Trainer(load_config(config_file, RESUMABLE), run_dir)
    kill_after(killed, 3)
    with pytest.raises(KeyboardInterrupt):
        killed.train()
    capsys.readouterr()
    assert train_script.main(["--resume", str(run_dir), "--set", "run.torch_threads=2"]) == 0
    out = capsys.readouterr().out
    assert (
        "run.torch_threads: 1 -> 2" in out and "note: run.torch_threads: the thread count changes the rounding" in out
    )
    assert yaml.safe_load((run_dir / "config.yaml").read_text())["run"]["torch_threads"] == 2
    (resumed,) = json.loads((run_dir / "run_info.json").read_text())["resumed"]
    assert resumed["changed"] == {"run.torch_threads": [1, 2]}


def test_an_encoder_that_does_not_fit_names_the_environments_own_observation_space(
    tmp_path: Path, config_file: Path, capsys: pytest.CaptureFixture
) -> None:
    """A gymnasium environment's observations reach the model translated (a Dict of vector_observation and/or
    visual_observation): the error names the space the user's environment has, not the translation."""
    import gymnasium as gym

    from tests.support.tiny_env import ENV_ID

    cartpole = " ".join(str(gym.make("CartPole-v1").observation_space).split())
    args = ["--config", str(config_file), "--run-dir", str(tmp_path / "run"), "--set", "env.id=CartPole-v1"]
    assert train_script.main([*args, "--set", "env.options={}", "--set", "model.encoder=nature_cnn"]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line == (
        f"error: model.encoder=nature_cnn needs an image observation, but CartPole-v1's observation space {cartpole} "
        "has none: set model.encoder: mlp (its layers: model.mlp_sizes)"
    )
    assert (
        train_script.main(
            [*args, "--set", "env.options={}", "--set", "model.encoder=mlp", "--set", "model.helm.lm=random"]
        )
        == 2
    )
    assert capsys.readouterr().err == (
        f"error: model.helm.lm='random': the HELM branch needs an image observation, but CartPole-v1's observation "
        f"space {cartpole} has none: set model.helm.lm: none\n"
    )
    image = ["--set", f"env.id={ENV_ID}", "--set", "env.options={}", "--set", "env.image_layout=chw"]
    image += ["--set", "env.make_kwargs={observation: image_chw}", "--set", "model.encoder=mlp"]
    assert train_script.main([*args, *image]) == 2
    err = capsys.readouterr().err
    assert "Dict(" not in err and "(36, 36, 3)" not in err
    assert f"but {ENV_ID}'s observation space Box(0, 255, (3, 36, 36), uint8) has one: use an image encoder" in err
    assert not (tmp_path / "run").exists()
