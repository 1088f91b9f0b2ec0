"""Generic checks that every registered id must pass (parametrized over ``envs.ENV_IDS``).

* the single face passes gymnasium's ``check_env``;
* slot k of ``make_vec(id, num_envs=N)`` reset with seed s + k plays exactly the episodes of a single env reset with
  seed s + k (observations, rewards, flags, infos, final infos), through the NEXT_STEP autoreset continuation and in
  SAME_STEP mode, over whole episodes with random actions;
* reset options apply to one episode only, on both faces;
* ``rgb_array`` renders the observation image, ``debug_rgb_array`` a uint8 picture 4x its size (336x336x3 for the
  84x84 Memory Gym views), ``human`` opens a window (dummy video driver);
* unknown option keys raise ``ValueError`` naming the key and the valid keys.
"""

from __future__ import annotations

import math
import re
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.vector import AutoresetMode

import envs
from envs import ENV_IDS, make_core
from envs.options import Option

ALL_IDS = list(ENV_IDS)
NUM_ENVS = 3
MAX_VECTOR_STEPS = 1500  # enough for two random episodes of every id (the longest, MysteryPath, stops at 512 steps)


# ----------------------------------------------------------------------------------------------------- helpers
def random_action(space: gym.Space, rng: np.random.Generator) -> Any:
    if isinstance(space, gym.spaces.Discrete):
        return int(space.start + rng.integers(space.n))
    if isinstance(space, gym.spaces.MultiDiscrete):
        return (space.start + rng.integers(space.nvec)).astype(space.dtype)
    raise TypeError(f"no random action for {space}")


def plain(value: Any) -> Any:
    """Arrays and numpy scalars as python lists/numbers, recursively, so values compare by content."""
    if isinstance(value, dict):
        return {k: plain(v) for k, v in value.items()}
    if hasattr(value, "tolist"):
        return value.tolist()
    return value


def same(a: Any, b: Any) -> bool:
    a, b = plain(a), plain(b)
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, int | float) and isinstance(b, int | float):
        return (math.isnan(a) and math.isnan(b)) or math.isclose(a, b, rel_tol=1e-12, abs_tol=1e-12)
    return a == b


def slot_info(infos: dict[str, Any], k: int) -> dict[str, Any]:
    """Slot k's info out of a vector info dict (keys with their ``_key`` masks, nested dicts recursively)."""
    out = {}
    for key, value in infos.items():
        if key.startswith("_") or not infos[f"_{key}"][k]:
            continue
        out[key] = slot_info(value, k) if isinstance(value, dict) else value[k]
    return out


def slot_obs(obs: Any, k: int) -> Any:
    return {key: v[k] for key, v in obs.items()} if isinstance(obs, dict) else obs[k]


def image_of(obs: Any) -> np.ndarray:
    return obs["visual_observation"] if isinstance(obs, dict) else obs


def changed_value(spec: Option) -> Any:
    """A valid value that differs from the option's default."""

    def shift(v: float, kind: str) -> float:
        step = 1 if kind == "int" else 0.5 * (abs(v) or 1.0)
        up = v + step
        if kind == "float" and spec.high is not None and up > spec.high:
            up = (v + spec.high) / 2 if v < spec.high else v - step
        if spec.high is not None and up > spec.high or up == v:
            up = v - step
        if spec.low is not None and up < spec.low:
            up = (v + spec.low) / 2 if kind == "float" else v
        return up

    if spec.kind == "bool":
        return not spec.default
    if spec.kind in ("int", "float"):
        return shift(spec.default, spec.kind)
    kind = "int" if spec.kind == "int_list" else "float"
    return [shift(v, kind) for v in spec.default]


def first_steps(env: gym.Env, seed: int, options: dict | None, steps: int = 60) -> list[Any]:
    """Reset observation and the first steps under a fixed action stream, as comparable plain values."""
    rng = np.random.default_rng(0)
    obs, info = env.reset(seed=seed, options=options)
    out = [(image_of(obs).tobytes(), plain(info))]
    for _ in range(steps):
        obs, reward, terminated, truncated, info = env.step(random_action(env.action_space, rng))
        out.append((image_of(obs).tobytes(), reward, terminated, truncated, plain(info)))
        if terminated or truncated:
            break
    return out


# ------------------------------------------------------------------------------------------------------ tests
@pytest.mark.parametrize("env_id", ALL_IDS)
@pytest.mark.parametrize("render_mode", [None, "rgb_array"])
def test_check_env(env_id: str, render_mode: str | None) -> None:
    env = gym.make(env_id, render_mode=render_mode, disable_env_checker=True)
    check_env(env.unwrapped, skip_render_check=render_mode is None)
    env.close()


def play_vector(env_id: str, mode: AutoresetMode, seed: int) -> list[dict[str, Any]]:
    """Run the vector face with per-slot random actions; return everything each step returned."""
    venv = gym.make_vec(env_id, num_envs=NUM_ENVS, autoreset_mode=mode)
    assert venv.metadata["autoreset_mode"] == mode
    rngs = [np.random.default_rng(1000 + k) for k in range(NUM_ENVS)]
    obs, infos = venv.reset(seed=seed)
    record = [{"obs": obs, "infos": infos}]
    episodes = np.zeros(NUM_ENVS, dtype=int)
    for _ in range(MAX_VECTOR_STEPS):
        actions = np.stack([np.asarray(random_action(venv.single_action_space, r)) for r in rngs])
        obs, rewards, terminated, truncated, infos = venv.step(actions)
        record.append(dict(actions=actions, obs=obs, rewards=rewards, terminated=terminated, infos=infos))
        episodes += terminated | truncated
        if (episodes >= 2).all():
            break
    venv.close()
    assert (episodes >= 1).all(), f"some slot never finished an episode in {MAX_VECTOR_STEPS} steps: {episodes}"
    return record


def assert_step(got: tuple, want: tuple, where: str) -> None:
    names = ("obs", "reward", "terminated", "info")
    for name, g, w in zip(names, got, want, strict=True):
        if name == "obs":
            ok = all(np.array_equal(g[key], w[key]) for key in w) if isinstance(w, dict) else np.array_equal(g, w)
        else:
            ok = same(g, w)
        assert ok, (
            f"{where}: {name} differs (vector {g if name != 'obs' else '...'}, single {w if name != 'obs' else '...'})"
        )


@pytest.mark.parametrize("env_id", ALL_IDS)
@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
def test_vector_slots_replay_single_envs(env_id: str, mode: AutoresetMode) -> None:
    seed = 11
    record = play_vector(env_id, mode, seed)
    for k in range(NUM_ENVS):
        env = gym.make(env_id, disable_env_checker=True)
        obs, info = env.reset(seed=seed + k)
        first = record[0]
        assert_step((slot_obs(first["obs"], k), 0, False, slot_info(first["infos"], k)), (obs, 0, False, info), "reset")
        needs_reset = False
        for t, rec in enumerate(record[1:], start=1):
            got_info = slot_info(rec["infos"], k)
            got = (slot_obs(rec["obs"], k), rec["rewards"][k], bool(rec["terminated"][k]), None)
            where = f"{env_id} slot {k} step {t} ({mode.value})"
            if needs_reset:  # NEXT_STEP: this step restarts the slot (action ignored, reward 0)
                obs, info = env.reset()
                assert_step(got[:3] + (got_info,), (obs, 0.0, False, info), where + " autoreset")
                needs_reset = False
                continue
            obs, reward, terminated, truncated, info = env.step(rec["actions"][k])
            assert not truncated
            if terminated and mode == AutoresetMode.SAME_STEP:
                final = (got_info["final_obs"], rec["rewards"][k], bool(rec["terminated"][k]), got_info["final_info"])
                assert_step(final, (obs, reward, terminated, info), where + " final")
                obs, info = env.reset()
                rest = {key: v for key, v in got_info.items() if key not in ("final_obs", "final_info")}
                assert_step((got[0], 0.0, False, rest), (obs, 0.0, False, info), where + " same-step reset")
                continue
            assert_step(got[:3] + (got_info,), (obs, reward, terminated, info), where)
            needs_reset = terminated and mode == AutoresetMode.NEXT_STEP
        env.close()


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_options_apply_to_one_episode(env_id: str) -> None:
    # Between the episode with the option and the checked one runs a default "flush" episode: some reference quirks
    # carry drawing state over a reset (Endless Mortar Mayhem's clue stream shows the sprite drawn last), so the
    # checked episode must follow the same previous episode in both runs.
    specs = make_core(env_id).option_specs
    baseline_env = gym.make(env_id, disable_env_checker=True)
    first_steps(baseline_env, 7, None)
    baseline = first_steps(baseline_env, 5, None)
    effective = []
    for key, spec in specs.items():
        options = {key: changed_value(spec)}
        env = gym.make(env_id, disable_env_checker=True)
        with_option = first_steps(env, 5, options)
        first_steps(env, 7, None)
        after = first_steps(env, 5, None)  # back to the defaults
        assert after == baseline, f"{env_id}: option {options} leaked into a later episode"
        if with_option != first_steps(gym.make(env_id, disable_env_checker=True), 5, None):
            effective.append(key)
        env.close()
    assert effective, f"{env_id}: no option changed the first steps, so this test could not fail"
    # the vector face: options of a reset apply to that reset only
    key = effective[0]
    venv = gym.make_vec(env_id, num_envs=2)
    venv.reset(seed=[5, 6], options={key: changed_value(specs[key])})
    obs, _ = venv.reset(seed=[5, 6])
    single_obs, _ = gym.make(env_id, disable_env_checker=True).reset(seed=5)
    assert np.array_equal(image_of(obs)[0], image_of(single_obs))
    venv.close()
    baseline_env.close()


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_render_modes(env_id: str, monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(0)
    env = gym.make(env_id, render_mode="rgb_array", disable_env_checker=True)
    debug = gym.make(env_id, render_mode="debug_rgb_array", disable_env_checker=True)
    obs, _ = env.reset(seed=3)
    debug.reset(seed=3)
    for _ in range(30):
        frame = env.render()
        assert frame.dtype == np.uint8 and frame.shape == image_of(obs).shape
        assert np.array_equal(frame, image_of(obs))
        picture = debug.render()
        height, width = image_of(obs).shape[:2]  # 84x84 Memory Gym views give 336x336 pictures
        assert picture.dtype == np.uint8 and picture.shape == (4 * height, 4 * width, 3)
        action = random_action(env.action_space, rng)
        obs, _, terminated, _, _ = env.step(action)
        debug.step(action)
        if terminated:
            obs, _ = env.reset()
            debug.reset()
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    human = gym.make(env_id, render_mode="human", disable_env_checker=True)
    human.reset(seed=3)  # shows the first picture (the window's clock holds the env's frame rate from the next one)
    assert human.render() is None
    human.close()
    env.close()
    debug.close()


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_unknown_option_raises(env_id: str) -> None:
    env = gym.make(env_id, disable_env_checker=True)
    with pytest.raises(ValueError, match="no_such_option") as err:
        env.reset(seed=0, options={"no_such_option": 1})
    for key in make_core(env_id).option_specs:
        assert key in str(err.value), "the message lists the valid keys"
    venv = gym.make_vec(env_id, num_envs=2)
    with pytest.raises(ValueError, match="no_such_option"):
        venv.reset(seed=0, options={"no_such_option": 1})
    with pytest.raises(ValueError, match="no_such_option"):
        gym.make(env_id, options={"no_such_option": 1})


def test_registry_lists_every_id() -> None:
    for env_id in ALL_IDS:
        assert env_id in gym.registry
    assert envs.make_core(ALL_IDS[0], num_envs=2).num_envs == 2


def bad_actions(space: gym.Space) -> list[tuple[Any, str]]:
    """Single actions outside ``space``, each with a pattern of what the refusal names."""
    if isinstance(space, gym.spaces.Discrete):
        return [
            (space.n, rf"action {space.n} is outside the action space Discrete\({space.n}\)"),
            (-1, r"action -1 is outside"),
            (1.0, r"action 1.0 has dtype float64; actions are integers \(integer-valued floats too"),
            ([1.0], r"action 1.0 has dtype float64; actions are integers"),
            (np.array([space.n]), rf"action {space.n} is outside the action space Discrete\({space.n}\)"),
            ([1, 2], r"action \[1, 2\] has shape \(2,\), expected \(\) or \(1,\)"),
            ([[1]], r"action \[\[1\]\] has shape \(1, 1\), expected \(\) or \(1,\)"),
            (True, r"action True has dtype bool"),
            (None, rf"action None is not an action: expected an action in Discrete\({space.n}\)"),
        ]
    high = int(space.nvec[0])
    return [
        (5, r"action 5 has shape \(\), expected \(2,\): an action in MultiDiscrete\(\[3, 3\]\)"),
        ([high, 0], rf"action \[{high}, 0\] is outside the action space MultiDiscrete\(\[3, 3\]\)"),
        ([0, -1], r"action \[0, -1\] is outside"),
        ([1, 1, 1], r"action \[1, 1, 1\] has shape \(3,\), expected \(2,\)"),
        (np.array([0.0, 1.0]), r"action \[0.0, 1.0\] has dtype float64"),
        ([[0, 1]], r"action \[\[0, 1\]\] has shape \(1, 2\), expected \(2,\)"),
        (None, r"action None is not an action: expected an action in MultiDiscrete\(\[3, 3\]\)"),
    ]


def replay_after(env: gym.Env, twin: gym.Env, steps: int, rng: np.random.Generator) -> None:
    """``env`` (which refused actions) and ``twin`` (which never saw them) play on identically."""
    for t in range(steps):
        action = random_action(env.action_space, rng)
        got, want = env.step(action), twin.step(action)
        assert_step((got[0], *got[1:3], got[4]), (want[0], *want[1:3], want[4]), f"step {t} after the refusals")
        if got[2]:
            break


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_actions_outside_the_space_are_refused_without_changing_any_state(env_id: str) -> None:
    env, twin = gym.make(env_id), gym.make(env_id)
    env.reset(seed=3)
    twin.reset(seed=3)
    for t, (action, message) in enumerate(bad_actions(env.action_space)):
        with pytest.raises(ValueError, match=rf"slot 0: {message}"):
            env.step(action)
        if t == 1:  # a valid step between refusals
            action = random_action(env.action_space, np.random.default_rng(t))
            assert_step(env.step(action)[:3] + (None,), twin.step(action)[:3] + (None,), "valid step")
    replay_after(env, twin, 30, np.random.default_rng(1))

    # the native vector face: the slot is named; the count and the shape of the batch are checked
    venv, vtwin = gym.make_vec(env_id, num_envs=4), gym.make_vec(env_id, num_envs=4)
    venv.reset(seed=5)
    vtwin.reset(seed=5)
    valid = np.stack([np.asarray(random_action(venv.single_action_space, np.random.default_rng(k))) for k in range(4)])
    with pytest.raises(ValueError, match=r"got actions of shape \(3,.*for 4 slots"):
        venv.step(valid[:3])
    discrete = isinstance(venv.single_action_space, gym.spaces.Discrete)
    for k, action in ((1, 9), (2, -3)) if discrete else ((1, [3, 0]), (2, [0, -3])):
        batch = valid.copy()
        batch[k] = action
        with pytest.raises(ValueError, match=rf"slot {k}: action {re.escape(str(action))} is outside the action space"):
            venv.step(batch)
    with pytest.raises(ValueError, match=r"slot 0: .* has dtype float64"):
        venv.step(valid.astype(np.float64))
    rng = np.random.default_rng(2)
    restarted = False
    for _ in range(600):  # also while slots wait for their NEXT_STEP autoreset (their action is checked too)
        batch = np.stack([np.asarray(random_action(venv.single_action_space, rng)) for _ in range(4)])
        if venv._needs_reset.any():
            k = int(np.flatnonzero(venv._needs_reset)[0])
            wrong = batch.copy()
            wrong[k] = -1
            with pytest.raises(ValueError, match=rf"slot {k}: action .*-1"):
                venv.step(wrong)
            restarted = True
        got, want = venv.step(batch), vtwin.step(batch)
        np.testing.assert_array_equal(image_of(got[0]), image_of(want[0]))
        assert got[1].tolist() == want[1].tolist() and got[2].tolist() == want[2].tolist()
        assert same(got[4], want[4])
        if restarted:
            break
    assert restarted

    # the batched core (what the trainer drives), with and without an index of stepped slots
    core, core_twin = make_core(env_id, num_envs=4), make_core(env_id, num_envs=4)
    core.reset_slots(range(4), range(4))
    core_twin.reset_slots(range(4), range(4))
    action, message = bad_actions(core.single_action_space)[1]  # the shape of an action, a value outside
    with pytest.raises(ValueError, match=rf"slot 3: {message}"):
        core.step(np.stack([valid[0], np.asarray(action)]), idx=[1, 3])
    with pytest.raises(ValueError, match=r"got actions of shape \(4,.*for 2 slots"):
        core.step(valid, idx=[0, 1])
    for _ in range(20):
        got, want = core.step(valid), core_twin.step(valid)
        assert got[0].tolist() == want[0].tolist() and got[1].tolist() == want[1].tolist()
        np.testing.assert_array_equal(image_of(core.observations()), image_of(core_twin.observations()))


def test_the_environments_page_table_names_every_id_with_its_spaces() -> None:
    """docs/environments.md's table of ids: one row per id, its action space, and its observation with the real keys."""
    from pathlib import Path

    table = (Path(__file__).resolve().parents[2] / "docs" / "environments.md").read_text()

    def describe(space: gym.spaces.Box) -> str:
        return f"{'x'.join(map(str, space.shape))} {space.dtype}"

    for env_id in ALL_IDS:
        rows = [line for line in table.splitlines() if line.startswith(f"| `{env_id}` |")]
        assert len(rows) == 1, f"{env_id}: {len(rows)} rows in docs/environments.md's table"
        actions, observation = (cell.strip() for cell in rows[0].split("|")[3:5])
        core = make_core(env_id)
        action_space = core.single_action_space
        if isinstance(action_space, gym.spaces.Discrete):
            assert actions == f"Discrete({action_space.n})", (env_id, actions)
        else:
            assert actions == f"MultiDiscrete({action_space.nvec.tolist()})".replace(" ", ""), (env_id, actions)
        space = core.single_observation_space
        if isinstance(space, gym.spaces.Dict):
            for key, sub in space.spaces.items():
                assert f"`{key}`: {describe(sub)}" in observation, (env_id, key, observation)
        else:
            assert observation == describe(space), (env_id, observation)


class SlotBySlotVectorEnv(envs.MemoryGymVectorEnv):
    """The vector face as it assembled infos before: every slot's ``step_info`` merged with its final info, through
    gymnasium's ``_add_info``, one slot after the other (the format the array assembly must reproduce)."""

    def reset(self, *, seed: Any = None, options: dict[str, Any] | None = None) -> tuple[Any, dict]:
        options = dict(options or {})
        mask = np.asarray(options.pop("reset_mask", np.ones(self.num_envs, dtype=bool)), dtype=bool)
        obs, _ = super().reset(seed=seed, options={**options, "reset_mask": mask})
        infos: dict[str, Any] = {}
        for k in np.flatnonzero(mask).tolist():
            infos = self._add_info(infos, self.core.step_info(k), k)
        return obs, infos

    def step(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict]:
        n = self.num_envs
        rewards = np.zeros(n, dtype=np.float64)
        terminated = np.zeros(n, dtype=bool)
        infos: dict[str, Any] = {}
        if self.autoreset_mode == AutoresetMode.NEXT_STEP and self._needs_reset.any():
            restart, live = np.flatnonzero(self._needs_reset), np.flatnonzero(~self._needs_reset)
            finals = {}
            if live.size:
                r, t, finals = self.core.step(actions[live], idx=live)
                rewards[live], terminated[live] = r, t
            self.core.restart_slots(restart)
        else:
            rewards, terminated, finals = self.core.step(actions)
        final_obs = self.core.observations() if self.autoreset_mode == AutoresetMode.SAME_STEP else None
        for k in range(n):
            info = self.core.step_info(k)
            info.update(finals.get(k, {}))
            if final_obs is not None and terminated[k]:
                obs_k = {key: v[k] for key, v in final_obs.items()} if isinstance(final_obs, dict) else final_obs[k]
                infos = self._add_info(infos, {"final_obs": obs_k, "final_info": info}, k)
                self.core.restart_slots([k])
                info = self.core.step_info(k)
            if info:
                infos = self._add_info(infos, info, k)
        self._needs_reset = terminated.copy() if self.autoreset_mode == AutoresetMode.NEXT_STEP else np.zeros(n, bool)
        return self.core.observations(), rewards, terminated, np.zeros(n, dtype=bool), infos


def assert_same_infos(got: dict[str, Any], want: dict[str, Any], where: str) -> None:
    """Same keys in the same order, same dtypes and shapes, same values (object arrays element by element)."""
    assert list(got) == list(want), f"{where}: keys {list(got)} != {list(want)}"
    for key, w in want.items():
        g = got[key]
        if isinstance(w, dict):
            assert_same_infos(g, w, f"{where}/{key}")
        elif w.dtype == object:
            assert g.dtype == object and g.shape == w.shape, f"{where}/{key}"
            for i, (a, b) in enumerate(zip(g, w, strict=True)):
                assert same(image_of(a) if a is not None else a, image_of(b) if b is not None else b), (
                    f"{where}/{key}[{i}]"
                )
        else:
            assert (g.dtype, g.shape) == (w.dtype, w.shape), f"{where}/{key}: {g.dtype}{g.shape} != {w.dtype}{w.shape}"
            np.testing.assert_array_equal(g, w, err_msg=f"{where}/{key}")


@pytest.mark.parametrize("env_id", ALL_IDS)
@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
def test_vector_infos_assembled_with_arrays_match_slot_by_slot_assembly(env_id: str, mode: AutoresetMode) -> None:
    core_path, variant = ENV_IDS[env_id]
    fast = gym.make_vec(env_id, num_envs=5, autoreset_mode=mode)
    slow = SlotBySlotVectorEnv(core_path, num_envs=5, autoreset_mode=mode, **variant)
    mask = np.array([True, False, True, True, False])
    for seed, options in ((3, {}), (4, {"reset_mask": mask})):
        got, want = fast.reset(seed=seed, options=options), slow.reset(seed=seed, options=options)
        np.testing.assert_array_equal(image_of(got[0]), image_of(want[0]))
        assert_same_infos(got[1], want[1], f"reset {seed}")
    rng = np.random.default_rng(0)
    finished = 0
    for t in range(MAX_VECTOR_STEPS):
        if finished >= 6:
            break
        actions = np.stack([np.asarray(random_action(fast.single_action_space, rng)) for _ in range(5)])
        got, want = fast.step(actions), slow.step(actions)
        np.testing.assert_array_equal(image_of(got[0]), image_of(want[0]))
        assert got[1].tolist() == want[1].tolist() and got[2].tolist() == want[2].tolist()
        assert_same_infos(got[4], want[4], f"step {t}")
        finished += int(got[2].sum())
    assert finished, "no episode ended: the final infos were not compared"


@pytest.mark.parametrize("env_id", [env_id for env_id in ALL_IDS if make_core(env_id).has_ground_truth_info])
def test_vector_face_assembles_step_infos_without_a_per_slot_call(env_id: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """The endless ids' ground truth comes as one array per step (``step_infos``), not slot by slot."""
    venv = gym.make_vec(env_id, num_envs=4)
    venv.reset(seed=0)

    def per_slot(k: int) -> dict:
        raise AssertionError("the vector face asked for one slot's step info")

    monkeypatch.setattr(venv.core, "step_info", per_slot)
    rng = np.random.default_rng(1)
    for _ in range(60):
        actions = np.stack([np.asarray(random_action(venv.single_action_space, rng)) for _ in range(4)])
        _, _, _, _, infos = venv.step(actions)
        assert infos["ground_truth"].shape[0] == 4 and infos["_ground_truth"].all()
    venv.reset(seed=1)


DISCRETE_IDS = [env_id for env_id in ALL_IDS if isinstance(make_core(env_id).single_action_space, gym.spaces.Discrete)]


@pytest.mark.parametrize("env_id", DISCRETE_IDS)
def test_discrete_actions_take_memory_gym_spellings(env_id: str) -> None:
    """Clients written for memory-gym treat every action space as multi-discrete: ``3``, ``[3]``, ``np.array([3])``
    and ``np.array(3)`` are the same action on the single face, shapes (N,) and (N, 1) on the vector face."""
    spellings = [int, lambda a: [a], lambda a: np.array([a]), np.array, np.int64]
    faces = [gym.make(env_id) for _ in spellings]
    for env in faces:
        env.reset(seed=4)
    rng = np.random.default_rng(0)
    for t in range(120):
        action = int(rng.integers(faces[0].action_space.n))
        results = [env.step(spell(action)) for env, spell in zip(faces, spellings, strict=True)]
        for got in results[1:]:
            assert_step((got[0], *got[1:3], got[4]), (results[0][0], *results[0][1:3], results[0][4]), f"step {t}")
        if results[0][2]:
            for env in faces:
                env.reset()
    for mode in (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP):
        flat, column = (gym.make_vec(env_id, num_envs=4, autoreset_mode=mode) for _ in range(2))
        flat.reset(seed=9)
        column.reset(seed=9)
        for t in range(150):  # through autoresets (the restarting slots' actions are checked too)
            actions = rng.integers(flat.single_action_space.n, size=4)
            got, want = column.step(actions[:, None]), flat.step(actions)
            np.testing.assert_array_equal(image_of(got[0]), image_of(want[0]))
            assert got[1].tolist() == want[1].tolist() and got[2].tolist() == want[2].tolist(), f"step {t}"
        with pytest.raises(ValueError, match=r"slot 0: action \[0, 0\] has shape \(2,\), expected \(\) or \(1,\)"):
            flat.step(np.zeros((4, 2), dtype=np.int64))
        with pytest.raises(ValueError, match=r"slot 2: action 9 is outside the action space"):
            flat.step(np.array([[0], [1], [9], [0]]))


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_options_that_are_not_a_mapping_and_a_missing_action_are_named(env_id: str) -> None:
    env = gym.make(env_id)
    obs, _ = env.reset(seed=2)
    for options in ([1, 2], "command_count", 3):
        with pytest.raises(
            ValueError, match=rf"options={re.escape(repr(options))} is invalid.*expected None or a mapping"
        ):
            env.reset(seed=3, options=options)
    assert np.array_equal(image_of(env.unwrapped.core.observations())[0], image_of(obs)), "the level was left alone"
    with pytest.raises(gym.error.ResetNeeded):  # as after any refused reset
        env.step(random_action(env.action_space, np.random.default_rng(0)))
    env.reset(seed=3)
    with pytest.raises(ValueError, match=r"slot 0: action None is not an action: expected an action in"):
        env.step(None)
    env.step(random_action(env.action_space, np.random.default_rng(0)))  # the episode goes on
    with pytest.raises(ValueError, match=r"options=\[1\] is invalid.*valid options: "):
        gym.make(env_id, options=[1])
    venv = gym.make_vec(env_id, num_envs=2)
    with pytest.raises(ValueError, match=r"options=\[1, 2\] is invalid.*valid options: .*reset_mask"):
        venv.reset(seed=0, options=[1, 2])
    venv.reset(seed=0)
    with pytest.raises(ValueError, match=r"got actions of shape \(\) for 2 slots"):
        venv.step(None)
    with pytest.raises(ValueError, match=r"slot 0: action None is not an action"):
        venv.step([None, None])


MMG = "MortarMayhem-Grid-v0"


def vector_command_counts(venv: gym.vector.VectorEnv, episodes: int, seed: int = 0) -> list[int]:
    """``command_count`` of every episode that ends until each slot has finished ``episodes`` (random play)."""
    rng = np.random.default_rng(seed)
    counts: list[int] = []
    ended = np.zeros(venv.num_envs, dtype=int)
    while (ended < episodes).any():
        _, _, terminated, _, infos = venv.step(rng.integers(4, size=venv.num_envs))
        if terminated.any():
            final = infos.get("final_info", infos)  # SAME_STEP nests the final infos
            counts += final["command_count"][terminated].tolist()
        ended += terminated
    return counts


@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
def test_vector_reset_options_persist_through_autoresets(mode: AutoresetMode) -> None:
    """The options of a vector reset apply to every later episode of the slots it reset (autoresets included) until
    their next reset; a reset without options goes back to make_vec's options."""
    venv = gym.make_vec(MMG, num_envs=4, autoreset_mode=mode)
    venv.reset(seed=0, options={"command_count": [3]})
    counts = vector_command_counts(venv, 3)
    assert len(counts) >= 12 and set(counts) == {3}, counts
    limit = {n: n * (3 + 1) + n * (6 + 2) - 2 + 1 for n in (2, 3)}  # C + n(D + E) - E + 1, C = n (shown + blank)
    assert venv.max_episode_steps.tolist() == [limit[3]] * 4
    venv.reset(seed=1)
    assert set(vector_command_counts(venv, 2)) == {10}
    # make_vec's options are the defaults that a reset without options goes back to
    venv = gym.make_vec(MMG, num_envs=4, autoreset_mode=mode, options={"command_count": [4]})
    venv.reset(seed=2)
    assert set(vector_command_counts(venv, 2)) == {4}
    venv.reset(seed=3, options={"command_count": [3]})
    assert set(vector_command_counts(venv, 2)) == {3}
    venv.reset(seed=4, options={"command_count": [2], "reset_mask": np.array([True, True, False, False])})
    counts = vector_command_counts(venv, 2)  # slots 2 and 3 keep the options of their last reset
    assert set(counts) == {2, 3} and counts.count(2) >= 4 and counts.count(3) >= 4
    assert venv.max_episode_steps.tolist() == [limit[2]] * 2 + [limit[3]] * 2
    venv.reset(seed=5)
    assert set(vector_command_counts(venv, 2)) == {4}


def test_single_face_options_apply_to_one_episode_as_in_memory_gym() -> None:
    env = gym.make(MMG)
    env.reset(seed=0, options={"command_count": [3]})
    counts = []
    rng = np.random.default_rng(0)
    while len(counts) < 3:
        _, _, terminated, _, info = env.step(int(rng.integers(4)))
        if terminated:
            counts.append(info["command_count"])
            env.reset()
    assert counts == [3, 10, 10]
