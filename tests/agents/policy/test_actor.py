"""The acting loop: frame stacks (online, and rebuilt from the buffer), grayscale, frame skip, slot memory."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

import envs
from agents.config import config_from_dict
from agents.policy.actor import Actor, grayscale
from agents.policy.checkpoint import build_agent
from agents.training.trainer import Trainer


def _config(env_id: str, *overrides: str):
    raw = {
        "env": {"id": env_id},
        "model": {"memory": "none", "hidden_size": 16, "vector_encoder_size": 8},
        "ppo": {"epochs": 1, "minibatches": 2},
        "run": {"total_steps": 512, "workers": 4, "worker_steps": 16, "progress_bar": False, "torch_threads": 1},
    }
    return config_from_dict(raw, list(overrides))


def _actor(config, seeds_from: int = 0) -> Actor:
    core = envs.make_core(config.env.id, config.run.workers, config.env.options)
    model, helm = build_agent(config, core)
    generator = torch.Generator().manual_seed(0)
    actor = Actor(core, model, config, generator, helm)
    counter = iter(range(seeds_from, 10**6))
    actor.start([next(counter) for _ in range(core.num_envs)], seed_source=lambda n: [next(counter) for _ in range(n)])
    return actor


def _observation(core, k: int, grey: bool) -> dict[str, np.ndarray]:
    raw = core.observations()
    arrays = raw if isinstance(raw, dict) else {"visual_observation": raw}
    image = arrays["visual_observation"][k]
    out = {"image": grayscale(image) if grey else image}
    if "vector_observation" in arrays:
        out["vector"] = arrays["vector_observation"][k].reshape(-1)
    return out


@pytest.mark.parametrize(("stack", "grey"), [(4, False), (16, True)])
def test_stacks_hold_only_the_current_episode(stack: int, grey: bool) -> None:
    """Against a slot-by-slot reference: the stack is the episode's last k observations, oldest first, filled with
    copies of its first observation at the start; nothing of a previous episode appears after a reset, also when
    slots reset in the middle (MortarMayhemB-Grid: short episodes, image and vector observations)."""
    config = _config("MortarMayhemB-Grid-v0", f"model.frame_stack={stack}", f"model.grayscale={str(grey).lower()}")
    actor = _actor(config)
    histories = [[_observation(actor.core, k, grey)] for k in range(actor.num_envs)]
    resets = 0
    for _ in range(40):
        inputs = actor.inputs()
        for k, history in enumerate(histories):
            window = ([history[0]] * stack + history)[-stack:]
            for name in ("image", "vector"):
                expected = np.concatenate([frame[name] for frame in window], axis=-1)
                assert np.array_equal(inputs[name][k].numpy(), expected), (name, k, len(history))
        outcome = actor.advance(actor.decide())
        for k in range(actor.num_envs):
            if outcome.terminated[k]:
                histories[k] = []
                resets += 1
            histories[k].append(_observation(actor.core, k, grey))
    assert resets >= 8  # episodes ended in the middle of the run, in several slots


@pytest.mark.parametrize("overrides", [("model.frame_stack=4",), ("model.frame_stack=16", "model.grayscale=true")])
def test_rebuilt_minibatch_stacks_equal_what_the_policy_saw(tmp_path: Path, overrides: tuple[str, ...]) -> None:
    """The buffer keeps one observation per step; the stacks it rebuilds for any steps (in any order, across the
    start of the rollout) are the stacks the policy acted on."""
    config = _config("MortarMayhemB-Grid-v0", *overrides)
    trainer = Trainer(config, tmp_path)
    for _ in range(2):  # the second rollout starts in the middle of episodes: its stacks reach into the history
        seen: list[dict[str, torch.Tensor]] = []
        decide = trainer.actor.decide

        def recording_decide(greedy: bool = False, decide=decide, seen=seen):
            decision = decide(greedy)
            seen.append({name: tensor.clone() for name, tensor in decision.inputs.items()})
            return decision

        trainer.actor.decide = recording_decide  # type: ignore[method-assign]
        trainer._collect_rollout()
        trainer.actor.decide = decide  # type: ignore[method-assign]
        buffer = trainer.buffer
        index = torch.from_numpy(np.random.default_rng(0).permutation(buffer.size))
        gathered = buffer.gather(index)
        for name in ("image", "vector"):
            expected = torch.stack([step[name] for step in seen], dim=1).reshape(buffer.size, -1)
            assert torch.equal(gathered[name].reshape(buffer.size, -1), expected[index]), name
    k = config.model.frame_stack
    frame = 84 * 84 * (1 if config.model.grayscale else 3) + 180 * 4
    history = (k - 1) * frame * buffer.workers // buffer.size
    assert buffer.bytes_per_step == frame + history + 8  # one observation per step (+ the episode step), not k


def test_grayscale_is_itu_601_luma() -> None:
    pixels = np.array([[255, 0, 0], [0, 255, 0], [0, 0, 255], [255, 255, 255], [0, 0, 0], [12, 200, 77]], np.uint8)
    luma = grayscale(pixels)
    assert luma.dtype == np.uint8 and luma.shape == (6, 1)
    assert luma[:, 0].tolist() == [76, 150, 29, 255, 0, 130]
    exact = pixels @ np.array([0.299, 0.587, 0.114])
    assert np.abs(luma[:, 0] - exact).max() <= 0.5 + 1e-9


@pytest.mark.parametrize("env_id", ["MortarMayhem-Grid-v0", "SearingSpotlights-v0"])
def test_frame_skip_repeats_the_action_sums_rewards_and_stops_at_the_episode_end(env_id: str) -> None:
    """One decision with env.frame_skip=k is k steps of a single environment with that action (fewer when the
    episode ends inside the repeat); the rewards are summed and the slot starts its next episode."""
    skip = 3
    config = _config(env_id, f"env.frame_skip={skip}", "run.workers=3")
    actor = _actor(config)
    singles = [envs.make_core(env_id, 1) for _ in range(3)]
    for k, single in enumerate(singles):
        single.reset_slot(0, seed=k)
    next_seed = 3
    ended = 0
    for _ in range(60):
        decision = actor.decide()
        outcome = actor.advance(decision)
        actions = decision.actions.numpy()
        for k, single in enumerate(singles):
            action = actions[k : k + 1, 0] if actor.discrete else actions[k : k + 1]
            total, done = 0.0, False
            for _ in range(skip):
                reward, terminated, _ = single.step(action)
                total += float(reward[0])
                if terminated[0]:
                    done = True
                    break
            assert outcome.terminated[k].item() == done
            assert outcome.rewards[k].item() == pytest.approx(total, abs=1e-6)
            if done:
                ended += 1
                single.reset_slot(0, seed=next_seed)
                next_seed += 1
            assert np.array_equal(single.observations()[0], actor.core.observations()[k])
    assert ended >= 1


def test_evaluation_slots_stop_at_their_episode_end() -> None:
    config = _config("ProofOfMemory-v0", "run.workers=3")
    actor = _actor(config)
    actor.start([5, 6, 7])  # no seed source: evaluation
    lengths = []
    while actor.active.any():
        before = actor.active.copy()
        outcome = actor.advance(actor.decide())
        lengths.append(int(before.sum()))
        assert not (outcome.terminated.numpy() & ~before).any()  # a stopped slot is not stepped again
    assert actor.core.seeds == [5, 6, 7] and lengths[-1] >= 1
