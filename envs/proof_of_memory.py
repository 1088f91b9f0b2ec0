"""``ProofOfMemory-v0``: the smallest task that a memory-less agent cannot solve.

The reset frame shows a cue: the left or the right half of the picture is white. Then ``delay - 1`` black frames
follow and a query frame (a white bar across the middle). The action taken on the query frame (0 = left,
1 = right) ends the episode: +1 if it names the cued side, 0 otherwise. Every earlier action is ignored. A
memory-less policy sees identical frames whatever the cue, so its success rate is 0.5 by construction.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from envs.core import BatchedCore, Index
from envs.options import Option

SIZE = 36  # the smallest picture the Nature CNN accepts (8x8/4, 4x4/2, 3x3/1 -> 1x1)


class ProofOfMemoryCore(BatchedCore):
    env_name = "ProofOfMemory-v0"
    option_specs = {
        "delay": Option(4, "int", 1, 256, doc="steps from the cue frame to the query frame"),
        "reward_correct": Option(1.0, "float", doc="reward for naming the cued side"),
        "reward_wrong": Option(0.0, "float", doc="reward for the other side"),
    }
    single_observation_space = gym.spaces.Box(0, 255, (SIZE, SIZE, 3), np.uint8)
    single_action_space = gym.spaces.Discrete(2)
    base_render_fps = 4

    def __init__(self, num_envs: int = 1, options: dict[str, Any] | None = None) -> None:
        super().__init__(num_envs, options)
        n = self.num_envs
        self.frames = np.zeros((n, SIZE, SIZE, 3), dtype=np.uint8)
        self.cue = np.zeros(n, dtype=np.int64)
        self.t = np.zeros(n, dtype=np.int64)
        self.delay = np.zeros(n, dtype=np.int64)
        self.reward_correct = np.zeros(n)
        self.reward_wrong = np.zeros(n)
        self.success = np.zeros(n, dtype=np.int64)

    def _reset_slot(self, k: int, rng: np.random.Generator, opts: dict[str, Any]) -> None:
        self.cue[k] = rng.integers(0, 2)
        self.t[k] = 0
        self.delay[k] = opts["delay"]
        self.reward_correct[k] = opts["reward_correct"]
        self.reward_wrong[k] = opts["reward_wrong"]
        self.success[k] = 0
        self._draw(np.array([k]))

    def _step(self, idx: Index, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        actions = actions.reshape(-1)
        self.t[idx] += 1
        judged = self.t[idx] > self.delay[idx]
        correct = judged & (actions == self.cue[idx])
        rewards = np.where(judged, np.where(correct, self.reward_correct[idx], self.reward_wrong[idx]), 0.0)
        self.success[idx] = correct
        self._draw(idx)
        return rewards, judged

    def _draw(self, idx: Index) -> None:
        frames = self.frames[idx]
        frames[:] = 0
        t, cue = self.t[idx], self.cue[idx]
        half = SIZE // 2
        frames[(t == 0) & (cue == 0), :, :half] = 255
        frames[(t == 0) & (cue == 1), :, half:] = 255
        frames[t >= self.delay[idx], half - 3 : half + 3, :] = 255
        self.frames[idx] = frames

    def _max_episode_steps(self, opts: dict[str, Any]) -> int:
        return opts["delay"] + 1  # every episode ends on the step after the query frame appears

    def _observation(self, idx: Index) -> np.ndarray:
        return self.frames[idx]

    def _final_info(self, k: int) -> dict[str, Any]:
        return {"success": int(self.success[k])}
