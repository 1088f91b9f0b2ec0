"""The ground-truth estimation loss (``ppo.ground_truth_coef``): the endless environments' ``info['ground_truth']``
reaches the buffer aligned with the observation each decision acted on, the head's loss is its mean squared error
and trains the memory, a run on an environment without ground truth is refused, and a run with the head trains,
checkpoints, evaluates and is counted by the sweep."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch
from torch.nn import functional as F

import envs
from agents.config import config_from_dict, load_config
from agents.experiments.dry_run import parameter_count
from agents.experiments.planning import load_panel
from agents.policy.actor import Actor
from agents.policy.checkpoint import build_agent, ground_truth_size, load_policy
from agents.policy.models import ActorCritic
from agents.training.sequences import pad_sequences, split_sequences
from agents.training.trainer import Trainer

ROOT = Path(__file__).resolve().parents[3]
ENDLESS = ["Endless-MortarMayhem-v0", "Endless-MysteryPath-v0", "Endless-SearingSpotlights-v0"]


def _config(env_id: str, *overrides: str):
    raw = {
        "env": {"id": env_id},
        "model": {
            "memory": "trxl",
            "hidden_size": 32,
            "trxl": {"layers": 1, "heads": 2, "dim": 32, "memory_length": 8},
        },
        "ppo": {"epochs": 2, "minibatches": 2, "ground_truth_coef": 1.0, "learning_rate": {"initial": 1.0e-3}},
        "run": {"total_steps": 1280, "workers": 4, "worker_steps": 32, "progress_bar": False, "torch_threads": 1},
        "eval": {"interval": 0},
    }
    return config_from_dict(raw, list(overrides))


@pytest.mark.parametrize("env_id", ENDLESS)
def test_each_decision_carries_the_ground_truth_of_the_observation_it_acts_on(env_id: str) -> None:
    """Against a single environment replaying each slot's episode (its seed, then its actions so far): at every
    decision the target of slot k is that environment's info['ground_truth'] where its observation is the one the
    policy saw, across episode starts too."""
    config = _config(env_id, "run.workers=3")
    core = envs.make_core(env_id, 3)
    size = ground_truth_size(config, core)
    assert size == core.ground_truth_space.shape[0]
    model, _ = build_agent(config, core)
    assert model.ground_truth_size == size
    assert Actor(core, model, config, torch.Generator()).decide().ground_truth is None  # evaluation: no targets
    actor = Actor(core, model, config, torch.Generator().manual_seed(0), ground_truth=True)
    counter = iter(range(10**6))
    actor.start([next(counter) for _ in range(3)], seed_source=lambda n: [next(counter) for _ in range(n)])
    reference = gym.make(env_id)
    discrete = isinstance(reference.action_space, gym.spaces.Discrete)
    distinct = set()
    for _ in range(24):
        decision = actor.decide()
        assert decision.ground_truth.shape == (3, size) and decision.ground_truth.dtype == torch.float32
        for k in range(3):
            observation, info = reference.reset(seed=actor.memory.seeds[k])
            for action in actor.memory.actions[k]:
                observation, _, _, _, info = reference.step(int(action[0]) if discrete else action)
            np.testing.assert_array_equal(decision.inputs["image"][k].numpy(), observation)
            np.testing.assert_allclose(decision.ground_truth[k].numpy(), info["ground_truth"], rtol=1e-6)
            distinct.add(tuple(info["ground_truth"]))
        actor.advance(decision)
    assert len(distinct) > 1  # the targets move: the comparison is not of constants


def test_the_estimator_loss_is_the_mean_squared_error_of_its_head_and_trains_the_memory() -> None:
    """``evaluate(..., ground_truth=targets)`` returns the head's mean squared error on the real steps (padding and
    filler rows left out); its gradient reaches the memory and the encoder, not the policy. Without targets no
    auxiliary loss is returned, and a model without the head has none."""
    space = gym.spaces.Box(0, 255, (36, 36, 3), np.uint8)
    config = config_from_dict({"model": {"memory": "gru", "memory_size": 16, "hidden_size": 16}}).model
    torch.manual_seed(0)
    model = ActorCritic(space, gym.spaces.Discrete(3), config, ground_truth_size=3)
    assert ActorCritic(space, gym.spaces.Discrete(3), config).ground_truth_head is None
    mask = torch.tensor([[True, True, True, True], [True, True, False, False]])
    inputs = {"image": torch.randint(0, 256, (8, 36, 36, 3), dtype=torch.uint8)}  # 6 real steps, 2 filler rows
    targets = torch.rand(6, 3)
    start = torch.zeros(2, 1, 16)
    _, _, auxiliary = model.evaluate(inputs, start, mask, None, ground_truth=targets)
    assert list(auxiliary) == ["ground_truth_loss"]
    real = {"image": inputs["image"][:6]}
    output = model.memory.sequences(model.encode(real), start, mask)
    expected = F.mse_loss(model.ground_truth_head(output), targets)
    torch.testing.assert_close(auxiliary["ground_truth_loss"], expected)
    auxiliary["ground_truth_loss"].backward()
    assert model.memory.rnn.weight_ih_l0.grad.abs().sum() > 0
    assert model.image_encoder.convs[0].weight.grad.abs().sum() > 0
    assert model.policy_heads[0].weight.grad is None and model.value_head.weight.grad is None
    assert model.evaluate(inputs, start, mask)[2] == {}


def test_an_environment_without_ground_truth_is_refused_naming_the_key(tmp_path: Path) -> None:
    config = _config("MortarMayhem-Grid-v0")
    with pytest.raises(ValueError, match=r"ppo\.ground_truth_coef=1 .*MortarMayhem-Grid-v0 has none.*Endless-"):
        Trainer(config, tmp_path / "run")
    assert not (tmp_path / "run").exists() or not any((tmp_path / "run").iterdir())
    with pytest.raises(ValueError, match=r"ppo\.ground_truth_coef"):
        parameter_count(config)
    assert ground_truth_size(_config("MortarMayhem-Grid-v0", "ppo.ground_truth_coef=0"), None) == 0


@pytest.mark.slow
def test_training_lowers_the_ground_truth_loss_and_the_run_checkpoints_and_evaluates(tmp_path: Path) -> None:
    """10 updates on Endless Mortar Mayhem with the head alone weighted 1: the buffer holds each step's target, the
    loss is logged as losses/ground_truth_loss and falls (measured: 0.67 -> 0.08-0.15 over the 10 updates), the
    checkpoint loads back with its head for evaluation, and the sweep counts the head's parameters."""
    config = _config("Endless-MortarMayhem-v0", "run.checkpoint_interval=5")
    trainer = Trainer(config, tmp_path)
    history = trainer.train()
    losses = [m["losses/ground_truth_loss"] for m in history]
    assert len(losses) == 10 and losses[0] > 2 * np.mean(losses[-3:])
    buffer = trainer.buffer
    assert buffer.ground_truth.shape == (4, 32, 2)
    assert ((buffer.ground_truth >= 0) & (buffer.ground_truth <= 1)).all()  # the target tile / 5
    sequences = split_sequences(buffer.terminated_numpy(), None)
    batch = pad_sequences(sequences, np.arange(len(sequences)))
    flat = buffer.flat(buffer.ground_truth)[batch.step_index]
    assert flat.shape == (batch.num_steps, 2)
    policy = load_policy(tmp_path)
    assert policy.model.ground_truth_head is not None
    torch.testing.assert_close(policy.model.state_dict(), trainer.model.state_dict())
    assert parameter_count(config) == sum(p.numel() for p in trainer.model.parameters())


def test_the_jmlr_ground_truth_grid_is_the_endless_trxl_with_the_estimator() -> None:
    """configs/paper/jmlr_endless_ground_truth.yaml: 5 seeds of TrXL + ground truth on Endless Mortar Mayhem, with
    exactly the settings of jmlr_endless.yaml's TrXL runs there but for the estimator's weight."""
    panel = load_panel(ROOT / "configs" / "paper" / "jmlr_endless_ground_truth.yaml", root="runs")
    endless = load_panel(ROOT / "configs" / "paper" / "jmlr_endless.yaml", root="runs")
    (trxl,) = [
        run.config
        for run in endless.runs
        if run.config.method == "trxl" and run.config.task == "endless_mm" and run.config.run.seed == 0
    ]
    assert len(panel.runs) == 5 and {run.config.run.seed for run in panel.runs} == set(range(5))
    for run in panel.runs:
        config = run.config
        assert config.env.id == "Endless-MortarMayhem-v0" and config.ppo.ground_truth_coef == 0.1
        assert config.model == trxl.model and config.env.options == trxl.env.options
        ppo = {k: v for k, v in vars(config.ppo).items() if k != "ground_truth_coef"}
        assert ppo == {k: v for k, v in vars(trxl.ppo).items() if k != "ground_truth_coef"}
        assert config.run.total_steps == trxl.run.total_steps and config.eval == trxl.eval
    assert trxl.ppo.ground_truth_coef == 0.0
    assert load_config(ROOT / "configs" / "paper" / "jmlr_endless_ground_truth.yaml").ppo.ground_truth_coef == 0.1
