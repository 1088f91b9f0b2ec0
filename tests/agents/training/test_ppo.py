"""GAE, the clipped losses with per-branch ratios, masked statistics and the update's NaN guard."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch

from agents.config import ModelConfig, PPOConfig
from agents.policy.models import ActorCritic
from agents.training.buffer import RolloutBuffer
from agents.training.ppo import explained_variance, gae_advantages, normalize, ppo_loss, ppo_update
from agents.training.sequences import pad_sequences, split_sequences


def test_gae_stops_at_episode_ends_and_bootstraps_the_rollout_end() -> None:
    gamma, lam = 0.9, 0.8
    rewards = torch.tensor([[1.0, 0.0, 2.0, 0.5], [0.0, 0.0, 0.0, 1.0]])
    values = torch.tensor([[0.5, 0.2, 0.1, 0.3], [1.0, 2.0, 3.0, 4.0]])
    terminated = torch.tensor([[False, True, False, False], [False, False, False, True]])
    last = torch.tensor([0.7, 9.0])
    advantages = gae_advantages(rewards, values, terminated, last, gamma, lam)

    def reference(w: int, t: int) -> float:
        """Sum over k of (gamma lambda)^k delta_{t+k}, up to and including the step that ends the episode."""
        total, factor = 0.0, 1.0
        for k in range(t, 4):
            next_value = 0.0 if terminated[w, k] else float(last[w] if k == 3 else values[w, k + 1])
            total += factor * (float(rewards[w, k]) + gamma * next_value - float(values[w, k]))
            if terminated[w, k]:
                break
            factor *= gamma * lam
        return total

    expected = torch.tensor([[reference(w, t) for t in range(4)] for w in range(2)])
    torch.testing.assert_close(advantages, expected)
    assert advantages[1, 3] == pytest.approx(1.0 - 4.0)  # the bootstrap value 9.0 is after an episode end: unused


def _loss(**overrides: object):
    n = 6
    g = torch.Generator().manual_seed(0)
    args = {
        "log_probs": torch.randn(n, 2, generator=g) * 0.3 - 1.0,
        "old_log_probs": torch.full((n, 2), -1.0),
        "advantages": torch.randn(n, generator=g),
        "entropy": torch.rand(n, generator=g),
        "values": torch.randn(n, generator=g),
        "old_values": torch.randn(n, generator=g),
        "returns": torch.randn(n, generator=g),
        "clip": 0.2,
        "clip_value_loss": True,
        "value_coef": 0.25,
        "entropy_coef": 0.01,
    }
    args.update(overrides)
    return ppo_loss(**args), args


def test_policy_loss_has_one_ratio_per_action_dimension() -> None:
    loss, a = _loss()
    ratio = (a["log_probs"] - a["old_log_probs"]).exp()  # (N, 2): not the joint ratio of the product
    adv = a["advantages"][:, None].expand(-1, 2)
    expected = -torch.min(ratio * adv, ratio.clamp(0.8, 1.2) * adv).mean()
    torch.testing.assert_close(loss.policy, expected)
    joint = ratio.prod(-1)
    joint_loss = -torch.min(joint * a["advantages"], joint.clamp(0.8, 1.2) * a["advantages"]).mean()
    assert not torch.isclose(loss.policy, joint_loss)
    torch.testing.assert_close(loss.clipfrac, ((ratio - 1).abs() > 0.2).float().mean())
    log_ratio = a["log_probs"] - a["old_log_probs"]
    torch.testing.assert_close(loss.approx_kl, ((ratio - 1) - log_ratio).mean())


def test_value_loss_clipping_and_total() -> None:
    def two_steps(values: list[float], returns: list[float], **overrides: object):
        """Two steps with old values 0, zero advantages and log-ratios, entropies 1 and 3."""
        loss, _ = _loss(
            values=torch.tensor(values),
            old_values=torch.zeros(2),
            returns=torch.tensor(returns),
            advantages=torch.zeros(2),
            log_probs=torch.zeros(2, 2),
            old_log_probs=torch.zeros(2, 2),
            entropy=torch.tensor([1.0, 3.0]),
            **overrides,
        )
        return loss

    loss = two_steps([1.0, 0.0], [0.0, 1.0])
    # step 0: unclipped error 1, clipped value 0.2 -> error 0.04; the max keeps 1.
    # step 1: unclipped 1, clipped value 0 -> error 1.
    assert float(loss.value) == pytest.approx(1.0)
    loss = two_steps([0.5, 0.0], [1.0, 0.0])
    assert float(loss.value) == pytest.approx((0.8**2 + 0.0) / 2)  # clipped (0.2 from 1.0) is the larger error
    unclipped = two_steps([0.5, 0.0], [1.0, 0.0], clip_value_loss=False)
    assert float(unclipped.value) == pytest.approx(0.5**2 / 2)
    assert float(unclipped.total) == pytest.approx(0.0 + 0.25 * 0.125 - 0.01 * 2.0)


def test_real_step_means_equal_masked_means_of_the_padded_layout() -> None:
    """The losses over real steps equal sum(mask * L) / sum(mask) over the padded (S, P) layout, and the
    advantage normalisation of a padded minibatch uses the real steps only."""
    terminated = np.zeros((2, 9), dtype=bool)
    terminated[0, [1, 6]] = True
    sequences = split_sequences(terminated, None)
    batch = pad_sequences(sequences, np.arange(len(sequences)))
    mask = batch.mask.float()
    g = torch.Generator().manual_seed(1)
    flat_adv = torch.randn(18, generator=g) * 3 + 1
    flat_err = torch.rand(18, generator=g)
    padded_adv = torch.full(mask.shape, 1e6)  # garbage in the padding must not matter
    padded_adv[batch.mask] = flat_adv[batch.step_index]
    padded_err = torch.full(mask.shape, -7.0)
    padded_err[batch.mask] = flat_err[batch.step_index]

    masked_mean = (mask * padded_adv).sum() / mask.sum()
    masked_std = ((mask * (padded_adv - masked_mean) ** 2).sum() / mask.sum()).sqrt()
    expected = (padded_adv - masked_mean) / (masked_std + 1e-8)
    torch.testing.assert_close(normalize(flat_adv[batch.step_index]), expected[batch.mask])
    torch.testing.assert_close(flat_err[batch.step_index].mean(), (mask * padded_err).sum() / mask.sum())
    assert batch.mask.numel() > batch.num_steps  # this layout does have padding


def test_explained_variance() -> None:
    returns = torch.tensor([1.0, 2.0, 3.0, 4.0])
    assert explained_variance(returns, returns) == pytest.approx(1.0)
    assert explained_variance(torch.zeros(4), returns) == pytest.approx(0.0)
    assert np.isnan(explained_variance(torch.zeros(4), torch.ones(4)))


def _filled_buffer(model: ActorCritic, workers: int = 3, steps: int = 8) -> RolloutBuffer:
    g = torch.Generator().manual_seed(5)
    buffer = RolloutBuffer(workers, steps, model.inputs, len(model.action_dims), model.state_shape, "cpu")
    buffer.inputs["image"].copy_(torch.randint(0, 256, buffer.inputs["image"].shape, generator=g, dtype=torch.uint8))
    buffer.terminated[:, 3] = True
    buffer.actions.copy_(torch.randint(0, 2, buffer.actions.shape, generator=g))
    buffer.log_probs.fill_(-0.7)
    buffer.values.copy_(torch.randn(workers, steps, generator=g))
    buffer.advantages.copy_(torch.randn(workers, steps, generator=g))
    buffer.returns.copy_(buffer.advantages + buffer.values)
    return buffer


def _small_gru_setup() -> tuple[ActorCritic, torch.optim.Optimizer, RolloutBuffer]:
    """A seeded small GRU model on 36x36 images, its optimizer and a filled rollout buffer."""
    torch.manual_seed(0)
    space = gym.spaces.Box(0, 255, (36, 36, 3), np.uint8)
    model = ActorCritic(space, gym.spaces.Discrete(2), ModelConfig(memory="gru", memory_size=8, hidden_size=8))
    return model, torch.optim.AdamW(model.parameters(), lr=1e-3), _filled_buffer(model)


def test_update_changes_weights_and_reports_statistics() -> None:
    model, optimizer, buffer = _small_gru_setup()
    before = [p.detach().clone() for p in model.parameters()]
    config = PPOConfig(epochs=2, minibatches=2)
    stats = ppo_update(
        model,
        optimizer,
        buffer,
        split_sequences(buffer.terminated.numpy(), None),
        config,
        0.2,
        0.01,
        np.random.default_rng(0),
    )
    assert set(stats) == {"policy_loss", "value_loss", "entropy", "approx_kl", "clipfrac", "grad_norm"}
    assert all(np.isfinite(v) for v in stats.values())
    assert any(not torch.equal(b, p) for b, p in zip(before, model.parameters(), strict=True))


def test_non_finite_loss_stops_before_touching_the_weights() -> None:
    model, optimizer, buffer = _small_gru_setup()
    buffer.returns[1, 2] = float("nan")
    before = [p.detach().clone() for p in model.parameters()]
    sequences = split_sequences(buffer.terminated.numpy(), None)
    with pytest.raises(FloatingPointError, match="non-finite loss or gradient"):
        ppo_update(model, optimizer, buffer, sequences, PPOConfig(minibatches=1), 0.2, 0.01, np.random.default_rng(0))
    assert all(torch.equal(b, p) for b, p in zip(before, model.parameters(), strict=True))
