"""A tiny gymnasium memory task, brought as a researcher's own environment: ``"tests.support.tiny_env:TinyMemory-v0"``
(importing this module registers the id).

The first observation shows a cue (one of two); ``delay`` blank steps follow; then the action that names the cue
scores 1 and ends the episode (the final info's ``success``). Without memory a policy is right half the time. The
observation and action spaces are chosen by keyword, to cover what the adapter (envs.gymnasium_core) takes."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

ENV_ID = "tests.support.tiny_env:TinyMemory-v0"
SIDE = 36  # the smallest image the Nature CNN takes


class TinyMemoryEnv(gym.Env):
    """See the module docstring. ``observation``: vector, image, image_chw, dict, discrete or text (unsupported);
    ``action``: discrete (Discrete(2, start=1)), multi_discrete or box (unsupported); ``ignore_seed``: reset does not
    seed the generator (an environment that cannot reproduce its episodes)."""

    metadata = {"render_modes": []}

    def __init__(
        self, delay: int = 2, observation: str = "vector", action: str = "discrete", ignore_seed: bool = False
    ) -> None:
        self.delay, self.kind, self.ignore_seed = delay, observation, ignore_seed
        vector = gym.spaces.Box(0.0, 1.0, (3,), np.float32)
        image = gym.spaces.Box(0, 255, (SIDE, SIDE, 3), np.uint8)
        spaces = {
            "vector": vector,
            "image": image,
            "image_chw": gym.spaces.Box(0, 255, (3, SIDE, SIDE), np.uint8),
            "dict": gym.spaces.Dict({"pixels": image, "cue": vector, "step": gym.spaces.Discrete(4)}),
            "discrete": gym.spaces.Discrete(3),
            "text": gym.spaces.Text(4),
        }
        self.observation_space = spaces[observation]
        actions = {
            "discrete": gym.spaces.Discrete(2, start=1),
            "multi_discrete": gym.spaces.MultiDiscrete([2, 3]),
            "box": gym.spaces.Box(-1.0, 1.0, (1,), np.float32),
        }
        self.action_space = actions[action]
        self.cue, self.t = 0, 0

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict]:
        if self.ignore_seed:
            self._np_random = np.random.default_rng()  # a fresh generator each time: the seed is lost
        else:
            super().reset(seed=seed)
        self.cue, self.t = int(self.np_random.integers(2)), 0
        return self._observation(), {}

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict]:
        self.t += 1
        if self.t <= self.delay:
            return self._observation(), 0.0, False, False, {}
        if isinstance(self.action_space, gym.spaces.Discrete):
            choice = int(action) - int(self.action_space.start)
        else:
            choice = int(np.asarray(action)[0])
        success = choice == self.cue
        return self._observation(), float(success), True, False, {"success": success, "cue": self.cue}

    def _observation(self) -> Any:
        shown = self.t == 0
        vector = np.zeros(3, np.float32)
        vector[self.cue if shown else 2] = 1.0
        image = np.zeros((SIDE, SIDE, 3), np.uint8)
        image[..., self.cue if shown else 2] = 255
        if self.kind == "vector":
            return vector
        if self.kind == "image":
            return image
        if self.kind == "image_chw":
            return np.ascontiguousarray(image.transpose(2, 0, 1))
        if self.kind == "dict":
            return {"pixels": image, "cue": vector, "step": min(self.t, 3)}
        if self.kind == "discrete":
            return self.cue if shown else 2
        return "cue"


if "TinyMemory-v0" not in gym.registry:
    gym.register("TinyMemory-v0", entry_point="tests.support.tiny_env:TinyMemoryEnv", max_episode_steps=20)
