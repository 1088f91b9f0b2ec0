"""Record ground-truth traces from the reference package memory-gym==1.0.2.

Runs INSIDE the isolated reference venv (it imports memory_gym, gymnasium 0.29 and numpy); normally started by
``scripts/reference_traces.py``. Run it from the repository root (``--out`` defaults to the committed data in
``tests/data/``):

    export SDL_VIDEODRIVER=dummy
    .venv-reference/bin/python -m scripts.reference.recorder traces [--ids ...] [--out tests/data/traces]
    .venv-reference/bin/python -m scripts.reference.recorder verify [--ids ...] [--out tests/data/traces]
    .venv-reference/bin/python -m scripts.reference.recorder mp-paths [--out tests/data/mp_paths.json.gz]

Everything is deterministic (fixed seeds, sorted JSON keys, gzip without timestamp): two runs give identical bytes.
The scripted policies read private members of the reference envs (target tile, path nodes, coin positions). With
probability ``DEVIATION`` per step they take a random action instead, held for 1 step, or for 1..``MAX_HOLD`` steps
in the "bursty" episodes (odd seeds 2001, 2003, ... and the unseeded one), so that failures, fall-offs and hits appear
as well.
"""

from __future__ import annotations

import argparse
import importlib.metadata
import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import memory_gym  # noqa: F401  (registers the ids)
import numpy as np

from scripts.reference import MP_PATHS_FILE, REFERENCE_IDS, TRACES_DIR
from scripts.reference.trace_format import DIGEST_METHOD, dump_json_gz, load_traces, obs_digest, to_jsonable

NUM_RANDOM = 12  # random episodes, reset(seed=1000 + k)
NUM_SCRIPTED = 12  # scripted episodes, reset(seed=2000 + k)
DEVIATION = 0.15  # probability of starting a random deviation in the scripted policy
MAX_HOLD = 8  # longest deviation (steps) in the "bursty" scripted episodes
ENDLESS_CUT = 400  # endless episodes are cut (``"cut": true``) after this many steps
FINITE_CAP = 1000  # safety cap for the finite envs (never reached: their own limits are lower)

MM_OPTIONS: list[dict[str, Any]] = [
    {"command_count": [5]},
    {"arena_size": 3},
    {"allowed_commands": 5, "explosion_delay": [10]},
    {"visual_feedback": False},
]
MP_OPTIONS: list[dict[str, Any]] = [
    {"show_origin": True, "show_goal": True},
    {"reward_path_progress": 0.0, "cardinal_origin_choice": [2]},
    {"visual_feedback": False},
]
# Options run in sequence on the shared instance, then options that leak across resets in the reference
# (hide_chessboard / black_background repaint the floor surfaces permanently), each on a fresh instance.
OPTIONS: dict[str, list[dict[str, Any]]] = {
    "MortarMayhem-v0": MM_OPTIONS,
    "MortarMayhem-Grid-v0": MM_OPTIONS,
    "MortarMayhemB-v0": MM_OPTIONS,
    "MortarMayhemB-Grid-v0": MM_OPTIONS,
    "MysteryPath-v0": MP_OPTIONS,
    "MysteryPath-Grid-v0": MP_OPTIONS,
    "SearingSpotlights-v0": [
        {"agent_visible": True, "coins_visible": True, "exit_visible": True},
        {"agent_visible": True},
        {"exit_visible": True},
        {"light_threshold": 200},
        {"initial_spawns": 0, "num_spawns": 0},
        {"num_coins": [2, 3]},
        {"sample_agent_position": False},
        {"num_coins": [0]},
    ],
    "Endless-MortarMayhem-v0": [
        {"allowed_commands": 5, "initial_command_count": 3},
        {"visual_feedback": False},
        {"max_steps": 300},
    ],
    "Endless-MysteryPath-v0": [
        {"show_background": True, "show_stamina": True},
        {"show_past_path": False},
        {"max_steps": 300},
    ],
    "Endless-SearingSpotlights-v0": [
        {"coins_visible": True, "agent_visible": True},
        {"max_steps": 300},
    ],
}
FRESH_OPTIONS: dict[str, list[dict[str, Any]]] = {
    "SearingSpotlights-v0": [{"hide_chessboard": True}, {"black_background": True}],
    "Endless-SearingSpotlights-v0": [{"hide_chessboard": True}, {"black_background": True}],
}

FAIL_LAST_IDS = ["MortarMayhem-v0", "MortarMayhem-Grid-v0", "MortarMayhemB-v0", "MortarMayhemB-Grid-v0"]

Action = Any  # int (Discrete) or [int, int] (MultiDiscrete)


def _reference_versions() -> dict[str, str]:
    return {
        "memory_gym": importlib.metadata.version("memory-gym"),
        "gymnasium": importlib.metadata.version("gymnasium"),
        "pygame": importlib.metadata.version("pygame"),
        "numpy": importlib.metadata.version("numpy"),
    }


def reference_obs_digest(obs: Any) -> str:
    """Digest of a reference observation: its obs[x][y][c] image is transposed to (row, column, channel) first."""
    if isinstance(obs, dict):
        return obs_digest({**obs, "visual_observation": obs["visual_observation"].transpose(1, 0, 2)})
    return obs_digest(obs.transpose(1, 0, 2))


# ----------------------------------------------------------------------------------------------------------------
# Scripted (target-seeking) policies. Each takes the unwrapped env and returns the oracle action.


def _toward(src: tuple[float, float], dst: tuple[float, float], dead: float = 1) -> list[int]:
    """MultiDiscrete action moving from ``src`` toward ``dst`` (per axis: 0 when within ``dead`` px)."""
    dx, dy = dst[0] - src[0], dst[1] - src[1]
    a0 = 0 if abs(dx) <= dead else (1 if dx < 0 else 2)
    a1 = 0 if abs(dy) <= dead else (1 if dy < 0 else 2)
    return [a0, a1]


def _grid_step(pos: tuple[int, int], rotation: int, target: tuple[int, int]) -> int:
    """Discrete grid action (1 turn left, 2 turn right, 3 forward) toward an orthogonally adjacent or aligned tile."""
    x, y = int(pos[0]), int(pos[1])
    tx, ty = int(target[0]), int(target[1])
    if (x, y) == (tx, ty):
        return 0
    if tx > x:
        want = 270
    elif tx < x:
        want = 90
    elif ty > y:
        want = 180
    else:
        want = 0
    if rotation == want:
        return 3
    return 1 if (want - rotation) % 360 in (90, 180) else 2


def _mm_target(e: Any, fail: bool) -> tuple[int, int]:
    """Current target tile; with ``fail``, a wrong tile while the last command is being executed."""
    tx, ty = int(e._target_pos[0]), int(e._target_pos[1])
    if fail and e._current_command == e.num_commands - 1 and not e.arena.tiles_on:
        tx = (tx + 2) % e.reset_params["arena_size"]
    return tx, ty


def _mm_oracle(e: Any, fail: bool = False) -> list[int]:
    if e._command_visualization:
        return [0, 0]
    tile = int(e.arena.tile_dim)
    tx, ty = _mm_target(e, fail)
    return _toward(
        e.agent.rect.center, (e.arena.rect.x + tx * tile + tile // 2, e.arena.rect.y + ty * tile + tile // 2)
    )


def _emm_oracle(e: Any) -> list[int]:
    """Endless MM: like ``_mm_oracle`` but the arena is a torus, so move along the shorter way per axis."""
    if e._command_visualization:
        return [0, 0]
    tile, dim = int(e.arena.tile_dim), e.screen_dim
    tx, ty = int(e._target_pos[0]), int(e._target_pos[1])
    ax, ay = e.agent.rect.center
    dx = (tx * tile + tile // 2 - ax + dim // 2) % dim - dim // 2
    dy = (ty * tile + tile // 2 - ay + dim // 2) % dim - dim // 2
    return _toward((0, 0), (dx, dy))


def _mm_grid_oracle(e: Any, fail: bool = False) -> int:
    if e._command_visualization:
        return 0
    return _grid_step(e.agent.grid_position, e.agent.rotation, _mm_target(e, fail))


def _mp_next_tile(e: Any, pos: tuple[int, int]) -> tuple[int, int] | None:
    path = [(int(n.x), int(n.y)) for n in reversed(e.mystery_path.path)]  # origin -> goal
    pos = (int(pos[0]), int(pos[1]))
    if pos not in path or pos == path[-1]:
        return None
    return path[path.index(pos) + 1]


def _mp_oracle(e: Any) -> list[int]:
    nxt = _mp_next_tile(e, e.normalized_agent_position)
    if nxt is None:
        return [0, 0]
    return _toward(e.agent.rect.center, (nxt[0] * e.tile_dim + e.tile_dim // 2, nxt[1] * e.tile_dim + e.tile_dim // 2))


def _mp_grid_oracle(e: Any) -> int:
    nxt = _mp_next_tile(e, e.agent.grid_position)
    if nxt is None:
        return 0
    return _grid_step(e.agent.grid_position, e.agent.rotation, nxt)


def _ss_oracle(e: Any) -> list[int]:
    agent = e.agent.rect.center
    if e.coins:
        coin = min(e.coins, key=lambda c: (c.location[0] - agent[0]) ** 2 + (c.location[1] - agent[1]) ** 2)
        return _toward(agent, coin.location)
    return _toward(agent, e.exit.location)


def _emp_oracle(e: Any) -> int:
    nxt = e.current_node.next_node
    ty = nxt.y * e.tile_dim + e.tile_dim // 2
    ay = e.agent.rect.center[1]
    if abs(ty - ay) >= 3:
        return 2 if ty < ay else 3
    return 1


def _ess_oracle(e: Any) -> list[int]:
    return _toward(e.agent.rect.center, e.coin.location)


ORACLES: dict[str, Callable[..., Action]] = {
    "MortarMayhem-v0": _mm_oracle,
    "MortarMayhem-Grid-v0": _mm_grid_oracle,
    "MortarMayhemB-v0": _mm_oracle,
    "MortarMayhemB-Grid-v0": _mm_grid_oracle,
    "MysteryPath-v0": _mp_oracle,
    "MysteryPath-Grid-v0": _mp_grid_oracle,
    "SearingSpotlights-v0": _ss_oracle,
    "Endless-MortarMayhem-v0": _emm_oracle,
    "Endless-MysteryPath-v0": _emp_oracle,
    "Endless-SearingSpotlights-v0": _ess_oracle,
}


# ----------------------------------------------------------------------------------------------------------------
# Recording


def _plain_action(action: Any) -> Action:
    """A sampled or scripted action as python int / [int, int] (exactly what is passed to ``step``)."""
    return to_jsonable(np.asarray(action))


def _random_action_like(space: gym.Space, rng: np.random.Generator) -> Action:
    if isinstance(space, gym.spaces.Discrete):
        return int(rng.integers(0, int(space.n)))
    return [int(rng.integers(0, int(n))) for n in space.nvec]


def record_episode(
    env: gym.Env,
    env_id: str,
    name: str,
    policy: str,
    seed: int | None,
    options: dict[str, Any] | None,
    policy_rng: np.random.Generator | None = None,
    max_hold: int = 1,
    deviation: float = DEVIATION,
    fail_last: bool = False,
) -> dict[str, Any]:
    """Reset ``env`` with ``seed``/``options`` and play one episode.

    ``policy`` is ``"random"`` (``env.action_space.sample()``) or ``"scripted"``: the oracle, deviating with
    probability ``deviation`` to a random action from ``policy_rng`` held for 1..``max_hold`` steps. ``fail_last``
    (Mortar Mayhem, finite) makes the oracle aim at a wrong tile for the last command.
    """
    obs, info = env.reset(seed=seed, options=options)
    ep: dict[str, Any] = {
        "name": name,
        "policy": policy,
        "seed": seed,
        "options": options,
        "reset_obs": reference_obs_digest(obs),
        "reset_info": to_jsonable(info),
        "actions": [],
        "obs": [],
        "rewards": [],
        "terminated": [],
        "truncated": [],
        "infos": [],
    }
    cap = ENDLESS_CUT if env_id.startswith("Endless-") else FINITE_CAP
    oracle = ORACLES[env_id]
    held, hold_left = None, 0
    for _ in range(cap):
        if policy == "random":
            action = _plain_action(env.action_space.sample())
        elif hold_left > 0:
            action, hold_left = held, hold_left - 1
        elif policy_rng.random() < deviation:
            action = held = _random_action_like(env.action_space, policy_rng)
            hold_left = int(policy_rng.integers(0, max_hold))
        else:
            action = _plain_action(oracle(env.unwrapped, fail=True) if fail_last else oracle(env.unwrapped))
        obs, reward, terminated, truncated, info = env.step(action)
        ep["actions"].append(action)
        ep["obs"].append(reference_obs_digest(obs))
        ep["rewards"].append(float(reward))
        ep["terminated"].append(bool(terminated))
        ep["truncated"].append(bool(truncated))
        ep["infos"].append(to_jsonable(info))
        if terminated or truncated:
            break
    else:
        ep["cut"] = True
    return ep


def _make(env_id: str) -> gym.Env:
    return gym.make(env_id, disable_env_checker=True)


def record_env(env_id: str) -> dict[str, Any]:
    """All episodes of one id: on one instance in file order, except the ``fresh_env`` ones."""
    env = _make(env_id)
    env.action_space.seed(123)
    episodes: list[dict[str, Any]] = []
    counter = 0

    def scripted(target: gym.Env, name: str, seed: int | None, options: Any = None, **kw: Any) -> dict[str, Any]:
        nonlocal counter
        counter += 1
        return record_episode(
            target, env_id, name, "scripted", seed, options, np.random.default_rng([7, counter]), **kw
        )

    for k in range(NUM_RANDOM):
        episodes.append(record_episode(env, env_id, f"random-{1000 + k}", "random", 1000 + k, None))
    episodes.append(record_episode(env, env_id, "random-noseed", "random", None, None))
    for k in range(NUM_SCRIPTED):
        episodes.append(scripted(env, f"scripted-{2000 + k}", 2000 + k, max_hold=MAX_HOLD if k % 2 else 1))
    episodes.append(scripted(env, "scripted-noseed", None, max_hold=MAX_HOLD))
    if env_id in FAIL_LAST_IDS:
        episodes.append(scripted(env, "scripted-faillast-2100", 2100, deviation=0.0, fail_last=True))
    for k, opts in enumerate(OPTIONS[env_id]):
        episodes.append(scripted(env, f"options-scripted-{3000 + k}", 3000 + k, opts))
        episodes.append(record_episode(env, env_id, f"options-random-{4000 + k}", "random", 4000 + k, opts))
    for k, opts in enumerate(FRESH_OPTIONS.get(env_id, [])):
        fresh = _make(env_id)  # never close(): it would quit pygame for every instance of the process
        ep = scripted(fresh, f"fresh-scripted-{5000 + k}", 5000 + k, opts)
        ep["fresh_env"] = True
        episodes.append(ep)
    return {"env_id": env_id, "reference": _reference_versions(), "digest": DIGEST_METHOD, "episodes": episodes}


def _canon(value: Any) -> str:
    """Canonical JSON text of a recorded value (NaN-safe equality)."""
    return json.dumps(to_jsonable(value), sort_keys=True)


def verify_env(trace: dict[str, Any]) -> list[str]:
    """Replay a trace file's recorded actions on the reference and return the mismatches (empty when consistent)."""
    env_id = trace["env_id"]
    env = _make(env_id)
    errors = []
    for ep in trace["episodes"]:
        target = _make(env_id) if ep.get("fresh_env") else env
        obs, info = target.reset(seed=ep["seed"], options=ep["options"])
        got = [(reference_obs_digest(obs), _canon(info))]
        want = [(ep["reset_obs"], _canon(ep["reset_info"]))]
        for t, action in enumerate(ep["actions"]):
            obs, reward, terminated, truncated, info = target.step(action)
            got.append((reference_obs_digest(obs), float(reward), bool(terminated), bool(truncated), _canon(info)))
            want.append(
                (ep["obs"][t], ep["rewards"][t], ep["terminated"][t], ep["truncated"][t], _canon(ep["infos"][t]))
            )
        errors += [
            f"{env_id} {ep['name']} t={t}: {g} != {w}" for t, (g, w) in enumerate(zip(got, want, strict=True)) if g != w
        ][:3]
    return errors


def _xy(node: Any) -> list[int]:
    return [int(node.x), int(node.y)]


def record_mp_paths() -> dict[str, Any]:
    """Mystery Path layouts (origin, goal, path origin->goal, sorted walls) and Endless Mystery Path segments."""
    env = _make("MysteryPath-v0")
    layouts = []
    runs = [(seed, None) for seed in range(300)]
    runs += [(seed, {"cardinal_origin_choice": [c]}) for c in range(4) for seed in range(50)]
    for seed, options in runs:
        env.reset(seed=seed, options=options)
        e = env.unwrapped
        layouts.append(
            {
                "seed": seed,
                "options": options,
                "origin": [int(v) for v in e.start],
                "goal": [int(v) for v in e.end],
                "path": [_xy(n) for n in reversed(e.mystery_path.path)],
                "walls": sorted(_xy(n) for n in e.mystery_path.wall_nodes),
            }
        )
    env = _make("Endless-MysteryPath-v0")
    endless = []
    for seed in range(100):
        env.reset(seed=seed)
        segments = env.unwrapped.endless_path.path[:3]
        endless.append({"seed": seed, "segments": [[_xy(n) for n in seg] for seg in segments]})
    return {
        "reference": _reference_versions(),
        "MysteryPath-v0": layouts,
        "Endless-MysteryPath-v0": endless,
    }


def main(argv: list[str] | None = None) -> None:
    """CLI: ``traces [--ids ...] --out DIR``, ``verify [--ids ...] --out DIR`` or ``mp-paths --out FILE``."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    p_tr = sub.add_parser("traces", help="record <out>/<env_id>.json.gz")
    p_tr.add_argument("--ids", nargs="+", default=REFERENCE_IDS, choices=REFERENCE_IDS)
    p_tr.add_argument("--out", type=Path, default=TRACES_DIR)
    p_ve = sub.add_parser("verify", help="replay <out>/<env_id>.json.gz on the reference")
    p_ve.add_argument("--ids", nargs="+", default=REFERENCE_IDS, choices=REFERENCE_IDS)
    p_ve.add_argument("--out", type=Path, default=TRACES_DIR)
    p_mp = sub.add_parser("mp-paths", help="record the Mystery Path layouts")
    p_mp.add_argument("--out", type=Path, default=MP_PATHS_FILE)
    args = parser.parse_args(argv)

    os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
    if args.command == "traces":
        for env_id in args.ids:
            data = record_env(env_id)
            path = args.out / f"{env_id}.json.gz"
            dump_json_gz(data, path)
            steps = sum(len(ep["actions"]) for ep in data["episodes"])
            print(f"{env_id}: {len(data['episodes'])} episodes, {steps} steps -> {path}", flush=True)
    elif args.command == "verify":
        errors = []
        for env_id in args.ids:
            found = verify_env(load_traces(env_id, args.out))
            print(f"{env_id}: {'OK' if not found else f'{len(found)} mismatches (at most 3 per episode)'}", flush=True)
            errors += found
        if errors:
            raise SystemExit("\n".join(errors))
    else:
        dump_json_gz(record_mp_paths(), args.out)
        print(f"mp paths -> {args.out}", flush=True)


if __name__ == "__main__":
    main()
