"""``max_episode_steps``: the figure memory-gym 1.0.2 sets at every reset and its clients size their memory from.

The reference values and rules come from the specification (environments.md §3.1, §3.6, §4, §5.1, §6.1, §7.1, §8;
ecosystem.md "Clients written for memory-gym"), written out here rather than read from the option specs, so that a
wrong default or formula in the cores cannot agree with itself.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401  (registers the ids)
from envs import ENV_IDS

# memory-gym 1.0.2's values at default options (ProofOfMemory-v0, ours: the delay of 4 plus the query step)
REFERENCE = {
    "ProofOfMemory-v0": 5,
    "MortarMayhem-v0": 275,
    "MortarMayhem-Grid-v0": 119,
    "MortarMayhemB-v0": 235,
    "MortarMayhemB-Grid-v0": 79,
    "Endless-MortarMayhem-v0": -1,
    "MysteryPath-v0": 512,
    "MysteryPath-Grid-v0": 128,
    "SearingSpotlights-v0": 256,
    "Endless-MysteryPath-v0": -1,
    "Endless-SearingSpotlights-v0": -1,
}
# Mortar Mayhem's list options at their defaults (§3.1): n, shown, blank, E (lethal), D (time to act)
MM_DEFAULTS = {
    "free": {"command_count": [10], "command_show_duration": [3], "command_show_delay": [1], "explosion_duration": [6],
             "explosion_delay": [18]},
    "grid": {"command_count": [10], "command_show_duration": [3], "command_show_delay": [1], "explosion_duration": [2],
             "explosion_delay": [6]},
}  # fmt: skip


def expected(env_id: str, options: dict[str, Any]) -> int:
    """The reference's rule: MM C + n(D + E) - E + 1 over the largest value of each list (C = 0 without a clue
    stream), ``max_steps`` for Mystery Path, Searing Spotlights and the endless ids, ``delay + 1`` for ours."""
    if env_id == "ProofOfMemory-v0":
        return options.get("delay", 4) + 1
    if env_id.startswith("MortarMayhem"):
        o = {**MM_DEFAULTS["grid" if "Grid" in env_id else "free"], **options}
        n, lethal, act = max(o["command_count"]), max(o["explosion_duration"]), max(o["explosion_delay"])
        clue = (
            0
            if env_id.startswith("MortarMayhemB")
            else n * (max(o["command_show_duration"]) + max(o["command_show_delay"]))
        )
        return clue + n * (act + lethal) - lethal + 1
    return options.get("max_steps", REFERENCE[env_id])


# Non-default options per id: list options with several entries (the largest counts), and max_steps
NON_DEFAULT = {
    "ProofOfMemory-v0": [{"delay": 9}],
    "MortarMayhem-v0": [{"command_count": [5]}, {"command_count": [3, 7], "command_show_delay": [0, 2],
                        "explosion_delay": [10, 4], "explosion_duration": [1, 3], "command_show_duration": [2]}],
    "MortarMayhem-Grid-v0": [{"command_count": [3]}, {"explosion_delay": [9], "explosion_duration": [4, 1]}],
    "MortarMayhemB-v0": [{"command_count": [20]}, {"explosion_delay": [5, 12], "explosion_duration": [2]}],
    "MortarMayhemB-Grid-v0": [{"command_count": [1]}, {"command_count": [4, 2], "explosion_delay": [3]}],
    "Endless-MortarMayhem-v0": [{"max_steps": 300}],
    "MysteryPath-v0": [{"max_steps": 200}],
    "MysteryPath-Grid-v0": [{"max_steps": 64}],
    "SearingSpotlights-v0": [{"max_steps": 100}],
    "Endless-MysteryPath-v0": [{"max_steps": 1000}],
    "Endless-SearingSpotlights-v0": [{"max_steps": 500}],
}  # fmt: skip


def test_the_tables_cover_every_id() -> None:
    assert set(REFERENCE) == set(NON_DEFAULT) == set(ENV_IDS)


@pytest.mark.parametrize("env_id", list(ENV_IDS))
def test_single_face_sets_the_reference_figure_at_every_reset(env_id: str) -> None:
    env = gym.make(env_id)
    # memory-gym sets the attribute in reset: before the first one it does not exist (hasattr is False)
    assert not hasattr(env.unwrapped, "max_episode_steps")
    with pytest.raises(AttributeError, match="before its first reset"):
        env.unwrapped.max_episode_steps  # noqa: B018
    env.reset(seed=0)
    assert env.unwrapped.max_episode_steps == REFERENCE[env_id] == expected(env_id, {})
    assert env.get_wrapper_attr("max_episode_steps") == REFERENCE[env_id]  # what gymnasium 1.x clients call
    for options in NON_DEFAULT[env_id]:
        env.reset(seed=1, options=options)
        assert env.unwrapped.max_episode_steps == expected(env_id, options), options
        assert env.unwrapped.max_episode_steps != REFERENCE[env_id], "the options must change the figure"
        env.reset(seed=1)  # reset options apply to one episode: back to the defaults
        assert env.unwrapped.max_episode_steps == REFERENCE[env_id]
    # options given to make are the instance's defaults
    options = NON_DEFAULT[env_id][0]
    made = gym.make(env_id, options=options)
    made.reset(seed=0)
    assert made.unwrapped.max_episode_steps == expected(env_id, options)
    # a refused reset leaves the episode, and its figure, as they were
    with pytest.raises(ValueError):
        made.reset(options={"no_such_option": 1})
    assert made.unwrapped.max_episode_steps == expected(env_id, options)


@pytest.mark.parametrize("env_id", list(ENV_IDS))
def test_vector_face_reports_one_figure_per_slot(env_id: str) -> None:
    vec = gym.make_vec(env_id, num_envs=3)
    assert not hasattr(vec, "max_episode_steps")
    options = NON_DEFAULT[env_id][0]
    vec.reset(seed=0, options={**options, "reset_mask": np.array([True, True, False])})
    limits = vec.max_episode_steps
    assert limits.dtype == np.int64 and limits.tolist() == [expected(env_id, options)] * 2 + [0]  # slot 2: no reset
    vec.reset(seed=5, options={"reset_mask": np.array([False, False, True])})
    assert vec.max_episode_steps.tolist() == [expected(env_id, options)] * 2 + [REFERENCE[env_id]]
    limits[:] = 7  # a copy: writing to it changes nothing
    assert vec.max_episode_steps.tolist()[2] == REFERENCE[env_id]


@pytest.mark.parametrize("env_id", ["MortarMayhem-Grid-v0", "Endless-MysteryPath-v0"])
def test_vector_face_answers_get_attr_and_call_like_sync_vector_env(env_id: str) -> None:
    """A client written for memory-gym asks a vector env for its slots' figure with call/get_attr, as it would a
    SyncVectorEnv of single envs; the native face gives the same tuples."""
    options = NON_DEFAULT[env_id][0]
    sync = gym.vector.SyncVectorEnv([lambda: gym.make(env_id) for _ in range(3)])
    vec = gym.make_vec(env_id, num_envs=3)
    with pytest.raises(AttributeError, match="before its first reset"):
        vec.call("max_episode_steps")
    for env in (sync, vec):
        env.reset(seed=0, options=options)
    assert vec.call("max_episode_steps") == vec.get_attr("max_episode_steps") == sync.call("max_episode_steps")
    assert vec.get_attr("max_episode_steps") == (expected(env_id, options),) * 3
    for name in ("action_space", "observation_space", "render_mode"):
        assert vec.get_attr(name) == sync.get_attr(name), name
    with pytest.raises(AttributeError, match="valid names are max_episode_steps, observation_space"):
        vec.get_attr("max_episode_stepz")
    with pytest.raises(ValueError, match="takes no arguments"):
        vec.call("max_episode_steps", 1)


def run_to_the_end(env: gym.Env, seed: int, options: dict[str, Any], action: Any, limit: int = 5000) -> int:
    env.reset(seed=seed, options=options)
    for t in range(1, limit + 1):
        if env.step(action)[2]:
            return t
    raise AssertionError(f"no episode end within {limit} steps")


# (id, options under which a no-op agent meets the time limit, the no-op action)
TIME_LIMITED = [
    ("ProofOfMemory-v0", {"delay": 6}, 0),
    ("MysteryPath-v0", {"max_steps": 40}, [0, 0]),
    ("MysteryPath-Grid-v0", {"max_steps": 17}, 0),
    ("SearingSpotlights-v0", {"max_steps": 30, "spot_damage": 0.0}, [0, 0]),
    ("Endless-MortarMayhem-v0", {"max_steps": 12}, [0, 0]),  # the first check comes at step 22
    ("Endless-MysteryPath-v0", {"max_steps": 15, "stamina_level": 100}, 0),
    ("Endless-SearingSpotlights-v0", {"max_steps": 25, "spot_damage": 0.0}, [0, 0]),
]


@pytest.mark.parametrize(("env_id", "options", "action"), TIME_LIMITED)
def test_time_limited_episodes_last_exactly_max_episode_steps(env_id: str, options: dict, action: Any) -> None:
    env = gym.make(env_id)
    for seed in (0, 1):
        length = run_to_the_end(env, seed, options, action)
        assert length == env.unwrapped.max_episode_steps == expected(env_id, options)


def test_the_environments_page_example_gives_the_figures_it_names() -> None:
    page = (Path(__file__).resolve().parents[2] / "docs" / "environments.md").read_text()
    block = re.search(r"```python\n(.*?)```", page, re.S).group(1)
    named = int(re.search(r"^env\.unwrapped\.max_episode_steps  # (\d+):", block, re.M).group(1))
    scope: dict[str, Any] = {}
    exec(block, scope)  # the page's own example
    assert scope["env"].unwrapped.max_episode_steps == named == expected("MortarMayhem-Grid-v0", {"command_count": [5]})
    assert scope["vec"].max_episode_steps.tolist() == [named] * scope["vec"].num_envs
