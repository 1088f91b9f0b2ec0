"""PPO on padded sequences: GAE, the clipped losses and the update loop.

Padding never reaches a loss. The model returns outputs for the real steps of a minibatch only (the mask selects
them right after the memory module), so every mean below is the masked mean ``sum(mask * x) / sum(mask)`` of the
paper, computed directly over the real steps; advantage normalisation and all logged statistics included.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from agents.config import PPOConfig
from agents.policy.models import ActorCritic, log_probs_and_entropy
from agents.training.buffer import RolloutBuffer
from agents.training.sequences import Sequences, minibatch_ids, pad_sequences


def gae_advantages(
    rewards: Tensor, values: Tensor, terminated: Tensor, last_values: Tensor, gamma: float, gae_lambda: float
) -> Tensor:
    """Generalised advantage estimates of a (workers, steps) rollout.

    ``last_values`` (workers,) bootstraps across the end of the rollout; an episode end (terminated) cuts both the
    bootstrap and the recursion, so no advantage leaks from one episode into the next.
    """
    advantages = torch.zeros_like(rewards)
    running = torch.zeros_like(last_values)
    next_values = last_values
    for t in reversed(range(rewards.shape[1])):
        alive = 1.0 - terminated[:, t].float()
        delta = rewards[:, t] + gamma * next_values * alive - values[:, t]
        running = delta + gamma * gae_lambda * alive * running
        advantages[:, t] = running
        next_values = values[:, t]
    return advantages


def normalize(advantages: Tensor) -> Tensor:
    """Zero mean, unit variance over the given (real) steps."""
    return (advantages - advantages.mean()) / (advantages.std(correction=0) + 1e-8)


@dataclass
class LossTerms:
    total: Tensor
    policy: Tensor
    value: Tensor
    entropy: Tensor
    approx_kl: Tensor
    clipfrac: Tensor


def ppo_loss(
    log_probs: Tensor,
    old_log_probs: Tensor,
    advantages: Tensor,
    entropy: Tensor,
    values: Tensor,
    old_values: Tensor,
    returns: Tensor,
    clip: float,
    clip_value_loss: bool,
    value_coef: float,
    entropy_coef: float,
) -> LossTerms:
    """Clipped surrogate with one ratio per action dimension (log-probs (N, branches), the advantage repeated across
    branches), (clipped) squared value error and the entropy bonus (already summed over branches), averaged over the
    N real steps."""
    log_ratio = log_probs - old_log_probs
    ratio = log_ratio.exp()
    advantage = advantages.unsqueeze(-1)
    surrogate = torch.min(ratio * advantage, ratio.clamp(1.0 - clip, 1.0 + clip) * advantage)
    policy_loss = -surrogate.mean()
    value_error = (values - returns).square()
    if clip_value_loss:
        clipped_values = old_values + (values - old_values).clamp(-clip, clip)
        value_error = torch.max(value_error, (clipped_values - returns).square())
    value_loss = value_error.mean()
    entropy_mean = entropy.mean()
    total = policy_loss + value_coef * value_loss - entropy_coef * entropy_mean
    with torch.no_grad():
        approx_kl = ((ratio - 1.0) - log_ratio).mean()
        clipfrac = ((ratio - 1.0).abs() > clip).float().mean()
    return LossTerms(total, policy_loss, value_loss, entropy_mean, approx_kl, clipfrac)


def ppo_update(
    model: ActorCritic,
    optimizer: torch.optim.Optimizer,
    buffer: RolloutBuffer,
    sequences: Sequences,
    config: PPOConfig,
    clip: float,
    entropy_coef: float,
    rng: np.random.Generator,
    autocast: Callable[[], contextlib.AbstractContextManager] = contextlib.nullcontext,
) -> dict[str, float]:
    """Epochs of minibatch updates over whole sequences; returns the step-weighted means of the loss terms.

    Raises ``FloatingPointError`` (before touching the weights) when a loss or the gradient norm is not finite.
    """
    episode_steps = buffer.flat(buffer.episode_step)
    actions, old_log_probs = buffer.flat(buffer.actions), buffer.flat(buffer.log_probs)
    old_values, returns = buffer.flat(buffer.values), buffer.flat(buffer.returns)
    advantages = buffer.flat(buffer.advantages)
    reconstruct = config.reconstruction_coef > 0
    # the auxiliary losses by their logged names, with their weights (agents.policy.models.ActorCritic.evaluate)
    auxiliary_coefs = {"reconstruction_loss": config.reconstruction_coef, "ground_truth_loss": config.ground_truth_coef}
    ground_truth = None if buffer.ground_truth is None else buffer.flat(buffer.ground_truth)
    if config.advantage_normalization == "batch":
        advantages = normalize(advantages)
    totals: dict[str, Tensor | float] = {}
    steps_seen = 0
    for epoch in range(config.epochs):
        for ids in minibatch_ids(len(sequences), config.minibatches, rng):
            batch = pad_sequences(sequences, ids, device=buffer.device)
            index = batch.step_index
            with autocast():
                filled = filled_index(index)
                logits, values, auxiliary = model.evaluate(
                    buffer.gather(filled),
                    buffer.memory_records(batch.start_index, batch.mask.shape[1]),
                    batch.mask,
                    rows(episode_steps, index),
                    reconstruct,
                    None if ground_truth is None else rows(ground_truth, index),
                )
            log_probs, entropy = log_probs_and_entropy(logits, rows(actions, index))
            minibatch_advantages = rows(advantages, index)
            if config.advantage_normalization == "minibatch":
                minibatch_advantages = normalize(minibatch_advantages)
            loss = ppo_loss(
                log_probs,
                rows(old_log_probs, index),
                minibatch_advantages,
                entropy,
                values,
                rows(old_values, index),
                rows(returns, index),
                clip,
                config.clip_value_loss,
                config.value_coef,
                entropy_coef,
            )
            total = loss.total
            for name, value in auxiliary.items():
                total = total + auxiliary_coefs[name] * value
            optimizer.zero_grad(set_to_none=True)
            total.backward()
            grad_norm = torch.nn.utils.clip_grad_norm_(model.parameters(), config.max_grad_norm, foreach=True)
            if not torch.isfinite(torch.stack((total.detach(), grad_norm))).all():  # one device sync
                raise FloatingPointError(f"non-finite loss or gradient in epoch {epoch}: {_describe(loss, grad_norm)}")
            optimizer.step()
            terms = {
                "policy_loss": loss.policy,
                "value_loss": loss.value,
                "entropy": loss.entropy,
                "approx_kl": loss.approx_kl,
                "clipfrac": loss.clipfrac,
                "grad_norm": grad_norm,
            }
            terms.update(auxiliary)
            for name, value in terms.items():
                totals[name] = totals.get(name, 0.0) + value.detach() * batch.num_steps
            steps_seen += batch.num_steps
    return {name: float(total) / steps_seen for name, total in totals.items()}


def rows(tensor: Tensor, index: Tensor) -> Tensor:
    """``tensor[index]`` for an int64 index of rows. ``index_select`` copies whole rows at once: for the minibatch's
    images it is ~8x faster than advanced indexing, which goes element by element."""
    return tensor.index_select(0, index)


ROW_MULTIPLE = 8


def filled_index(index: Tensor, multiple: int = ROW_MULTIPLE) -> Tensor:
    """``index`` followed by copies of its first entry up to a multiple of ``multiple`` rows.

    A minibatch holds whole sequences, so its number of steps changes from one minibatch to the next, and oneDNN
    builds (and, once its cache is full, rebuilds) kernels for every new shape: ~250 builds per update of the
    MortarMayhemB-Grid benchmark, steadily. Rounded up to a multiple of 8, a few shapes recur and stay cached, for
    ~1.5% more rows. :meth:`ActorCritic.evaluate` keeps the filler rows out of the memory and the outputs."""
    filler = -index.shape[0] % multiple
    return torch.cat((index, index[:1].expand(filler))) if filler else index


def explained_variance(values: Tensor, returns: Tensor) -> float:
    """1 - Var(returns - values) / Var(returns); NaN when the returns do not vary."""
    variance = returns.var()
    return float("nan") if variance == 0 else float(1.0 - (returns - values).var() / variance)


def _describe(loss: LossTerms, grad_norm: Tensor) -> str:
    terms = ", ".join(
        f"{name} loss {float(getattr(loss, name).detach()):.4g}" for name in ("policy", "value", "entropy")
    )
    return f"{terms}, gradient norm {float(grad_norm):.4g}"
