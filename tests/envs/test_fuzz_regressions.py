"""Regressions for what the fuzzed environments (tests/envs/test_fuzz.py) found: each fails without its fix."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from scripts.reference.parity import replay
from scripts.reference.trace_format import load_traces

MM_IDS = ["MortarMayhem-v0", "MortarMayhem-Grid-v0", "MortarMayhemB-v0", "MortarMayhemB-Grid-v0"]
ENDLESS_MM = "Endless-MortarMayhem-v0"


def _played(env_id: str, render_mode: str | None = None, carryover: bool = False) -> gym.Env:
    """An instance that played a few steps of another episode (its agent moved away from the next spawn)."""
    env = gym.make(env_id, render_mode=render_mode, disable_env_checker=True)
    env.unwrapped.core.reference_carryover = carryover
    env.reset(seed=7)
    action = 3 if isinstance(env.action_space, gym.spaces.Discrete) else np.array([2, 2])
    for _ in range(30):
        if env.step(action)[2]:
            break
    return env


def test_endless_mortar_mayhem_clue_frames_do_not_show_the_previous_episode() -> None:
    """memory-gym drew the previous episode's last agent sprite in the first clue frames of the next episode of the
    same instance; here every episode plays as on a fresh instance (a documented deviation)."""
    used, fresh = _played(ENDLESS_MM), gym.make(ENDLESS_MM, disable_env_checker=True)
    frames = [(used.reset(seed=3)[0], fresh.reset(seed=3)[0])]
    for _ in range(8):
        frames.append((used.step(np.array([0, 0]))[0], fresh.step(np.array([0, 0]))[0]))
    for t, (a, b) in enumerate(frames):
        assert np.array_equal(a, b), f"step {t}: the frame depends on the previous episode"


def test_reference_carryover_still_reproduces_memory_gym() -> None:
    """With ``reference_carryover`` (the parity replays) the first clue frames show the old sprite, as recorded."""
    used, fresh = _played(ENDLESS_MM, carryover=True), gym.make(ENDLESS_MM, disable_env_checker=True)
    used.reset(seed=3), fresh.reset(seed=3)
    a, b = used.step(np.array([0, 0]))[0], fresh.step(np.array([0, 0]))[0]
    assert not np.array_equal(a, b)


@pytest.mark.parametrize("env_id", [*MM_IDS, ENDLESS_MM])
def test_mortar_mayhem_debug_view_of_a_reset_shows_the_new_agent(env_id: str) -> None:
    used = _played(env_id, render_mode="debug_rgb_array")
    fresh = gym.make(env_id, render_mode="debug_rgb_array", disable_env_checker=True)
    used.reset(seed=3), fresh.reset(seed=3)
    assert np.array_equal(used.render(), fresh.render()), "the debug view shows the previous episode's agent"


def test_without_carryover_the_trace_differs_only_in_the_documented_frames() -> None:
    """The deviation is exactly the leftover sprite: replaying Endless Mortar Mayhem's reference traces without the
    carry-over differs only in observations of the first clue stream (steps 1 .. C - 1) of episodes that followed
    another episode on the same instance; every reward, flag, info and later frame is the reference's."""
    episodes = load_traces(ENDLESS_MM)["episodes"]
    result = replay(ENDLESS_MM, max_mismatches=10**6, carryover=False)
    assert result.steps > 0 and result.identical < result.steps  # the traces do show the reference's leftover
    names = [ep["name"] for ep in episodes]
    for mismatch in result.mismatches:
        name, _, rest = mismatch.partition(" step ")
        step, options = int(rest.split(":")[0]), episodes[names.index(name)]["options"] or {}
        stream = options.get("initial_command_count", 1) * 4  # icon 3 frames + 1 blank per command (defaults)
        assert names.index(name) > 0 and 1 <= step < stream, mismatch
        assert rest.split(": ", 1)[1].startswith("{'obs'") and "'reward'" not in rest and "'info'" not in rest
