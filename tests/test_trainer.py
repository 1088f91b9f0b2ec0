"""The trainer end to end on tiny configs: rollout bookkeeping, run files, checkpoints, exact resume, NaN guard."""

from __future__ import annotations

import json
import platform
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from agents.config import config_from_dict, load_config
from agents.models import log_probs_and_entropy
from agents.sequences import pad_sequences, split_sequences
from agents.trainer import Trainer, TrainingDiverged, latest_checkpoint
from scripts import train as train_script
from tests.support.dict_env import DictCore

TINY = {
    "env": {"id": "ProofOfMemory-v0", "options": {"delay": 3}},
    "model": {"memory": "gru", "memory_size": 16, "hidden_size": 16, "vector_encoder_size": 8},
    "ppo": {"epochs": 2, "minibatches": 2, "learning_rate": {"initial": 1.0e-3, "final": 1.0e-4}},
    "run": {"total_steps": 4 * 16 * 6, "workers": 4, "worker_steps": 16, "seed": 3, "progress_bar": False},
}


def _config(*overrides: str, raw: dict | None = None):
    return config_from_dict(raw or TINY, list(overrides))


def _kill_after(trainer: Trainer, updates: int) -> None:
    """Make ``trainer.train()`` die like a killed process once ``updates`` updates are done."""
    run_update = trainer.train_update

    def maybe_die() -> dict[str, float]:
        if trainer.update == updates:
            raise KeyboardInterrupt
        return run_update()

    trainer.train_update = maybe_die  # type: ignore[method-assign]


def _assert_same_weights(a: Trainer, b: Trainer) -> None:
    for (name, x), y in zip(a.model.state_dict().items(), b.model.state_dict().values(), strict=True):
        assert torch.equal(x, y), name


@pytest.mark.parametrize(
    "overrides",
    [
        ("model.memory=gru", "ppo.sequence_length=max"),
        ("model.memory=lstm", "ppo.sequence_length=3"),
        ("model.memory=none", "model.previous_action=true", "model.previous_reward=true"),
        ("model.memory=gru", "run.precision=bf16"),
    ],
    ids=["gru-max", "lstm-3", "none", "gru-bf16"],
)
def test_resume_gives_the_weights_of_an_uninterrupted_run(tmp_path: Path, overrides: tuple[str, ...]) -> None:
    config = _config(*overrides, "run.checkpoint_interval=2")
    uninterrupted = Trainer(config, tmp_path / "a")
    uninterrupted.train()

    killed = Trainer(config, tmp_path / "b")
    _kill_after(killed, 5)
    with pytest.raises(KeyboardInterrupt):
        killed.train()
    assert latest_checkpoint(tmp_path / "b").name == "update_0000004.pt"
    resumed = Trainer.resume(tmp_path / "b")
    assert resumed.update == 4 and resumed.global_step == 4 * 64
    resumed.train()
    assert resumed.update == uninterrupted.update == 6
    _assert_same_weights(uninterrupted, resumed)
    info = json.loads((tmp_path / "b" / "run_info.json").read_text())
    assert [r["update"] for r in info["resumed"]] == [4]


def test_resume_with_dict_observations_and_multidiscrete_actions(tmp_path: Path, dict_env: str) -> None:
    config = _config(
        f"env.id={dict_env}",
        "env.options={}",
        "model.previous_action=true",
        "model.previous_reward=true",
        "run.checkpoint_interval=3",
    )
    uninterrupted = Trainer(config, tmp_path / "a")
    history = uninterrupted.train()
    assert "env/hits" in history[-1] and not any("label" in key for key in history[-1])
    killed = Trainer(config, tmp_path / "b")
    _kill_after(killed, 4)
    with pytest.raises(KeyboardInterrupt):
        killed.train()
    resumed = Trainer.resume(tmp_path / "b")
    assert resumed.update == 3
    resumed.train()
    _assert_same_weights(uninterrupted, resumed)


def test_resume_refuses_a_nondeterministic_environment(tmp_path: Path, dict_env: str) -> None:
    config = _config(f"env.id={dict_env}", "env.options={}", "run.checkpoint_interval=1", "run.total_steps=64")
    Trainer(config, tmp_path).train()
    DictCore._reset_slot_original = DictCore._reset_slot  # type: ignore[attr-defined]
    try:
        DictCore._reset_slot = lambda self, k, rng, opts: DictCore._reset_slot_original(  # type: ignore[method-assign]
            self, k, np.random.default_rng(), opts
        )
        with pytest.raises(RuntimeError, match="not deterministic|did not reproduce"):
            Trainer.resume(tmp_path)
    finally:
        DictCore._reset_slot = DictCore._reset_slot_original  # type: ignore[method-assign]


def test_rollout_bookkeeping(tmp_path: Path, dict_env: str) -> None:
    """Stored start states are the states fed into each step (zeros after an episode end), previous action and
    reward are zero at episode starts, and re-evaluating the rollout as padded sequences reproduces its log-probs
    and values (the first epoch's ratio is 1)."""
    config = _config(
        f"env.id={dict_env}",
        "env.options={}",
        "env.train_seeds=[7, 9]",
        "model.previous_action=true",
        "model.previous_reward=true",
        "run.worker_steps=24",
    )
    trainer = Trainer(config, tmp_path)
    trainer._collect_rollout()
    buffer = trainer.buffer
    done = buffer.terminated
    assert done.any()
    assert set(trainer.core.seeds) <= {7, 8, 9}
    starts = torch.zeros_like(done)
    starts[:, 1:] = done[:, :-1]
    assert not buffer.memory_states[starts].any()
    assert not buffer.inputs["previous_action"][starts].any() and not buffer.inputs["previous_reward"][starts].any()
    continuing = ~starts
    continuing[:, 0] = False
    prev_action = torch.zeros_like(buffer.actions)
    prev_action[:, 1:] = buffer.actions[:, :-1]
    assert torch.equal(buffer.inputs["previous_action"][continuing], prev_action[continuing])
    assert buffer.memory_states[continuing].abs().sum(-1).gt(0).all()

    for max_length in (None, 5):
        sequences = split_sequences(done.numpy(), max_length)
        batch = pad_sequences(sequences, np.arange(len(sequences)))
        inputs = {name: buffer.flat(t)[batch.step_index] for name, t in buffer.inputs.items()}
        with torch.no_grad():
            logits, values = trainer.model.evaluate(
                inputs, buffer.flat(buffer.memory_states)[batch.start_index], batch.mask
            )
        log_probs, _ = log_probs_and_entropy(logits, buffer.flat(buffer.actions)[batch.step_index])
        torch.testing.assert_close(log_probs, buffer.flat(buffer.log_probs)[batch.step_index], atol=1e-5, rtol=1e-5)
        torch.testing.assert_close(values, buffer.flat(buffer.values)[batch.step_index], atol=1e-5, rtol=1e-5)


def test_run_directory_holds_config_versions_scalars_and_pruned_checkpoints(tmp_path: Path) -> None:
    config = _config("run.checkpoint_interval=1", "run.keep_checkpoints=2")
    trainer = Trainer(config, tmp_path)
    trainer.train()
    assert load_config(tmp_path / "config.yaml") == config
    info = json.loads((tmp_path / "run_info.json").read_text())
    assert info["seed"] == 3 and {"python", "torch", "numpy", "gymnasium"} <= set(info["versions"])
    assert info["git"]["revision"] and "machine" in info
    assert sorted(p.name for p in (tmp_path / "checkpoints").iterdir()) == ["update_0000005.pt", "update_0000006.pt"]
    events = EventAccumulator(str(tmp_path))
    events.Reload()
    tags = set(events.Tags()["scalars"])
    expected = {
        "charts/episodic_return",
        "charts/episodic_length",
        "charts/SPS",
        "charts/learning_rate",
        "losses/policy_loss",
        "losses/value_loss",
        "losses/entropy",
        "losses/approx_kl",
        "losses/clipfrac",
        "losses/explained_variance",
        "env/success",
    }
    assert expected <= tags
    learning_rates = [e.value for e in events.Scalars("charts/learning_rate")]
    assert learning_rates[0] == pytest.approx(1e-3) and learning_rates == sorted(learning_rates, reverse=True)
    assert [e.step for e in events.Scalars("charts/SPS")] == [64 * u for u in range(1, 7)]


def test_non_finite_loss_stops_and_keeps_the_last_good_checkpoint(tmp_path: Path) -> None:
    trainer = Trainer(_config("run.checkpoint_interval=2"), tmp_path)
    step = trainer.core.step

    def poisoned_step(actions: np.ndarray, idx: np.ndarray | None = None):
        rewards, terminated, finals = step(actions, idx)
        if trainer.update >= 3:
            rewards = np.full_like(rewards, np.nan)
        return rewards, terminated, finals

    trainer.core.step = poisoned_step  # type: ignore[method-assign]
    with pytest.raises(TrainingDiverged, match=r"update 4: non-finite loss.*last good checkpoint is .*update_0000002"):
        trainer.train()
    assert latest_checkpoint(tmp_path).name == "update_0000002.pt"
    resumed = Trainer.resume(tmp_path)
    assert resumed.update == 2 and all(torch.isfinite(p).all() for p in resumed.model.parameters())


def test_command_line(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    config_path = tmp_path / "tiny.yaml"
    config_path.write_text(yaml.safe_dump(TINY))
    run_dir = tmp_path / "run"
    code = train_script.main(
        [
            "--config",
            str(config_path),
            "--set",
            "run.total_steps=128",
            "--set",
            "model.memory=none",
            "--run-dir",
            str(run_dir),
        ]
    )
    assert code == 0
    assert load_config(run_dir / "config.yaml").model.memory == "none"
    assert latest_checkpoint(run_dir).name == "update_0000002.pt"
    assert "env/success=" in capsys.readouterr().out
    assert train_script.main(["--config", str(config_path), "--set", "ppo.gama=0.9"]) == 2
    assert "did you mean 'ppo.gamma'?" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        train_script.main(["--resume", str(run_dir), "--set", "ppo.gamma=0.9"])
    with pytest.raises(SystemExit):
        train_script.main(["--config", str(config_path), "--run-dir", str(run_dir)])  # would overwrite a run
    assert train_script.main(["--resume", str(tmp_path / "missing")]) == 2


def test_bf16_acts_with_a_bfloat16_copy_of_the_weights(tmp_path: Path, dict_env: str) -> None:
    config = _config(f"env.id={dict_env}", "env.options={}", "model.previous_action=true", "run.precision=bf16")
    trainer = Trainer(config, tmp_path)
    assert trainer.rollout_model is not trainer.model
    trainer.train_update()
    for low, weight in zip(trainer.rollout_model.parameters(), trainer.model.parameters(), strict=True):
        assert low.dtype == torch.bfloat16 and weight.dtype == torch.float32
        assert torch.equal(low, weight.to(torch.bfloat16))  # refreshed after the update
    trainer._collect_rollout()
    buffer = trainer.buffer
    sequences = split_sequences(buffer.terminated.numpy(), None)
    batch = pad_sequences(sequences, np.arange(len(sequences)))
    inputs = {name: buffer.flat(t)[batch.step_index] for name, t in buffer.inputs.items()}
    with torch.no_grad(), trainer._autocast():
        logits, values = trainer.model.evaluate(
            inputs, buffer.flat(buffer.memory_states)[batch.start_index], batch.mask
        )
    log_probs, _ = log_probs_and_entropy(logits, buffer.flat(buffer.actions)[batch.step_index])
    # acting in bfloat16 and training under bf16 autocast agree to bfloat16 precision: the first ratios are ~1
    ratio = (log_probs - buffer.flat(buffer.log_probs)[batch.step_index]).exp()
    assert (ratio - 1).abs().max() < 0.05


def test_a_config_with_a_grid_is_refused(tmp_path: Path) -> None:
    config = _config("run.seed=1", raw={**TINY, "grid": {"run.seed": [1, 2]}})
    with pytest.raises(ValueError, match="grid"):
        Trainer(config, tmp_path)


@pytest.mark.skipif(sys.platform != "linux" or platform.libc_ver()[0] != "glibc", reason="a glibc allocator setting")
def test_freed_tensor_memory_is_reused_without_page_faults() -> None:
    import resource

    from agents.trainer import keep_freed_memory

    assert keep_freed_memory()

    def minibatch() -> None:  # like a minibatch's activations: several large tensors alive at once, then all freed
        live = [torch.ones(2 << 20) for _ in range(8)]  # 8 x 8 MiB
        del live

    minibatch()
    minibatch()
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(10):
        minibatch()
    faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before
    # glibc's defaults give back the freed 64 MiB each time: ~16k page faults per round (measured 163k for ten)
    assert faults < 16_000, f"{faults} page faults in 10 rounds: freed memory was not reused"
