"""ProofOfMemory-v0: the cue is only in the first frame, so a memory-less policy is at chance by construction."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import envs
from envs.proof_of_memory import SIZE


def _episode(core: envs.BatchedCore, seed: int, actions: list[int]) -> tuple[list[np.ndarray], list[float], dict]:
    core.reset_slot(0, seed)
    frames, rewards, final = [core.observations()[0]], [], {}
    for action in actions:
        reward, terminated, finals = core.step(np.array([action]))
        rewards.append(float(reward[0]))
        frames.append(core.observations()[0])
        if terminated[0]:
            final = finals[0]
            break
    return frames, rewards, final


def _seeds_by_cue(delay: int) -> dict[int, int]:
    core = envs.make_core("ProofOfMemory-v0", 1, {"delay": delay})
    found: dict[int, int] = {}
    for seed in range(100):
        core.reset_slot(0, seed)
        found.setdefault(int(core.cue[0]), seed)
    return found


@pytest.mark.parametrize("delay", [1, 4, 9])
def test_only_the_first_frame_differs_between_cues(delay: int) -> None:
    core = envs.make_core("ProofOfMemory-v0", 1, {"delay": delay})
    seeds = _seeds_by_cue(delay)
    left, _, _ = _episode(core, seeds[0], [0] * (delay + 1))
    right, _, _ = _episode(core, seeds[1], [0] * (delay + 1))
    assert len(left) == len(right) == delay + 2  # reset frame + delay + 1 steps (the last frame is terminal)
    assert not np.array_equal(left[0], right[0])
    for a, b in zip(left[1:], right[1:], strict=True):
        np.testing.assert_array_equal(a, b)
    half = SIZE // 2
    assert (left[0][:, :half] == 255).all() and (left[0][:, half:] == 0).all()
    assert (right[0][:, half:] == 255).all() and (right[0][:, :half] == 0).all()
    query = left[delay]
    assert (query[half - 3 : half + 3] == 255).all() and query.sum() == 6 * SIZE * 3 * 255


@pytest.mark.parametrize("delay", [1, 4])
def test_reward_and_success_depend_on_the_action_at_the_query(delay: int) -> None:
    core = envs.make_core("ProofOfMemory-v0", 1, {"delay": delay})
    for cue, seed in _seeds_by_cue(delay).items():
        # earlier actions are ignored: the opposite action before the query changes nothing
        _, rewards, final = _episode(core, seed, [1 - cue] * delay + [cue])
        assert rewards == [0.0] * delay + [1.0]
        assert final == {"reward": 1.0, "length": delay + 1, "success": 1}
        _, rewards, final = _episode(core, seed, [cue] * delay + [1 - cue])
        assert rewards[-1] == 0.0 and final["success"] == 0 and final["length"] == delay + 1


def test_cues_are_balanced_and_seeded() -> None:
    core = envs.make_core("ProofOfMemory-v0", 64)
    for k in range(64):
        core.reset_slot(k, 1000 + k)
    cues = core.cue.copy()
    assert 0.3 < cues.mean() < 0.7
    single = envs.make_core("ProofOfMemory-v0", 1)
    for k in (0, 17, 63):
        single.reset_slot(0, 1000 + k)
        assert single.cue[0] == cues[k]


def test_options_are_validated() -> None:
    with pytest.raises(ValueError, match="delay"):
        envs.make_core("ProofOfMemory-v0", 1, {"delay": 0})
    env = gym.make("ProofOfMemory-v0")
    obs, _ = env.reset(seed=3)
    assert obs.shape == (SIZE, SIZE, 3) and obs.dtype == np.uint8
    env.close()
