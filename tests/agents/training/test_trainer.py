"""The trainer end to end on tiny configs: rollout bookkeeping, run files, checkpoints, exact resume, NaN guard."""

from __future__ import annotations

import csv
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from agents.config import config_from_dict, load_config
from agents.policy.checkpoint import latest_checkpoint
from agents.policy.models import log_probs_and_entropy, one_hot_actions
from agents.training.sequences import pad_sequences, split_sequences
from agents.training.trainer import Trainer, TrainingDiverged
from scripts import train as train_script
from tests.support.dict_env import DictCore
from tests.support.interrupt import kill_after

TINY = {
    "env": {"id": "ProofOfMemory-v0", "options": {"delay": 3}},
    "model": {"memory": "gru", "memory_size": 16, "hidden_size": 16, "vector_encoder_size": 8},
    "ppo": {"epochs": 2, "minibatches": 2, "learning_rate": {"initial": 1.0e-3, "final": 1.0e-4}},
    "run": {
        "total_steps": 4 * 16 * 6,
        "workers": 4,
        "worker_steps": 16,
        "seed": 3,
        "progress_bar": False,
        "torch_threads": 1,  # the same numbers on any machine, and no OpenMP stalls when the cores are busy
    },
}


HELM = (  # a tiny random transformer with a memory shorter than the episodes
    "model.helm.lm=random",
    "model.helm.mem_len=3",
    "model.helm.random_layers=2",
    "model.helm.random_width=32",
    "model.helm.random_vocab=64",
)

# a small Transformer-XL whose window (3 steps) is shorter than the episodes (delay 4: 5 steps), which straddle the
# 16-step rollouts: windows reach back into the previous rollout, and a resume must restore them
TRXL = ("model.trxl.layers=2", "model.trxl.heads=2", "model.trxl.dim=16", "model.trxl.memory_length=3")
TRXL = (*TRXL, "env.options.delay=4")


def _config(*overrides: str, raw: dict | None = None):
    return config_from_dict(raw or TINY, list(overrides))


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
        ("model.memory=none", "model.frame_stack=4", "model.grayscale=true", "env.frame_skip=2"),
        ("model.memory=trxl", *TRXL, "ppo.sequence_length=3"),
        ("model.memory=trxl", *TRXL, "model.trxl.cache_dtype=bf16", "run.precision=bf16", "model.trxl.gating=true"),
        ("model.memory=lru", "ppo.sequence_length=3", "model.memory_layers=2"),
        ("model.memory=ffm", "ppo.sequence_length=max", "model.ffm.trace_size=4", "model.ffm.context_size=2"),
        ("model.memory=mamba", "ppo.sequence_length=3", "model.mamba.state_size=4", "run.precision=bf16"),
        ("model.memory=mamba2", "model.mamba2.head_dim=16", "model.mamba2.chunk_size=4", "run.precision=bf16"),
        ("model.memory=tests.support.external_memory:LeakyMemory", "model.memory_options={leak: 0.5}"),
        ("model.memory=gru", "env.id=Endless-MortarMayhem-v0", "env.options={}", "ppo.ground_truth_coef=0.5"),
    ],
    ids=[
        "gru-max",
        "lstm-3",
        "none",
        "gru-bf16",
        "stack4-gray-skip2",
        "trxl-3",
        "trxl-bf16-gated",
        "lru-3-2layers",
        "ffm-max",
        "mamba-3-bf16",
        "mamba2-chunks4-bf16",
        "external-memory",
        "gru-ground-truth",
    ],
)
@pytest.mark.slow
def test_resume_gives_the_weights_of_an_uninterrupted_run(tmp_path: Path, overrides: tuple[str, ...]) -> None:
    """Killed after update 5 with checkpoints every 2: the resumed run ends with the same weights, TensorBoard
    points, training log and evaluation records as an uninterrupted one (nothing of update 5 survives twice)."""
    evaluation = ("eval.interval=3", "eval.seeds=[100000, 100002]", "eval.repetitions=2")
    _check_resume(tmp_path, _config(*overrides, *evaluation, "run.checkpoint_interval=2"))


@pytest.mark.slow
def test_resume_rebuilds_the_helm_memory_exactly(tmp_path: Path, dict_env: str) -> None:
    """The HELM branch's memory is rebuilt by replaying the slots' episodes (of different lengths here)."""
    evaluation = ("eval.interval=3", "eval.seeds=[100000, 100002]", "eval.repetitions=2")
    env = (f"env.id={dict_env}", "env.options={}")
    _check_resume(tmp_path, _config("model.memory=none", *HELM, *env, *evaluation, "run.checkpoint_interval=2"))


def _check_resume(tmp_path: Path, config) -> None:
    uninterrupted = Trainer(config, tmp_path / "a")
    uninterrupted.train()

    killed = Trainer(config, tmp_path / "b")
    kill_after(killed, 5)
    with pytest.raises(KeyboardInterrupt):
        killed.train()
    assert latest_checkpoint(tmp_path / "b").name == "update_0000004.pt"
    # training.csv had a row per update, the one past the checkpoint included, then a kill tore a line in two
    assert [row["step"] for row in _rows(tmp_path / "b" / "training.csv")] == [str(64 * u) for u in range(1, 6)]
    with open(tmp_path / "b" / "training.csv", "a") as handle:
        handle.write("b,gru,ProofOfMemory-v0,ProofOfMemory-v0,38")
    _next_second()  # event files are named by time, then by a per-process counter: keep the resumed one after
    resumed = Trainer.resume(tmp_path / "b")
    assert resumed.update == 4 and resumed.global_step == 4 * 64
    resumed.train()
    assert resumed.update == uninterrupted.update == 6
    _assert_same_weights(uninterrupted, resumed)
    info = json.loads((tmp_path / "b" / "run_info.json").read_text())
    assert [r["update"] for r in info["resumed"]] == [4]
    for name in ("training.csv", "eval/episodes.csv"):
        assert _rows(tmp_path / "a" / name) == _rows(tmp_path / "b" / name), name
    uninterrupted_log = (tmp_path / "a" / "training.csv").read_text()
    assert (tmp_path / "b" / "training.csv").read_text() == uninterrupted_log.replace("\na,", "\nb,")  # the run column
    assert uninterrupted_log.count("run,method,task") == 1 and uninterrupted_log.endswith("\n")
    uninterrupted_events, resumed_events = _scalars(tmp_path / "a"), _scalars(tmp_path / "b")
    assert set(uninterrupted_events) == set(resumed_events)
    for tag, points in uninterrupted_events.items():
        assert [step for step, _ in resumed_events[tag]] == [step for step, _ in points], tag
        if "SPS" not in tag:
            assert [value for _, value in resumed_events[tag]] == pytest.approx([value for _, value in points]), tag
    assert [step for step, _ in uninterrupted_events["charts/learning_rate"]] == [64 * u for u in range(1, 7)]
    assert [step for step, _ in uninterrupted_events["eval/metric"]] == [64 * 3, 64 * 6]


def _next_second() -> None:
    time.sleep(1.0 - time.time() % 1.0 + 0.01)


def _rows(path: Path) -> list[dict[str, str]]:
    """A CSV's rows without the run column (the run directory's name)."""
    with open(path, newline="") as handle:
        return [{k: v for k, v in row.items() if k != "run"} for row in csv.DictReader(handle)]


def _scalars(run_dir: Path) -> dict[str, list[tuple[int, float]]]:
    """Every scalar of a run directory's event files (all of them, a resumed run's too): tag -> (step, value)."""
    events = EventAccumulator(str(run_dir))
    events.Reload()
    return {tag: [(e.step, e.value) for e in events.Scalars(tag)] for tag in events.Tags()["scalars"]}


def test_training_csv_gets_a_row_per_update_while_the_run_goes_on(tmp_path: Path) -> None:
    """With checkpoint_interval 0 (a checkpoint only at the end) the log still grows by one flushed row per update:
    read by another reader before each update, it holds every update done so far."""
    trainer = Trainer(_config("run.checkpoint_interval=0"), tmp_path)
    path, run_update, seen = tmp_path / "training.csv", trainer.train_update, []

    def update_and_read() -> dict[str, float]:
        seen.append([row["step"] for row in _rows(path)])
        return run_update()

    trainer.train_update = update_and_read  # type: ignore[method-assign]
    trainer.train()
    assert seen == [[str(64 * u) for u in range(1, done + 1)] for done in range(6)]
    assert [row["step"] for row in _rows(path)] == [str(64 * u) for u in range(1, 7)]


@pytest.mark.slow
def test_an_extended_run_resumes_exactly_and_its_schedules_go_on_from_final(tmp_path: Path) -> None:
    """A finished 3-update run lengthened to 6: killed right after the extension (its newest checkpoint still says
    3 updates) and again after update 5, it ends as the same extension run uninterrupted: weights, training.csv,
    learning rates. The learning rate, which had decayed to its final value at update 3, stays there."""
    config = _config("run.total_steps=192", "run.checkpoint_interval=2", "run.keep_checkpoints=0")
    lengthen = ["run.total_steps=384"]
    Trainer(config, tmp_path / "a").train()
    uninterrupted = Trainer.resume(tmp_path / "a", lengthen)
    assert uninterrupted.extension["num_updates"] == [3, 6] and not uninterrupted.finished
    history = uninterrupted.train()
    assert [m["update"] for m in history] == [4, 5, 6]
    assert [m["charts/learning_rate"] for m in history] == pytest.approx([1e-4] * 3)

    Trainer(config, tmp_path / "b").train()
    killed = Trainer.resume(tmp_path / "b", lengthen)
    kill_after(killed, 3)  # before its first update: the newest checkpoint is the 3-update run's
    with pytest.raises(KeyboardInterrupt):
        killed.train()
    killed = Trainer.resume(tmp_path / "b")  # config.yaml says 6 updates, the checkpoint 3: extended at update 3
    assert killed.extensions == [(3, 3)] and killed.extension is None
    kill_after(killed, 5)
    with pytest.raises(KeyboardInterrupt):
        killed.train()
    _next_second()
    resumed = Trainer.resume(tmp_path / "b")  # from update 4's checkpoint, which holds the extension
    assert (resumed.update, resumed.extensions) == (4, [(3, 3)])
    assert [m["charts/learning_rate"] for m in resumed.train()] == pytest.approx([1e-4] * 2)
    _assert_same_weights(uninterrupted, resumed)
    assert _rows(tmp_path / "a" / "training.csv") == _rows(tmp_path / "b" / "training.csv")
    assert [r["step"] for r in _rows(tmp_path / "b" / "training.csv")] == [str(64 * u) for u in range(1, 7)]
    info = json.loads((tmp_path / "b" / "run_info.json").read_text())
    assert [e["update"] for e in info["extended"]] == [3] and info["finished"]["update"] == 6
    # the checkpoints from before the extension still load, for evaluation and for the trainer
    from agents.policy.checkpoint import load_policy

    assert load_policy(tmp_path / "b", tmp_path / "b" / "checkpoints" / "update_0000002.pt").update == 2


def test_resume_names_the_keys_of_a_config_that_changed_since_the_checkpoint(tmp_path: Path) -> None:
    Trainer(_config("run.total_steps=128"), tmp_path).train()
    saved = yaml.safe_load((tmp_path / "config.yaml").read_text())
    saved["ppo"]["gamma"] = 0.9
    (tmp_path / "config.yaml").write_text(yaml.safe_dump(saved))
    with pytest.raises(ValueError, match=r"different config than the run's config.yaml \(differing: ppo.gamma\)"):
        Trainer.resume(tmp_path)
    saved["ppo"]["gamma"], saved["run"]["total_steps"] = 0.99, 64  # shorter than the checkpoint's run
    (tmp_path / "config.yaml").write_text(yaml.safe_dump(saved))
    with pytest.raises(ValueError, match="a run can be extended, not shortened"):
        Trainer.resume(tmp_path)


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
    kill_after(killed, 4)
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
    # an episode's first step has no previous action (-1, an all-zero one-hot, as in the authors' code) and reward 0
    assert (buffer.inputs["previous_action"][starts] == -1).all() and not buffer.inputs["previous_reward"][starts].any()
    one_hot = one_hot_actions(buffer.inputs["previous_action"][starts], trainer.model.action_dims)
    assert one_hot.shape[-1] == sum(trainer.model.action_dims) and not one_hot.any()
    continuing = ~starts
    continuing[:, 0] = False
    prev_action = torch.full_like(buffer.actions, -1)
    prev_action[:, 1:] = buffer.actions[:, :-1]
    assert torch.equal(buffer.inputs["previous_action"][continuing], prev_action[continuing])
    assert buffer.memory_states[continuing].abs().sum(-1).gt(0).all()

    for max_length in (None, 5):
        sequences = split_sequences(done.numpy(), max_length)
        batch = pad_sequences(sequences, np.arange(len(sequences)))
        inputs = buffer.gather(batch.step_index)
        with torch.no_grad():
            logits, values, _ = trainer.model.evaluate(
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
    assert train_script.main(["--resume", str(run_dir), "--set", "ppo.gamma=0.9"]) == 2
    assert "ppo.gamma cannot be changed on resume" in capsys.readouterr().err
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
    inputs = buffer.gather(batch.step_index)
    with torch.no_grad(), trainer.autocast():
        logits, values, _ = trainer.model.evaluate(
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

    from agents.runtime.allocator import keep_freed_memory

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


def test_helm_outputs_are_cached_once_and_the_branch_never_trains(tmp_path: Path) -> None:
    """The HELM features stored in the buffer equal a fresh forward of the frozen branch over each episode (from
    its start: the memory was cleared there), and an update leaves the branch untouched and without gradients."""
    trainer = Trainer(_config("model.memory=none", *HELM, "env.options.delay=5", "run.worker_steps=24"), tmp_path)
    before = [p.clone() for p in trainer.helm.parameters()]
    trainer.train_update()
    trainer._collect_rollout()
    buffer = trainer.buffer
    checked = 0
    for worker in range(buffer.workers):
        starts = (buffer.episode_step[worker] == 0).nonzero().flatten().tolist()
        for first, end in zip(starts, starts[1:], strict=False):  # whole episodes inside the rollout
            fresh = trainer.helm.recompute_episode(buffer.inputs["image"][worker, first:end])
            torch.testing.assert_close(buffer.inputs["helm"][worker, first:end], fresh, atol=1e-4, rtol=1e-4)
            checked += 1
    assert checked >= 8
    for param, old in zip(trainer.helm.parameters(), before, strict=True):
        assert torch.equal(param, old) and param.grad is None and not param.requires_grad
    assert not any(p is q for p in trainer.helm.parameters() for q in trainer.model.parameters())
