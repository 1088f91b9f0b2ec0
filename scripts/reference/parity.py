"""Replay of reference traces (recorded from memory-gym==1.0.2 by scripts/reference_traces.py) against our envs.

Every episode of a trace file is replayed on one environment instance in file order (a fresh instance where the
trace says ``fresh_env``), with the recorded seed, options and actions. Each step is compared on the observation
digest, reward, terminated/truncated flags and info. Info keys that our core declares in its ``added_info_keys``
(keys that memory-gym does not have) are left out of the comparison.

Runs with the project's python (it imports ``envs``), never inside the reference venv. Used by
``scripts/parity_report.py`` and ``tests/reference/test_parity.py``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import envs  # registers the ids; make_core for the batched replay
from envs.compare import jsonable, values_equal
from scripts.reference import TRACES_DIR
from scripts.reference.trace_format import load_traces, obs_digest


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


def added_info_keys(core: Any) -> frozenset[str]:
    """The info keys that ``core`` adds beyond the reference's (declared by the core class; none by default)."""
    return frozenset(getattr(core, "added_info_keys", frozenset()))


def reference_info(info: dict[str, Any], added: frozenset[str]) -> Any:
    """One of our infos as the trace stores the reference's: without the ``added`` keys, as plain python values."""
    return jsonable({key: value for key, value in info.items() if key not in added})


def replay(env_id: str, root: Path = TRACES_DIR, max_mismatches: int = 5, carryover: bool = True) -> ParityResult:
    """Replay every episode of ``env_id``'s trace file and count identical steps. ``carryover``: draw what the
    reference's instance carried over from its previous episode (``BatchedCore.reference_carryover``, a documented
    deviation that is off by default), as the traces recorded it."""
    trace = load_traces(env_id, root)
    result = ParityResult(env_id)
    env = None
    for episode in trace["episodes"]:
        if env is None or episode.get("fresh_env"):
            env = gym.make(env_id, disable_env_checker=True)
            env.unwrapped.core.reference_carryover = carryover
        result.episodes += 1
        added = added_info_keys(env.unwrapped.core)
        obs, info = env.reset(seed=episode["seed"], options=episode["options"])
        frames = [(obs_digest(obs), None, None, None, reference_info(info, added))]
        expected = [(episode["reset_obs"], None, None, None, episode["reset_info"])]
        for t, action in enumerate(episode["actions"]):
            obs, reward, terminated, truncated, info = env.step(action)
            frames.append((obs_digest(obs), reward, terminated, truncated, reference_info(info, added)))
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


def replay_batched(env_id: str, root: Path = TRACES_DIR, max_mismatches: int = 5) -> ParityResult:
    """Replay the seeded trace episodes each in its own slot of ONE batched core, stepping the live slots together.

    This checks the vectorised step against the reference (the single-env face may take per-slot fast paths). The
    reference drew some frames from what the previous episode of the same instance left behind (e.g. Endless Mortar
    Mayhem's first clue frames show the last agent sprite), so each slot first plays, unchecked, the episode that
    preceded its own in the trace file; episodes whose predecessor was unseeded are left to :func:`replay`.
    """

    trace = load_traces(env_id, root)["episodes"]
    chosen = [
        (trace[i - 1] if i > 0 and not ep.get("fresh_env") else None, ep)
        for i, ep in enumerate(trace)
        if ep["seed"] is not None and (i == 0 or ep.get("fresh_env") or trace[i - 1]["seed"] is not None)
    ]
    core = envs.make_core(env_id, num_envs=len(chosen))
    core.reference_carryover = True  # the traces show what the reference carried over (see ``replay``)
    added = added_info_keys(core)
    episodes = [ep for _, ep in chosen]
    result = ParityResult(env_id, episodes=len(episodes))

    def check(name: str, t: int, got: tuple, want: tuple) -> None:
        result.steps += 1
        if all(values_equal(g, w) for g, w in zip(got, want, strict=True)):
            result.identical += 1
        elif len(result.mismatches) < max_mismatches:
            result.mismatches.append(f"{name} step {t}: got {got}, expected {want}")

    def frames_of(slots: np.ndarray) -> list:
        frames = core.observations(slots)
        if isinstance(frames, dict):
            return [{key: v[i] for key, v in frames.items()} for i in range(slots.size)]
        return list(frames)

    # Slots whose episodes share options are reset together (``reset_slots``), as the trainer resets them.
    def reset_groups(eps: list[tuple[int, dict]]) -> None:
        groups: dict[str, list[tuple[int, dict]]] = {}
        for k, ep in eps:
            groups.setdefault(json.dumps(ep["options"], sort_keys=True), []).append((k, ep))
        for group in groups.values():
            core.reset_slots([k for k, _ in group], [ep["seed"] for _, ep in group], group[0][1]["options"])

    previous_eps = [(k, previous) for k, (previous, _) in enumerate(chosen) if previous is not None]
    reset_groups(previous_eps)  # rebuild what the reference instance carried over
    for k, previous in previous_eps:
        for action in previous["actions"]:
            core.step(np.array([action]), idx=np.array([k]))
    reset_groups(list(enumerate(episodes)))
    reset_frames = frames_of(np.arange(len(episodes)))
    for k, ep in enumerate(episodes):
        check(ep["name"], 0, (obs_digest(reset_frames[k]),), (ep["reset_obs"],))
    for t in range(max(len(ep["actions"]) for ep in episodes)):
        live = np.array([k for k, ep in enumerate(episodes) if t < len(ep["actions"])])
        actions = np.array([episodes[k]["actions"][t] for k in live])
        rewards, terminated, finals = core.step(actions, idx=live if live.size < len(episodes) else None)
        frames = frames_of(live)
        for i, k in enumerate(live.tolist()):
            ep = episodes[k]
            info = core.step_info(k)
            info.update(finals.get(k, {}))
            got = (obs_digest(frames[i]), float(rewards[i]), bool(terminated[i]), reference_info(info, added))
            want = (ep["obs"][t], ep["rewards"][t], ep["terminated"][t], ep["infos"][t])
            check(ep["name"], t + 1, got, want)
    return result
