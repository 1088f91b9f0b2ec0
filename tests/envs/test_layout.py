"""``layout``: ``gymnasium.make(id, layout="memory-gym")`` and ``gymnasium.make_vec(id, num_envs=n,
layout="memory-gym")`` return memory-gym's (x, y, channel) arrays, the transpose of the default ``"rows"`` images;
the observation spaces follow, ``render()`` does not change. (Pixel-for-pixel equality with memory-gym 1.0.2 on the
recorded traces: ``tests/reference/test_layout_parity.py``.)
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.vector import AutoresetMode

import envs  # noqa: F401  (registers the ids)
from envs import ENV_IDS
from envs.core import OBSERVATION_LAYOUTS, BatchedCore, Index, MemoryGymEnv, MemoryGymVectorEnv

ALL_IDS = list(ENV_IDS)
IMAGE = "visual_observation"


def image_of(obs: Any) -> np.ndarray:
    return obs[IMAGE] if isinstance(obs, dict) else obs


def transposed_space(space: gym.Space) -> gym.Space:
    """The space written out for memory-gym's layout: images (x, y, channel), vectors unchanged."""
    if isinstance(space, gym.spaces.Dict):
        return gym.spaces.Dict({key: transposed_space(part) for key, part in space.spaces.items()})
    if len(space.shape) == 3:
        height, width, channels = space.shape
        return gym.spaces.Box(0, 255, (width, height, channels), np.uint8)
    return space


class WideCore(BatchedCore):
    """A core with a non-square image (6 rows, 10 columns) and a vector part: pixel (row, column) of step t holds
    (row, column, t); episodes last three steps."""

    env_name = "Wide"
    option_specs: dict = {}
    single_observation_space = gym.spaces.Dict(
        {
            IMAGE: gym.spaces.Box(0, 255, (6, 10, 3), np.uint8),
            "vector_observation": gym.spaces.Box(0.0, 10.0, (4,), np.float32),
        }
    )
    single_action_space = gym.spaces.Discrete(2)

    def __init__(self, num_envs: int = 1, options: dict[str, Any] | None = None) -> None:
        super().__init__(num_envs, options)
        self.frames = np.zeros((num_envs, 6, 10, 3), dtype=np.uint8)
        self.vectors = np.zeros((num_envs, 4), dtype=np.float32)
        self.t = np.zeros(num_envs, dtype=np.int64)

    def _reset_slot(self, k: int, rng: np.random.Generator, opts: dict[str, Any]) -> None:
        self.t[k] = 0
        self._draw(np.array([k]))

    def _step(self, idx: Index, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        self.t[idx] += 1
        self._draw(idx)
        return np.zeros(len(self.slots(idx)), dtype=np.float32), self.t[idx] >= 3

    def _draw(self, idx: Index) -> None:
        rows, columns = np.mgrid[0:6, 0:10]
        self.frames[idx, :, :, 0] = rows
        self.frames[idx, :, :, 1] = columns
        self.frames[idx, :, :, 2] = self.t[idx][:, None, None]
        self.vectors[idx] = np.arange(4, dtype=np.float32) + self.t[idx][:, None]

    def _observation(self, idx: Index) -> dict[str, np.ndarray]:
        return {IMAGE: self.frames[idx], "vector_observation": self.vectors[idx]}


def test_the_layouts() -> None:
    assert OBSERVATION_LAYOUTS == ("rows", "memory-gym")


@pytest.mark.parametrize("layout", ["memory_gym", "xy", "", None, 1])
def test_a_bad_layout_is_refused_by_name(layout: Any) -> None:
    message = rf"layout={layout!r} is invalid; valid layouts: rows, memory-gym"
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")):
        gym.make("MortarMayhem-v0", layout=layout)
    with pytest.raises(ValueError, match="valid layouts: rows, memory-gym"):
        gym.make_vec("MortarMayhem-v0", num_envs=2, layout=layout)


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_spaces_follow_the_layout(env_id: str) -> None:
    rows = gym.make(env_id)
    memory_gym = gym.make(env_id, layout="memory-gym")
    assert rows.layout == "rows" and memory_gym.layout == "memory-gym"
    expected = transposed_space(rows.observation_space)
    assert memory_gym.observation_space == expected
    if isinstance(expected, gym.spaces.Dict):  # the B variants: same keys in the same order, the vector unchanged
        assert list(memory_gym.observation_space.spaces) == list(rows.observation_space.spaces)
        assert memory_gym.observation_space["vector_observation"] == rows.observation_space["vector_observation"]
    if env_id == "ProofOfMemory-v0":
        assert image_of(memory_gym.observation_space).shape == (36, 36, 3)
    vec = gym.make_vec(env_id, num_envs=3, layout="memory-gym")
    assert vec.single_observation_space == expected
    assert vec.observation_space == gym.vector.utils.batch_space(expected, 3)
    obs, _ = vec.reset(seed=0)
    assert vec.observation_space.contains(obs)
    for env in (rows, memory_gym, vec):
        env.close()


def test_a_non_square_image_and_its_vector() -> None:
    env = MemoryGymEnv(WideCore, layout="memory-gym")
    assert env.observation_space[IMAGE].shape == (10, 6, 3)
    assert env.observation_space["vector_observation"] == WideCore.single_observation_space["vector_observation"]
    x, y = np.mgrid[0:10, 0:6]
    obs, _ = env.reset(seed=0)
    for t in range(3):
        assert env.observation_space.contains(obs)
        assert (obs[IMAGE][..., 0] == y).all() and (obs[IMAGE][..., 1] == x).all() and (obs[IMAGE][..., 2] == t).all()
        assert obs["vector_observation"].tolist() == [t, t + 1, t + 2, t + 3]
        obs, *_ = env.step(0)
    vec = MemoryGymVectorEnv(WideCore, num_envs=2, layout="memory-gym")
    assert vec.single_observation_space == env.observation_space
    obs, _ = vec.reset(seed=0)
    assert vec.observation_space.contains(obs) and obs[IMAGE].shape == (2, 10, 6, 3)
    assert (obs[IMAGE][..., 0] == y).all() and (obs[IMAGE][..., 1] == x).all()


def play(env_id: str, layout: str, steps: int = 120) -> list[tuple[Any, Any]]:
    """Observations and renders of a single env under a fixed action stream (rgb_array), resets included."""
    env = gym.make(env_id, render_mode="rgb_array", layout=layout)
    rng = np.random.default_rng(0)
    obs, _ = env.reset(seed=4)
    seen = [(obs, env.render())]
    for _ in range(steps):
        obs, _, terminated, _, _ = env.step(_action(env.action_space, rng))
        seen.append((obs, env.render()))
        if terminated:
            obs, _ = env.reset()
            seen.append((obs, env.render()))
    env.close()
    return seen


def _action(space: gym.Space, rng: np.random.Generator) -> Any:
    if isinstance(space, gym.spaces.Discrete):
        return int(rng.integers(space.n))
    return rng.integers(space.nvec).astype(np.int64)


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_single_face_transposes_the_images_and_renders_as_before(env_id: str) -> None:
    for (rows, rows_render), (memory_gym, memory_gym_render) in zip(
        play(env_id, "rows"), play(env_id, "memory-gym"), strict=True
    ):
        assert np.array_equal(image_of(memory_gym), image_of(rows).transpose(1, 0, 2))
        if isinstance(rows, dict):
            assert np.array_equal(memory_gym["vector_observation"], rows["vector_observation"])
        assert np.array_equal(memory_gym_render, rows_render) and np.array_equal(rows_render, image_of(rows))


@pytest.mark.parametrize("env_id", ["MortarMayhemB-Grid-v0", "MysteryPath-Grid-v0", "ProofOfMemory-v0"])
@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
def test_vector_face_transposes_every_observation(env_id: str, mode: AutoresetMode) -> None:
    faces = [gym.make_vec(env_id, num_envs=4, autoreset_mode=mode, layout=layout) for layout in OBSERVATION_LAYOUTS]
    rng = np.random.default_rng(1)
    results = [face.reset(seed=9) for face in faces]
    finals = 0
    previous = None
    for _ in range(200):
        (rows, rows_info), (memory_gym, memory_gym_info) = results
        assert np.array_equal(image_of(memory_gym), image_of(rows).transpose(0, 2, 1, 3))
        if isinstance(rows, dict):
            assert np.array_equal(memory_gym["vector_observation"], rows["vector_observation"])
        for k in np.flatnonzero(rows_info.get("_final_obs", [])):  # SAME_STEP: the last observation of an episode
            finals += 1
            want = image_of(rows_info["final_obs"][k]).transpose(1, 0, 2)
            assert np.array_equal(image_of(memory_gym_info["final_obs"][k]), want)
        if previous is not None:  # every step returns new arrays (gymnasium's "returned data not reused")
            assert not np.shares_memory(image_of(previous), image_of(memory_gym))
        previous = memory_gym
        actions = np.stack([np.asarray(_action(faces[0].single_action_space, rng)) for _ in range(4)])
        results = [face.step(actions)[0::4] for face in faces]
    assert finals or mode == AutoresetMode.NEXT_STEP, "no episode ended: the final observations went unchecked"
    for face in faces:
        face.close()


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_gymnasium_checker_passes_in_memory_gyms_layout(env_id: str) -> None:
    env = gym.make(env_id, render_mode="rgb_array", layout="memory-gym")
    check_env(env)
    env.close()
