"""Property-based fuzzing of every environment id (Hypothesis, from the dev extra: this module is imported only by the
fuzz tests and ``scripts/fuzz_envs.py``, never by ``envs`` itself): strategies for valid and invalid options, seeds and
action scripts, and the properties that ``tests/envs/test_fuzz.py`` runs in CI and ``scripts/fuzz_envs.py`` runs at
length.

Profiles (``HYPOTHESIS_PROFILE``, read at import): ``ci`` (the default) tries a few derandomized cases per id and
property, so CI is reproducible and adds well under a minute; ``long`` tries many random ones with more slots and
longer episodes. Options are drawn from each option's documented range (``Option.low``/``high``); where a range is
open, values are drawn up to a cap (``OPEN_RANGE_CAPS``) so that a case stays seconds long.

Properties (one Hypothesis test per property and id):

* :func:`check_faces_agree`: n single envs, the vector face and the batched core (stepped in random slot subsets),
  given one random script of resets (seeded, unseeded, masked, with options) and steps, agree slot for slot (frames,
  rewards, flags, infos); nothing raises; observations lie in the observation space; infos have the documented keys.
* :func:`check_reset_is_fresh`: after any history (episodes with other options, resets in the middle of episodes),
  ``reset(seed=s, options=o)`` plays the same episode, frame for frame and debug picture for debug picture, as a fresh
  instance reset with them; likewise for a batched core reset after a history of its own.
* :func:`check_invalid_input_refused`: invalid options, seeds and actions raise ``ValueError`` naming the key or the
  slot; a refused action changes nothing (the episode goes on as if it was never sent), and after a refused reset a
  valid one plays the fresh episode.
"""

from __future__ import annotations

import math
import os
import time
import traceback
from collections import Counter
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.error import ResetNeeded
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import envs
from envs.compare import jsonable, values_equal
from envs.core import BatchedCore
from envs.options import Option

ALL_IDS = list(envs.ENV_IDS)

# ------------------------------------------------------------------------------------------------------ profiles
_COMMON = {"deadline": None, "suppress_health_check": [HealthCheck.too_slow, HealthCheck.data_too_large]}
settings.register_profile("ci", max_examples=30, derandomize=True, database=None, print_blob=True, **_COMMON)
settings.register_profile("long", max_examples=20, derandomize=False, print_blob=True, **_COMMON)
PROFILE = os.environ.get("HYPOTHESIS_PROFILE", "ci")
settings.load_profile(PROFILE)


@dataclass(frozen=True)
class Scale:
    """How big one case may get under a profile."""

    max_slots: int  # slots of the vector face and the core (that many single envs beside them)
    max_steps: int  # steps of a script
    max_events: int  # resets and step runs of a script
    episode_steps: int  # steps of the episode compared after a history (a long episode)


SCALES = {"ci": Scale(3, 40, 4, 60), "long": Scale(16, 400, 12, 1000)}
SCALE = SCALES.get(PROFILE, SCALES["ci"])

# Cases tried, per (property, env id): read by scripts/fuzz_envs.py for results/reliability.json.
CASES: Counter[tuple[str, str]] = Counter()

# ------------------------------------------------------------------------------------------- documented info keys
# docs/environments.md and docs/environment_notes.md: the keys of the final info of each id (memory-gym's, plus the
# keys the core lists in ``added_info_keys``), and ``ground_truth`` on every step and reset of the endless ids.
_MM = {"reward", "length", "success", "commands_completed", "checks_passed", "command_count"}
FINAL_INFO_KEYS: dict[str, set[str]] = {
    "ProofOfMemory-v0": {"reward", "length", "success"},
    "MortarMayhem-v0": _MM,
    "MortarMayhem-Grid-v0": _MM,
    "MortarMayhemB-v0": _MM,
    "MortarMayhemB-Grid-v0": _MM,
    "Endless-MortarMayhem-v0": {"reward", "length", "commands_completed", "max_command_sequence", "checks_passed"},
    "MysteryPath-v0": {"reward", "length", "success", "num_fails"},
    "MysteryPath-Grid-v0": {"reward", "length", "success", "num_fails"},
    "Endless-MysteryPath-v0": {"reward", "length", "num_fails", "max_x", "tiles_visited"},
    "SearingSpotlights-v0": {"reward", "length", "agent_health", "coins_collected", "success"},
    "Endless-SearingSpotlights-v0": {"reward", "length", "agent_health", "coins_collected"},
}


def step_info_keys(env_id: str) -> set[str]:
    return {"ground_truth"} if env_id.startswith("Endless-") else set()


# ----------------------------------------------------------------------------------------------------- options
# Caps of open ranges (the documented range has no upper bound, or no lower one): values stay in the range, and a
# case stays seconds long (a clue stream of 40 commands shown 20 frames each is already 800 steps).
OPEN_RANGE_CAPS: dict[str, tuple[float, float]] = {
    "max_steps": (-3, 600),
    "command_count": (1, 40),
    "initial_command_count": (1, 30),
    "command_show_duration": (1, 12),
    "command_show_delay": (0, 12),
    "explosion_duration": (1, 30),
    "explosion_delay": (1, 40),
    "agent_speed": (0, 200),
    "stamina_level": (1, 120),
    "spot_damage": (0, 20),
    "light_dim_off_duration": (0, 30),
    "agent_health": (1, 40),
    "initial_spawn_interval": (0, 100),
    "spawn_interval_threshold": (0, 100),
    "steps_per_coin": (-1, 300),
    "spawn_interval": (1, 200),
    "coin_show_duration": (0, 30),
    # 10 coins fail to fit in ~3.5% of levels: a documented RuntimeError ("no free spawn position left")
    "num_coins": (0, 9),
}
_DEFAULT_OPEN = (-1000.0, 1000.0)  # rewards


def _bounds(key: str, spec: Option) -> tuple[float, float]:
    """The documented range, within the key's cap (the ends of the documented range are drawn too: ``_ends``)."""
    cap_low, cap_high = OPEN_RANGE_CAPS.get(key, _DEFAULT_OPEN)
    low = cap_low if spec.low is None else max(spec.low, cap_low)
    high = cap_high if spec.high is None else min(spec.high, cap_high)
    return low, high


def _ends(spec: Option) -> list[float]:
    return [end for end in (spec.low, spec.high) if end is not None]


def _number(spec_kind: str, low: float, high: float) -> st.SearchStrategy[Any]:
    """A valid number: ints (also numpy's) for int options; floats, ints and numpy scalars for float options."""
    if spec_kind == "int":
        ints = st.integers(math.ceil(low), math.floor(high))
        return st.one_of(ints, ints.map(np.int64))
    floats = st.floats(low, high, allow_nan=False, allow_infinity=False)
    ints = st.integers(math.ceil(low), math.floor(high))
    return st.one_of(floats, ints, floats.map(np.float64), ints.map(np.int32))


def option_value(key: str, spec: Option) -> st.SearchStrategy[Any]:
    """A value of option ``key`` inside its documented range."""
    if spec.kind == "bool":
        return st.one_of(st.booleans(), st.booleans().map(np.bool_))
    low, high = _bounds(key, spec)
    kind = "int" if spec.kind.startswith("int") else "float"
    entry = _number(kind, low, high)
    ends = _ends(spec)
    if ends:  # now and then an end of the documented range, beyond the cap (a huge speed, 100 commands, ...)
        entry = st.one_of(entry, st.sampled_from(ends).map(int if kind == "int" else float))
    if spec.kind in ("int", "float"):
        return entry
    lists = st.lists(entry, min_size=0 if spec.allow_empty else 1, max_size=4)
    return st.one_of(lists, lists.map(tuple))


@st.composite
def options(draw: st.DrawFn, specs: dict[str, Option], env_id: str) -> dict[str, Any] | None:
    """``None``, ``{}`` or a random subset of the options with valid values (also valid together)."""
    if draw(st.integers(0, 4)) == 0:
        return draw(st.sampled_from([None, {}]))
    keys = draw(st.lists(st.sampled_from(sorted(specs)), unique=True, max_size=len(specs)))
    chosen = {key: draw(option_value(key, specs[key])) for key in keys}
    for low, high in (("spot_min_radius", "spot_max_radius"), ("spot_min_speed", "spot_max_speed")):
        if low in specs:  # Searing Spotlights: min <= max (defaults fill the missing side)
            a, b = chosen.get(low, specs[low].default), chosen.get(high, specs[high].default)
            if a > b:
                chosen[low], chosen[high] = b, a
    return chosen


@st.composite
def invalid_option(draw: st.DrawFn, specs: dict[str, Option]) -> tuple[Any, str]:
    """Options that must be refused, and the text the message must contain (the key, or "mapping")."""
    kind = draw(st.sampled_from(["unknown", "type", "range", "nonfinite", "huge", "not_a_mapping", "empty_list"]))
    if kind == "not_a_mapping":
        return draw(st.sampled_from([[1, 2], "command_count", 3, ("a", 1)])), "mapping"
    if kind == "unknown":
        key = draw(st.text(min_size=1, max_size=12).filter(lambda k: k not in specs))
        return {key: 1}, repr(key)
    key = draw(st.sampled_from(sorted(specs)))
    spec = specs[key]
    scalar = spec.kind in ("int", "float")
    if kind == "type":
        bad = {
            "bool": [1, 0, "yes", None, 1.0],
            "int": ["3", None, 2.5, [1], True],
            "float": ["0.5", None, [0.5], True, complex(1, 1)],
            "int_list": [3, "3", [1.5], [None], [True], {"a": 1}],
            "float_list": [0.5, "0.5", [None], ["x"], [True]],
        }[spec.kind]
        value = draw(st.sampled_from(bad))
    elif kind == "nonfinite" and spec.kind in ("float", "float_list"):
        bad_number = draw(st.sampled_from([math.nan, math.inf, -math.inf, np.float64("nan"), 10**400]))
        value = bad_number if scalar else [bad_number]
    elif kind == "huge" and spec.kind in ("int", "int_list"):
        bad_number = draw(st.sampled_from([2**63, -(2**63) - 1, 10**30]))
        value = bad_number if scalar else [bad_number]
    elif kind == "empty_list" and spec.kind.endswith("list") and not spec.allow_empty:
        value = []
    elif spec.kind != "bool" and (spec.low is not None or spec.high is not None):
        sides = [s for s in ("low", "high") if getattr(spec, s) is not None]
        side = draw(st.sampled_from(sides))
        step = 1 if spec.kind.startswith("int") else draw(st.sampled_from([1e-6, 0.5, 1e9]))
        out = spec.low - step if side == "low" else spec.high + step
        if spec.kind.startswith("int"):
            out = int(math.floor(out)) if side == "low" else int(math.ceil(out))
        value = out if scalar else [out]
    else:
        value = draw(st.sampled_from(["x", None]))
    return {key: value}, repr(key)


# ------------------------------------------------------------------------------------------------------ scripts
@dataclass
class Reset:
    seed: int | list[int | None] | None  # one seed (slot k gets seed + k), one per slot, or none
    options: dict[str, Any] | None
    mask: list[bool] | None  # slots reset (None: all)


@dataclass
class Steps:
    count: int
    action_seed: int  # actions are drawn from a generator with this seed (a script stays a few numbers)
    noop_bias: float  # share of no-op actions (long survival in Mortar Mayhem, lingering in the clue phase)


SEEDS = st.one_of(st.integers(0, 2**32 - 1), st.integers(0, 2**70), st.sampled_from([0, 1, 2**32 - 1, 2**32, 2**63]))


@st.composite
def scripts(draw: st.DrawFn, env_id: str, num_envs: int, max_steps: int | None = None) -> list[Reset | Steps]:
    """A seeded reset, then steps and resets (with options, masks and seeds or none) in any order."""
    specs = envs.make_core(env_id).option_specs
    events: list[Reset | Steps] = [Reset(draw(SEEDS), draw(options(specs, env_id)), None)]
    budget = max_steps or SCALE.max_steps
    for _ in range(draw(st.integers(1, SCALE.max_events))):
        if draw(st.integers(0, 3)) == 0:
            seed = draw(
                st.one_of(st.none(), SEEDS, st.lists(st.one_of(st.none(), SEEDS), min_size=num_envs, max_size=num_envs))
            )
            mask = draw(st.one_of(st.none(), st.lists(st.booleans(), min_size=num_envs, max_size=num_envs)))
            events.append(Reset(seed, draw(options(specs, env_id)), mask))
        else:
            count = draw(st.integers(1, max(1, budget)))
            budget -= count
            events.append(Steps(count, draw(st.integers(0, 2**32 - 1)), draw(st.sampled_from([0.0, 0.5, 0.9]))))
        if budget <= 0:
            break
    return events


def random_actions(space: gym.Space, rng: np.random.Generator, n: int, noop_bias: float) -> np.ndarray:
    """n valid actions (int64): uniform, or the no-op (0) with probability ``noop_bias``."""
    if isinstance(space, gym.spaces.Discrete):
        actions = rng.integers(0, space.n, size=n)
    else:
        actions = rng.integers(0, np.asarray(space.nvec), size=(n, *space.shape))
    noop = rng.random(n) < noop_bias
    actions[noop] = 0
    return actions.astype(np.int64)


# ----------------------------------------------------------------------------------------------------- checks
def image(obs: Any) -> np.ndarray:
    return obs["visual_observation"] if isinstance(obs, dict) else obs


def same_obs(a: Any, b: Any) -> bool:
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(np.array_equal(a[key], b[key]) for key in a)
    return np.array_equal(a, b)


def slot_obs(obs: Any, k: int) -> Any:
    return {key: v[k] for key, v in obs.items()} if isinstance(obs, dict) else obs[k]


def slot_info(infos: dict[str, Any], k: int) -> dict[str, Any]:
    """Slot k's info from a vector info dict (gymnasium's format: ``info[key]`` with the mask ``info["_key"]``)."""
    return {key: v[k] for key, v in infos.items() if not key.startswith("_") and infos[f"_{key}"][k]}


def same_info(a: dict[str, Any], b: dict[str, Any]) -> bool:
    return values_equal(jsonable(a), jsonable(b))


def check_info_keys(env_id: str, info: dict[str, Any], final: bool, where: str) -> None:
    expected = step_info_keys(env_id) | (FINAL_INFO_KEYS[env_id] if final else set())
    assert set(info) == expected, f"{where}: info keys {sorted(info)}, documented {sorted(expected)}"


def _vector_seeds(seed: int | list[int | None] | None, n: int) -> list[int | None]:
    if isinstance(seed, list):
        return seed
    return [None if seed is None else seed + k for k in range(n)]


# -------------------------------------------------------------------------------------------- property: faces
def check_faces_agree(env_id: str, num_envs: int, base: dict[str, Any] | None, script: list, split_seed: int) -> None:
    """One script on n single envs, the vector face (next-step autoreset) and a core: identical slot for slot."""
    CASES[("faces_agree", env_id)] += 1
    n = num_envs
    singles = [gym.make(env_id, disable_env_checker=True, options=base) for _ in range(n)]
    vec = gym.make_vec(env_id, num_envs=n, options=base)
    core = envs.make_core(env_id, num_envs=n, options=base)
    space, single_space = vec.observation_space, singles[0].observation_space
    split = np.random.default_rng(split_seed)
    needs_reset = np.zeros(n, dtype=bool)
    reset_options: list[dict[str, Any] | None] = [None] * n  # options of each slot's last reset call
    started = np.zeros(n, dtype=bool)
    for e, event in enumerate(script):
        if isinstance(event, Reset):
            mask = np.ones(n, bool) if event.mask is None else np.array(event.mask, bool)
            seeds = _vector_seeds(event.seed, n)
            opts = None if event.options is None else dict(event.options)
            vec_options = None if event.mask is None and opts is None else {**(opts or {}), "reset_mask": mask}
            obs, infos = vec.reset(seed=event.seed, options=vec_options)
            slots = np.flatnonzero(mask)
            core.reset_slots(slots, [seeds[k] for k in slots], opts)
            core_obs = core.observations()
            for k in slots.tolist():
                s_obs, s_info = singles[k].reset(seed=seeds[k], options=opts)
                where = f"{env_id} event {e} reset slot {k}"
                assert single_space.contains(s_obs), f"{where}: observation outside {single_space}"
                assert same_obs(slot_obs(obs, k), s_obs), f"{where}: vector frame differs from single"
                assert same_obs(slot_obs(core_obs, k), s_obs), f"{where}: core frame differs from single"
                assert same_info(slot_info(infos, k), s_info), f"{where}: info {slot_info(infos, k)} vs {s_info}"
                check_info_keys(env_id, s_info, False, where)
                reset_options[k] = opts
            needs_reset[mask] = False
            started |= mask
            assert space.contains(obs), f"{env_id} event {e}: vector observation outside {space}"
            continue
        rng = np.random.default_rng(event.action_seed)
        for t in range(event.count):
            actions = random_actions(vec.single_action_space, rng, n, event.noop_bias)
            if not started.all():  # a slot that no reset reached yet: the vector face must refuse the step
                try:
                    vec.step(actions)
                except ResetNeeded:
                    return
                raise AssertionError(f"{env_id}: the vector face stepped a slot that was never reset")
            obs, rewards, terminated, truncated, infos = vec.step(actions)
            assert space.contains(obs), f"{env_id} event {e} step {t}: vector observation outside {space}"
            assert not truncated.any()
            # the core: restart the finished slots (options of their last reset), then the others in two groups
            restart = np.flatnonzero(needs_reset)
            if restart.size:
                core.restart_slots(restart)
            live = np.flatnonzero(~needs_reset)
            order = split.permutation(live)
            cut = int(split.integers(0, live.size + 1))
            core_r, core_t, core_finals = np.zeros(n), np.zeros(n, bool), {}
            for group in (np.sort(order[:cut]), np.sort(order[cut:])):
                if group.size:
                    r, term, finals = core.step(actions[group], idx=group)
                    core_r[group], core_t[group] = r, term
                    core_finals.update(finals)
            core_obs = core.observations()
            for k in range(n):
                where = f"{env_id} event {e} step {t} slot {k}"
                if needs_reset[k]:  # next-step autoreset: this step starts the slot's next episode
                    s_obs, s_info = singles[k].reset(options=reset_options[k])
                    s_reward, s_term = 0.0, False
                else:
                    s_obs, s_reward, s_term, s_trunc, s_info = singles[k].step(actions[k])
                    assert not s_trunc
                    check_info_keys(env_id, s_info, s_term, where)
                    final = {**core.step_info(k), **core_finals.get(k, {})}
                    assert same_info(final, s_info), f"{where}: core info {final} vs single {s_info}"
                assert single_space.contains(s_obs), f"{where}: observation outside {single_space}"
                assert same_obs(slot_obs(obs, k), s_obs), f"{where}: vector frame differs from single"
                assert same_obs(slot_obs(core_obs, k), s_obs), f"{where}: core frame differs from single"
                assert values_equal(float(rewards[k]), s_reward), f"{where}: reward {rewards[k]} vs {s_reward}"
                assert values_equal(float(core_r[k]), s_reward), f"{where}: core reward {core_r[k]} vs {s_reward}"
                assert bool(terminated[k]) == s_term == bool(core_t[k]), f"{where}: terminated differs"
                assert same_info(slot_info(infos, k), s_info), f"{where}: info {slot_info(infos, k)} vs {s_info}"
            needs_reset = terminated.copy()
    for env in singles:
        env.close()
    vec.close()


# ------------------------------------------------------------------------------------ property: fresh after reset
def play_history(env: gym.Env, script: list) -> None:
    """Play a script on a single env (vector-face resets become single resets; masks are ignored)."""
    for event in script:
        if isinstance(event, Reset):
            seed = event.seed[0] if isinstance(event.seed, list) else event.seed
            env.reset(seed=seed, options=event.options)
            continue
        rng = np.random.default_rng(event.action_seed)
        for _ in range(event.count):
            _, _, terminated, _, _ = env.step(random_actions(env.action_space, rng, 1, event.noop_bias)[0])
            if terminated:
                env.reset()


def check_reset_is_fresh(
    env_id: str, history: list, seed: int, opts: dict[str, Any] | None, action_seed: int, noop_bias: float
) -> None:
    """After ``history``, reset(seed, opts) plays what a fresh instance plays (frames, debug pictures, infos)."""
    CASES[("reset_is_fresh", env_id)] += 1
    used = gym.make(env_id, render_mode="debug_rgb_array", disable_env_checker=True)
    fresh = gym.make(env_id, render_mode="debug_rgb_array", disable_env_checker=True)
    play_history(used, history)
    got, want = used.reset(seed=seed, options=opts), fresh.reset(seed=seed, options=opts)
    assert same_obs(got[0], want[0]) and same_info(got[1], want[1]), f"{env_id}: reset frame depends on the history"
    assert used.unwrapped.max_episode_steps == fresh.unwrapped.max_episode_steps
    rng = np.random.default_rng(action_seed)
    for t in range(SCALE.episode_steps):
        if t < 6 or t % 50 == 0:
            assert np.array_equal(used.render(), fresh.render()), f"{env_id} step {t}: debug view depends on history"
        action = random_actions(used.action_space, rng, 1, noop_bias)[0]
        a, b = used.step(action), fresh.step(action)
        assert same_obs(a[0], b[0]), f"{env_id} step {t + 1}: frame depends on the history"
        assert values_equal(a[1], b[1]) and a[2] == b[2], f"{env_id} step {t + 1}: reward/flag depends on the history"
        assert same_info(a[4], b[4]), f"{env_id} step {t + 1}: info {a[4]} vs fresh {b[4]}"
        if a[2]:
            break
    used.close()
    fresh.close()


def check_core_reset_is_fresh(env_id: str, num_envs: int, history: list, seed: int, opts: dict | None) -> None:
    """A batched core reset after its own history (random slot subsets stepped) equals a fresh core."""
    CASES[("core_reset_is_fresh", env_id)] += 1
    used, fresh = envs.make_core(env_id, num_envs=num_envs), envs.make_core(env_id, num_envs=num_envs)
    for event in history:
        if isinstance(event, Reset):
            seeds = _vector_seeds(event.seed, num_envs)
            mask = np.ones(num_envs, bool) if event.mask is None else np.array(event.mask, bool)
            slots = [k for k in range(num_envs) if mask[k] or k in used.unready]
            used.reset_slots(slots, [seeds[k] for k in slots], event.options)
            continue
        rng = np.random.default_rng(event.action_seed)
        for _ in range(event.count):
            live = np.flatnonzero(rng.random(num_envs) < 0.7)
            if live.size:
                _, terminated, _ = used.step(random_actions(used.single_action_space, rng, live.size, 0.3), idx=live)
                if terminated.any():
                    used.restart_slots(live[terminated])
    seeds = [seed + k for k in range(num_envs)]
    for core in (used, fresh):
        core.reset_slots(range(num_envs), seeds, opts)
    _assert_cores_equal(env_id, used, fresh, "reset")
    rng = np.random.default_rng(seed % 2**32)
    for t in range(SCALE.episode_steps // 2):
        actions = random_actions(used.single_action_space, rng, num_envs, 0.3)
        a, b = used.step(actions), fresh.step(actions)
        assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1]), f"{env_id} step {t + 1}: rewards differ"
        assert same_info(a[2], b[2]), f"{env_id} step {t + 1}: final infos differ"
        for core in (used, fresh):
            if a[1].any():
                core.restart_slots(np.flatnonzero(a[1]))
        _assert_cores_equal(env_id, used, fresh, f"step {t + 1}")


def _assert_cores_equal(env_id: str, a: BatchedCore, b: BatchedCore, where: str) -> None:
    assert same_obs(a.observations(), b.observations()), f"{env_id} {where}: core frames depend on the history"
    for k in range(a.num_envs):
        assert same_info(a.step_info(k), b.step_info(k)), f"{env_id} {where} slot {k}: step info differs"


# ------------------------------------------------------------------------------------------ property: invalid
def invalid_actions(space: gym.Space) -> st.SearchStrategy[Any]:
    """Single-face actions outside ``space``: out of range, negative, floats, bools, wrong shapes, None, text."""
    if isinstance(space, gym.spaces.Discrete):
        out = st.one_of(st.integers(space.n, 2**40), st.integers(-(2**40), -1))
        return st.one_of(
            out,
            out.map(lambda a: np.array([a])),
            st.sampled_from([0.0, 1.0, 1.5, None, "1", True, [0, 1], [[1]], np.array([1, 0])]),
            st.sampled_from([np.float32(1), np.array(1.0)]),
        )
    nvec = np.asarray(space.nvec)
    good = [int(v) - 1 for v in nvec]
    out_entries = st.lists(st.integers(-(2**40), 2**40), min_size=len(good), max_size=len(good)).filter(
        lambda a: any(x < 0 or x >= n for x, n in zip(a, nvec.tolist(), strict=True))
    )
    return st.one_of(
        out_entries,
        out_entries.map(np.array),
        st.sampled_from([[0.0, 1.0], [1], [1, 1, 1], 1, None, "ab", [True, False], [[1, 1]], [None, 1]]),
        st.just(np.array(good, dtype=np.float64)),
    )


def check_invalid_input_refused(
    env_id: str, seed: int, before: int, bad: tuple[str, Any, str], action_seed: int, num_envs: int, bad_slot: int
) -> None:
    """A refused call names what is wrong and leaves the env as it was (actions) or ready for a reset (options)."""
    CASES[("invalid_refused", env_id)] += 1
    kind, value, named = bad
    env, twin = gym.make(env_id, disable_env_checker=True), gym.make(env_id, disable_env_checker=True)
    for e in (env, twin):
        e.reset(seed=seed)
    rng = np.random.default_rng(action_seed)
    actions = [random_actions(env.action_space, rng, 1, 0.5)[0] for _ in range(before + 30)]

    def advance(e: gym.Env, steps: list) -> list:
        out = []
        for action in steps:
            obs, reward, terminated, _, info = e.step(action)
            out.append((image(obs).tobytes(), reward, terminated, jsonable(info)))
            if terminated:
                e.reset()
        return out

    assert advance(env, actions[:before]) == advance(twin, actions[:before])
    if kind == "action":
        try:
            env.step(value)
        except ValueError as err:
            assert "action" in str(err), f"{env_id}: the message does not say what is wrong: {err}"
        else:
            raise AssertionError(f"{env_id}: action {value!r} was not refused")
        assert advance(env, actions[before:]) == advance(twin, actions[before:]), f"{env_id}: a refused action acted"
    elif kind in ("options", "make_options", "seed"):
        try:
            if kind == "options":
                env.reset(seed=seed, options=value)
            elif kind == "seed":
                env.reset(seed=value)
            else:
                gym.make(env_id, disable_env_checker=True, options=value)
        except ValueError as err:
            assert named in str(err), f"{env_id}: {named} not named in {err}"
        else:
            raise AssertionError(f"{env_id}: {kind} {value!r} was not refused")
        if kind == "make_options":
            assert advance(env, actions[before:]) == advance(twin, actions[before:])
        else:
            try:
                env.step(actions[before])
            except ResetNeeded:
                pass
            else:
                raise AssertionError(f"{env_id}: a step after a refused reset went on")
            env.reset(seed=seed + 1)
            twin = gym.make(env_id, disable_env_checker=True)
            twin.reset(seed=seed + 1)
            assert advance(env, actions[before:]) == advance(twin, actions[before:]), f"{env_id}: refused reset leaked"
    # the vector face names the slot of a bad action, and steps on afterwards
    vec = gym.make_vec(env_id, num_envs=num_envs)
    vec.reset(seed=seed)
    good = random_actions(vec.single_action_space, rng, num_envs, 0.0)
    if kind == "action":
        rows = [value if k == bad_slot else good[k].tolist() for k in range(num_envs)]
        try:
            batch = np.array(rows)
        except ValueError:
            batch = np.array(rows, dtype=object)
        clean = batch.dtype.kind in "iu" and batch.shape == good.shape
        # numpy may turn the bad row into a valid one (True among ints becomes 1): then nothing is to be refused
        if not (clean and vec.action_space.contains(batch.astype(np.int64))):
            try:
                vec.step(batch)
            except ValueError as err:
                if clean:  # an int batch with one bad row: the message names that slot
                    assert f"slot {bad_slot}" in str(err), f"{env_id}: slot {bad_slot} not named in {err}"
            else:
                raise AssertionError(f"{env_id}: vector actions {rows!r} were not refused")
    vec.step(good)
    vec.close()
    env.close()
    twin.close()


@st.composite
def bad_inputs(draw: st.DrawFn, env_id: str) -> tuple[str, Any, str]:
    core = envs.make_core(env_id)
    kind = draw(st.sampled_from(["action", "options", "make_options", "seed"]))
    if kind == "action":
        return kind, draw(invalid_actions(core.single_action_space)), "slot"
    if kind == "seed":
        return kind, draw(st.sampled_from([-1, -(2**40), 1.5, "0", [1, 2]])), "seed"
    value, named = draw(invalid_option(core.option_specs))
    return kind, value, named


# ------------------------------------------------------------------------------------------------------- runners
# One Hypothesis search per (property, id), under the loaded profile; tests/envs/test_fuzz.py and scripts/fuzz_envs.py
# call these.
def run_faces_agree(env_id: str) -> None:
    specs = envs.make_core(env_id).option_specs

    @given(data=st.data())
    def faces_agree(data: st.DataObject) -> None:
        n = data.draw(st.integers(1, SCALE.max_slots), label="num_envs")
        base = data.draw(options(specs, env_id), label="make options")
        script = data.draw(scripts(env_id, n), label="script")
        check_faces_agree(env_id, n, base, script, data.draw(st.integers(0, 2**32 - 1), label="split seed"))

    faces_agree()


def run_reset_is_fresh(env_id: str) -> None:
    specs = envs.make_core(env_id).option_specs

    @given(data=st.data())
    def reset_is_fresh(data: st.DataObject) -> None:
        history = data.draw(scripts(env_id, 1), label="history")
        seed = data.draw(SEEDS, label="seed")
        opts = data.draw(options(specs, env_id), label="options")
        action_seed = data.draw(st.integers(0, 2**32 - 1), label="action seed")
        check_reset_is_fresh(env_id, history, seed, opts, action_seed, data.draw(st.sampled_from([0.0, 0.5, 0.9])))
        n = data.draw(st.integers(1, SCALE.max_slots), label="core slots")
        core_history = data.draw(scripts(env_id, n), label="core history")
        check_core_reset_is_fresh(env_id, n, core_history, seed, opts)

    reset_is_fresh()


def run_invalid_input_refused(env_id: str) -> None:
    @given(data=st.data())
    def invalid_input_refused(data: st.DataObject) -> None:
        seed = data.draw(st.integers(0, 2**32 - 1), label="seed")
        before = data.draw(st.integers(0, 30), label="steps before")
        bad = data.draw(bad_inputs(env_id), label="bad input")
        n = data.draw(st.integers(1, SCALE.max_slots), label="num_envs")
        slot = data.draw(st.integers(0, n - 1), label="bad slot")
        check_invalid_input_refused(env_id, seed, before, bad, data.draw(st.integers(0, 2**32 - 1)), n, slot)

    invalid_input_refused()


PROPERTIES = {
    "faces_agree": run_faces_agree,
    "reset_is_fresh": run_reset_is_fresh,
    "invalid_refused": run_invalid_input_refused,
}


# What the fuzzing found in envs/ (each fixed, with a regression test in tests/envs/test_fuzz_regressions.py);
# scripts/fuzz_envs.py writes it into results/reliability.json beside the figures of its run.
FOUND_AND_FIXED: list[dict[str, str]] = [
    {
        "ids": "every Mortar Mayhem id (observations: Endless-MortarMayhem-v0; debug view: all five)",
        "property": "reset_is_fresh",
        "symptom": "the debug view of a reset showed the previous episode's last agent sprite, and Endless Mortar "
        "Mayhem's first clue frames (observations) showed it too: an episode depended on what the slot played before",
        "fix": "removed by default (documented deviation); BatchedCore.reference_carryover brings memory-gym's "
        "leftover back for the parity replays of traces recorded on reused instances",
        "regression_tests": "test_endless_mortar_mayhem_clue_frames_do_not_show_the_previous_episode, "
        "test_mortar_mayhem_debug_view_of_a_reset_shows_the_new_agent",
    },
    {
        "ids": "SearingSpotlights-v0, Endless-SearingSpotlights-v0",
        "property": "reset_is_fresh",
        "symptom": "render() in debug_rgb_array raised ValueError (broadcast) once a spotlight of radius above ~22 "
        "(valid: up to 42) was far off-screen",
        "fix": "spotlight discs are clipped to the screen in the debug view",
        "regression_tests": "test_searing_spotlights_debug_view_with_large_spotlights",
    },
    {
        "ids": "every id",
        "property": "invalid_refused",
        "symptom": "NaN (and infinite) values of float options without bounds (rewards) were accepted; infinite or "
        "huge values of open-ended options crashed later with OverflowError/IndexError/MemoryError (e.g. "
        "spawn_interval_threshold=inf, explosion_delay=[2**62], Endless MP agent_speed=1e300)",
        "fix": "float options must be finite, int options must fit int64; upper bounds where memory-gym has none "
        "(Mortar Mayhem command counts <= 100, clue frames <= 100, explosion steps <= 10000; spot_damage <= 1e9, "
        "spawn intervals <= 1e6; Mystery Path agent_speed <= 1000: at 1e6 px per step, valid before, an Endless "
        "Mystery Path step generated ~10^4 levels and one case ran for minutes)",
        "regression_tests": "test_non_finite_and_huge_option_values_are_refused_by_name, "
        "test_extreme_valid_option_values_play",
    },
]


# What the long profile found in the harness itself (fixed there; the environments were right).
HARNESS_FIXES: list[dict[str, str]] = [
    {
        "ids": "MysteryPath-Grid-v0, Endless-MysteryPath-v0 (Discrete action spaces)",
        "property": "invalid_refused",
        "symptom": "the vector face 'accepted' the bad action True in slot 0 of [True, 3]: numpy builds the int batch "
        "[1, 3] from that list, a valid batch (the single face refuses True itself)",
        "fix": "the property expects a refusal only when the batch it builds is invalid",
    },
]


def fuzz(ids: list[str], properties: list[str], log: Any = print) -> dict[str, Any]:
    """Run the properties on the ids under the loaded profile; per id: cases tried per property, failures
    (the falsifying example and the error, as Hypothesis reports them), seconds."""
    per_id: dict[str, Any] = {}
    for env_id in ids:
        entry: dict[str, Any] = {"cases": {}, "failures": [], "seconds": 0.0}
        for prop in properties:
            before = dict(CASES)
            start = time.perf_counter()
            try:
                PROPERTIES[prop](env_id)
            except Exception as err:  # a falsified property: recorded, and the other properties still run
                text = "".join(traceback.format_exception_only(type(err), err)).strip()
                entry["failures"].append({"property": prop, "error": text[-4000:]})
            seconds = time.perf_counter() - start
            for key, count in CASES.items():
                if key[1] == env_id and count != before.get(key, 0):
                    entry["cases"][key[0]] = count - before.get(key, 0)
            entry["seconds"] = round(entry["seconds"] + seconds, 1)
            log(f"{env_id:30s} {prop:16s} {seconds:7.1f}s {entry['cases']} failures: {len(entry['failures'])}")
        per_id[env_id] = entry
    return per_id
