"""A small synthetic environment with Dict observations and MultiDiscrete actions, for trainer tests."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from envs.core import BatchedCore, Index

ENV_ID = "TestDict-v0"
CORE = "tests.support.dict_env:DictCore"


class DictCore(BatchedCore):
    """A synthetic Dict-observation, MultiDiscrete env: random episode lengths, rewards that use the slot's
    generator during steps (so exact resume needs the generator state), numeric and non-numeric final infos."""

    env_name = "TestDict-v0"
    option_specs = {}
    single_observation_space = gym.spaces.Dict(
        {
            "visual_observation": gym.spaces.Box(0, 255, (36, 36, 3), np.uint8),
            "vector_observation": gym.spaces.Box(-1.0, 1.0, (4,), np.float32),
        }
    )
    single_action_space = gym.spaces.MultiDiscrete([3, 2])

    def __init__(self, num_envs: int = 1, options: dict[str, Any] | None = None) -> None:
        super().__init__(num_envs, options)
        self.t = np.zeros(num_envs, dtype=np.int64)
        self.length = np.zeros(num_envs, dtype=np.int64)
        self.target = np.zeros(num_envs, dtype=np.int64)
        self.hits = np.zeros(num_envs, dtype=np.int64)
        self.images = np.zeros((num_envs, 36, 36, 3), dtype=np.uint8)

    def _reset_slot(self, k: int, rng: np.random.Generator, opts: dict[str, Any]) -> None:
        self.t[k], self.hits[k] = 0, 0
        self.length[k] = rng.integers(2, 12)
        self.target[k] = rng.integers(0, 3)
        self.images[k] = rng.integers(0, 256, (36, 36, 3), dtype=np.uint8)

    def _step(self, idx: Index, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        rewards = np.zeros(len(self.slots(idx)))
        for i, k in enumerate(self.slots(idx)):
            hit = actions[i, 0] == self.target[k]
            self.hits[k] += hit
            rewards[i] = 0.1 * hit + 0.01 * self.rngs[k].random()
            self.images[k, self.t[k] % 36] = self.rngs[k].integers(0, 256)
        self.t[idx] += 1
        return rewards, self.t[idx] >= self.length[idx]

    def _observation(self, idx: Index) -> dict[str, np.ndarray]:
        vector = np.stack([self.t[idx] / 12, self.target[idx] / 3, self.hits[idx] / 12, self.length[idx] / 12], -1)
        return {"visual_observation": self.images[idx], "vector_observation": vector.astype(np.float32)}

    def _final_info(self, k: int) -> dict[str, Any]:
        return {"hits": int(self.hits[k]), "label": "not a number"}
