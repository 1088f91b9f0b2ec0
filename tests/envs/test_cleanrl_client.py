"""A CleanRL-style client written for memory-gym (the shape of the authors' ``ppo_trxl.py`` loop, ported to
gymnasium 1.x) runs unchanged against every id.

What such a client does and needs from the environments (ecosystem.md, "Clients written for memory-gym"):

* ``gym.vector.SyncVectorEnv`` over ``RecordEpisodeStatistics(gym.make(id))``, default (NEXT_STEP) autoreset;
* every action space treated as multi-discrete: actions of shape ``(num_envs, branches)``, one branch for a
  ``Discrete`` space, so each env receives a one-element array ``np.array([a])``;
* ``max_episode_steps`` read after the reset (through ``unwrapped``, ``call`` or ``get_attr``: gymnasium 1.x wrappers
  no longer forward attributes) to size a per-episode memory, -1 meaning "no limit" (the client then picks a size);
* episode statistics from ``infos["episode"]`` under the ``infos["_episode"]`` mask.
"""

from __future__ import annotations

from collections.abc import Callable

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401  (registers the ids)
from envs import ENV_IDS

NUM_ENVS = 3
STEPS = 600  # every id ends an episode within this under random play (MysteryPath-v0 at its 512-step limit)
UNBOUNDED_MEMORY = 1024  # what the client substitutes for -1


def make_env(env_id: str) -> Callable[[], gym.Env]:
    return lambda: gym.wrappers.RecordEpisodeStatistics(gym.make(env_id))


@pytest.mark.parametrize("env_id", list(ENV_IDS))
def test_a_cleanrl_style_loop_runs_on_every_id(env_id: str) -> None:
    vec = gym.vector.SyncVectorEnv([make_env(env_id) for _ in range(NUM_ENVS)])
    space = vec.single_action_space
    branches = [space.n] if isinstance(space, gym.spaces.Discrete) else space.nvec.tolist()
    obs, _ = vec.reset(seed=7)
    limits = vec.call("max_episode_steps")
    assert limits == vec.get_attr("max_episode_steps") == (vec.envs[0].unwrapped.max_episode_steps,) * NUM_ENVS
    max_episode_steps = limits[0] if limits[0] > 0 else UNBOUNDED_MEMORY
    memory = np.zeros((NUM_ENVS, max_episode_steps, 8), dtype=np.float32)  # one row per step of the episode
    episode_step = np.zeros(NUM_ENVS, dtype=np.int64)  # index of the current observation in its episode
    autoreset = np.zeros(NUM_ENVS, dtype=bool)  # NEXT_STEP: this step restarts the env (its action is ignored)
    rng = np.random.default_rng(0)
    returns, lengths = [], []
    for t in range(STEPS):
        acting = np.flatnonzero(~autoreset)
        memory[acting, episode_step[acting]] = t  # IndexError if an episode outgrew max_episode_steps
        action = np.stack([rng.integers(0, n, size=NUM_ENVS) for n in branches], axis=1)  # (num_envs, branches)
        if t % 2:  # the other spelling: one array per env, np.array([a]) for a Discrete space
            action = [row.copy() for row in action]
        obs, reward, terminated, truncated, infos = vec.step(action)
        done = terminated | truncated
        episode_step = np.where(autoreset, 0, episode_step + 1)
        autoreset = done
        assert (obs["visual_observation"] if isinstance(obs, dict) else obs).shape[0] == NUM_ENVS
        if "episode" in infos:
            finished = infos["_episode"]
            assert (finished == done).all()
            # RecordEpisodeStatistics agrees with the environment's own statistics of the same episode
            np.testing.assert_allclose(infos["episode"]["r"][finished], infos["reward"][finished], rtol=1e-5)
            assert infos["episode"]["l"][finished].tolist() == infos["length"][finished].tolist()
            returns += infos["episode"]["r"][finished].tolist()
            lengths += infos["episode"]["l"][finished].tolist()
    assert lengths, f"{env_id}: no episode ended in {STEPS} steps"
    if limits[0] > 0:
        assert max(lengths) <= limits[0]
    assert all(np.isfinite(returns))
    # the figure stays readable after the autoresets
    assert vec.call("max_episode_steps") == limits
    vec.close()
