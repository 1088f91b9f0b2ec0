"""What clients written for memory-gym read on the object ``gymnasium.make(id)`` returns (no ``.unwrapped``):
episodic-transformer-memory-ppo reads ``env.max_episode_steps``, neroRL ``max_episode_steps``,
``has_ground_truth_info`` and ``ground_truth_space`` (ecosystem.md, "Clients written for memory-gym").

gymnasium 1.x wrappers do not forward attributes, so the ids are registered without gymnasium's order-enforcing and
passive-checker wrappers: ``gymnasium.make`` returns the environment itself. It keeps refusing a step (and a render)
before the first reset on its own, and gymnasium's full checker passes on what ``make`` returns.
"""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.error import ResetNeeded
from gymnasium.utils.env_checker import check_env

import envs  # noqa: F401  (registers the ids)
from envs import ENV_IDS
from envs.core import MemoryGymEnv

ALL_IDS = list(ENV_IDS)
# The size of info['ground_truth'] of the endless ids (environments.md: EMM tile (x, y), EMP a direction of 3,
# ESS agent and coin positions); every other id has no ground truth.
GROUND_TRUTH_SIZES = {"Endless-MortarMayhem-v0": 2, "Endless-MysteryPath-v0": 3, "Endless-SearingSpotlights-v0": 4}


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_make_returns_the_environment_itself(env_id: str) -> None:
    env = gym.make(env_id)
    assert type(env) is MemoryGymEnv and env.unwrapped is env
    assert env.spec is not None and env.spec.id == env_id
    env.close()


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_client_attributes_are_plain_reads(env_id: str) -> None:
    env = gym.make(env_id)
    size = GROUND_TRUTH_SIZES.get(env_id)
    assert env.has_ground_truth_info is (size is not None)
    if size is None:
        assert env.ground_truth_space is None  # what neroRL substitutes when has_ground_truth_info is False
    else:
        assert env.ground_truth_space == gym.spaces.Box(0.0, 1.0, (size,), np.float32)
    # as in memory-gym, max_episode_steps exists from the first reset on
    assert not hasattr(env, "max_episode_steps")
    with pytest.raises(AttributeError, match="call reset first"):
        env.max_episode_steps  # noqa: B018
    _, info = env.reset(seed=3)
    assert type(env.max_episode_steps) is int and env.max_episode_steps == int(env.core.max_episode_steps[0])
    assert env.max_episode_steps == -1 if env_id.startswith("Endless") else env.max_episode_steps > 0
    if size is None:
        assert "ground_truth" not in info
    else:
        assert env.ground_truth_space.contains(np.asarray(info["ground_truth"], dtype=np.float32))
    env.close()


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_step_and_render_before_reset_are_refused(env_id: str) -> None:
    env = gym.make(env_id, render_mode="rgb_array")
    with pytest.raises(ResetNeeded, match="call reset first"):
        env.step(env.action_space.sample())
    with pytest.raises(ResetNeeded, match="call reset first"):
        env.render()
    env.reset(seed=0)
    obs, *_ = env.step(env.action_space.sample())
    assert np.array_equal(env.render(), obs["visual_observation"] if isinstance(obs, dict) else obs)
    env.close()


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_gymnasium_checker_passes_on_what_make_returns(env_id: str) -> None:
    env = gym.make(env_id, render_mode="rgb_array")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env)
    assert not [str(w.message) for w in caught if "wrapper" in str(w.message).lower()]
    env.close()


@pytest.mark.parametrize("env_id", ["MortarMayhem-v0", "Endless-SearingSpotlights-v0"])
def test_a_client_wrapper_reads_through_gymnasium_lookups(env_id: str) -> None:
    """CleanRL's ``ppo_trxl.py`` wraps the environment and reads through ``get_wrapper_attr`` and the vector env's
    ``call``: that keeps working."""
    wrapped = gym.wrappers.RecordEpisodeStatistics(gym.make(env_id))
    wrapped.reset(seed=1)
    assert wrapped.get_wrapper_attr("max_episode_steps") == wrapped.unwrapped.max_episode_steps
    assert wrapped.get_wrapper_attr("has_ground_truth_info") is (env_id in GROUND_TRUTH_SIZES)
    vec = gym.vector.SyncVectorEnv([lambda: gym.wrappers.RecordEpisodeStatistics(gym.make(env_id))] * 2)
    vec.reset(seed=1)
    assert vec.call("max_episode_steps") == (wrapped.unwrapped.max_episode_steps,) * 2
    assert vec.get_attr("ground_truth_space") == (wrapped.unwrapped.ground_truth_space,) * 2
    vec.close()
    wrapped.close()
