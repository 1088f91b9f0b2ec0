"""``layout="memory-gym"`` returns memory-gym 1.0.2's own observation arrays, pixel for pixel, on every recorded frame
of the reference traces: through ``gymnasium.make`` and through ``gymnasium.make_vec``.

The traces store a digest of each of memory-gym's observations as memory-gym returned it, (x, y, channel), computed
by the function the trace's ``digest`` field names (the recorder transposes memory-gym's array, then hashes it). The
observations of the memory-gym layout go through that same function, as memory-gym's did; the default layout, put
through it, does not match (the check tells the two layouts apart).
"""

from __future__ import annotations

import json
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401  (registers the ids)
from scripts.reference import REFERENCE_IDS
from scripts.reference.trace_format import DIGEST_METHOD, load_traces, obs_digest

LAYOUT = "memory-gym"
Episode = dict[str, Any]


def recorded_digest(obs: Any) -> str:
    """What the recorder stored for an observation of memory-gym's layout (``DIGEST_METHOD``: the (x, y, channel)
    image hashed as ``obs.transpose(1, 0, 2)``, the vector part as float32)."""
    if isinstance(obs, dict):
        return obs_digest({**obs, "visual_observation": obs["visual_observation"].transpose(1, 0, 2)})
    return obs_digest(obs.transpose(1, 0, 2))


def test_the_traces_digest_memory_gyms_own_arrays_this_way() -> None:
    assert DIGEST_METHOD.startswith("sha256 hex, first 16 chars, of np.ascontiguousarray(obs.transpose(1,0,2))")
    for env_id in REFERENCE_IDS:
        assert load_traces(env_id)["digest"] == DIGEST_METHOD


def replay_single(env_id: str, layout: str) -> tuple[int, int, list[str]]:
    """Every episode of the trace on one instance (a fresh one where the trace says so), as the reference played
    them; returns (frames, frames whose observation matches, first mismatches)."""
    frames, identical, mismatches = 0, 0, []
    env = None
    for episode in load_traces(env_id)["episodes"]:
        if env is None or episode.get("fresh_env"):
            env = gym.make(env_id, layout=layout)
            env.unwrapped.core.reference_carryover = True  # the traces were recorded on reused instances
        obs, _ = env.reset(seed=episode["seed"], options=episode["options"])
        got = [obs]
        got += [env.step(action)[0] for action in episode["actions"]]
        for t, (observation, want) in enumerate(zip(got, [episode["reset_obs"], *episode["obs"]], strict=True)):
            assert env.observation_space.contains(observation)
            frames += 1
            if recorded_digest(observation) == want:
                identical += 1
            elif len(mismatches) < 3:
                mismatches.append(f"{episode['name']} frame {t}")
    return frames, identical, mismatches


@pytest.mark.parametrize("env_id", REFERENCE_IDS)
def test_single_face_returns_memory_gyms_arrays(env_id: str) -> None:
    frames, identical, mismatches = replay_single(env_id, LAYOUT)
    assert frames > 0 and identical == frames, f"{env_id}: {identical}/{frames} frames identical; {mismatches}"


@pytest.mark.parametrize("env_id", REFERENCE_IDS)
def test_the_default_layout_does_not_match(env_id: str) -> None:
    # Only frames that equal their own transpose (a blank delay between Mortar Mayhem's clues, ...) match in both
    # layouts: at most 2.1% of an id's frames.
    frames, identical, _ = replay_single(env_id, "rows")
    assert identical < frames / 20, f"{env_id}: {identical}/{frames} row-layout frames match memory-gym's arrays"


def runs_of(episodes: list[Episode]) -> list[tuple[Episode | None, list[Episode]]]:
    """The trace's episodes in runs that slots of one vector env replay side by side, each run with the episode that
    the reference's instance played before it (replayed first, unchecked: Endless Mortar Mayhem draws what it left
    behind) or None on a fresh instance. A run starts at a fresh-instance episode, or at a seeded episode that follows
    a seeded one; an unseeded episode, or one after it, stays in the run before it (it continues that generator)."""
    runs: list[tuple[Episode | None, list[Episode]]] = []
    shared: list[Episode] | None = None  # the run on the trace's shared instance
    previous: Episode | None = None  # the episode played last on the shared instance
    for episode in episodes:
        if episode.get("fresh_env"):
            runs.append((None, [episode]))
        elif shared is None or (episode["seed"] is not None and previous is not None and previous["seed"] is not None):
            shared = [episode]
            runs.append((previous, shared))
            previous = episode
        else:
            shared.append(episode)
            previous = episode
    return runs


def replay_vector(env_id: str) -> tuple[int, int, list[str]]:
    """Every episode of the trace in a slot of one ``make_vec`` env (the runs of :func:`runs_of`, one per slot), all
    slots stepped together; a slot that finishes an episode is reset alone (``reset_mask``) into its next one."""
    runs = runs_of(load_traces(env_id)["episodes"])
    n = len(runs)
    venv = gym.make_vec(env_id, num_envs=n, layout=LAYOUT)
    venv.unwrapped.core.reference_carryover = True
    queues = [[(before, False)] * (before is not None) + [(ep, True) for ep in run] for before, run in runs]
    playing: list[tuple[Episode, bool] | None] = [None] * n
    step = [0] * n
    frames, identical, mismatches = 0, 0, []

    def check(k: int, obs: Any, want: str, where: str) -> None:
        nonlocal frames, identical
        observation = {key: v[k] for key, v in obs.items()} if isinstance(obs, dict) else obs[k]
        assert venv.single_observation_space.contains(observation)
        frames += 1
        if recorded_digest(observation) == want:
            identical += 1
        elif len(mismatches) < 3:
            mismatches.append(where)

    def start(slots: list[int]) -> None:
        groups: dict[str, list[int]] = {}  # one reset call per options: a reset's options apply to all its slots
        for k in slots:
            playing[k], step[k] = queues[k].pop(0), 0
            groups.setdefault(json.dumps(playing[k][0]["options"], sort_keys=True), []).append(k)
        for group in groups.values():
            mask = np.zeros(n, dtype=bool)
            mask[group] = True
            seeds = [playing[k][0]["seed"] if mask[k] else None for k in range(n)]
            options = playing[group[0]][0]["options"] or {}
            obs, _ = venv.reset(seed=seeds, options={**options, "reset_mask": mask})
            for k in group:
                episode, checked = playing[k]
                if checked:
                    check(k, obs, episode["reset_obs"], f"{episode['name']} frame 0")

    start(list(range(n)))
    idle = np.zeros(venv.single_action_space.shape, dtype=np.int64)  # for slots that have played their runs
    while any(playing):
        actions = np.array([p[0]["actions"][step[k]] if p else idle for k, p in enumerate(playing)])
        obs, *_ = venv.step(actions)
        finished = []
        for k, p in enumerate(playing):
            if p is None:
                continue
            episode, checked = p
            if checked:
                check(k, obs, episode["obs"][step[k]], f"{episode['name']} frame {step[k] + 1}")
            step[k] += 1
            if step[k] == len(episode["actions"]):
                finished.append(k)
        for k in finished:
            playing[k] = None
        start([k for k in finished if queues[k]])
    venv.close()
    return frames, identical, mismatches


@pytest.mark.parametrize("env_id", REFERENCE_IDS)
def test_vector_face_returns_memory_gyms_arrays(env_id: str) -> None:
    episodes = load_traces(env_id)["episodes"]
    assert sum(len(run) for _, run in runs_of(episodes)) == len(episodes)
    frames, identical, mismatches = replay_vector(env_id)
    assert frames == sum(len(ep["actions"]) + 1 for ep in episodes)
    assert identical == frames, f"{env_id}: {identical}/{frames} frames identical; {mismatches}"
