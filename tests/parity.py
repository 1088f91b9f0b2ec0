"""Replay of reference traces (recorded from memory-gym==1.0.2 by scripts/reference_traces.py) against our envs.

Every episode of a trace file is replayed on one environment instance in file order (a fresh instance where the
trace says ``fresh_env``), with the recorded seed, options and actions. Each step is compared on the observation
digest, reward, terminated/truncated flags and info.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym

import envs  # noqa: F401  (registers the ids)
from scripts.trace_format import load_traces, obs_digest

TRACE_ROOT = Path(__file__).parent / "data" / "traces"
REFERENCE_IDS = [
    "MortarMayhem-v0",
    "MortarMayhem-Grid-v0",
    "MortarMayhemB-v0",
    "MortarMayhemB-Grid-v0",
    "MysteryPath-v0",
    "MysteryPath-Grid-v0",
    "SearingSpotlights-v0",
    "Endless-MortarMayhem-v0",
    "Endless-MysteryPath-v0",
    "Endless-SearingSpotlights-v0",
]


@dataclass
class ParityResult:
    """How many recorded frames (reset frames included) matched, and where the first mismatches were."""

    env_id: str
    episodes: int = 0
    steps: int = 0
    identical: int = 0
    mismatches: list[str] = field(default_factory=list)

    @property
    def percent(self) -> float:
        return 100.0 * self.identical / max(self.steps, 1)


def values_equal(a: Any, b: Any) -> bool:
    """Equality for JSON-like values: numbers compare with a 1e-9 tolerance and NaN equals NaN."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(values_equal(a[k], b[k]) for k in a)
    if isinstance(a, list | tuple) and isinstance(b, list | tuple):
        return len(a) == len(b) and all(values_equal(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, int | float) and isinstance(b, int | float):
        if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
            return True
        return math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-9)
    return a == b


def jsonable(value: Any) -> Any:
    """Numpy arrays and scalars as plain python lists and numbers (as the traces store them)."""
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, dict):
        return {k: jsonable(v) for k, v in value.items()}
    return value


def replay(env_id: str, root: Path = TRACE_ROOT, max_mismatches: int = 5) -> ParityResult:
    """Replay every episode of ``env_id``'s trace file and count identical steps."""
    trace = load_traces(env_id, root)
    result = ParityResult(env_id)
    env = None
    for episode in trace["episodes"]:
        if env is None or episode.get("fresh_env"):
            env = gym.make(env_id, disable_env_checker=True)
        result.episodes += 1
        obs, info = env.reset(seed=episode["seed"], options=episode["options"])
        frames = [(obs_digest(obs), None, None, None, jsonable(info))]
        expected = [(episode["reset_obs"], None, None, None, episode["reset_info"])]
        for t, action in enumerate(episode["actions"]):
            obs, reward, terminated, truncated, info = env.step(action)
            frames.append((obs_digest(obs), reward, terminated, truncated, jsonable(info)))
            expected.append(
                (
                    episode["obs"][t],
                    episode["rewards"][t],
                    episode["terminated"][t],
                    episode["truncated"][t],
                    episode["infos"][t],
                )
            )
        for t, (got, want) in enumerate(zip(frames, expected, strict=True)):
            result.steps += 1
            fields = ("obs", "reward", "terminated", "truncated", "info")
            wrong = [name for name, g, w in zip(fields, got, want, strict=True) if not values_equal(g, w)]
            if not wrong:
                result.identical += 1
            elif len(result.mismatches) < max_mismatches:
                detail = {name: (g, w) for name, g, w in zip(fields, got, want, strict=True) if name in wrong}
                result.mismatches.append(f"{episode['name']} step {t}: {detail} (got, expected)")
    if env is not None:
        env.close()
    return result
