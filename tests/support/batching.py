"""Shared check: one core with several slots (stepped all at once or a few at a time) equals one-slot cores."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

import envs
from envs.compare import jsonable, values_equal
from envs.core import BatchedCore

ActionChooser = Callable[[np.random.Generator, list[BatchedCore]], np.ndarray]


def check_batched_equals_singles(
    env_id: str, options: Sequence[dict[str, Any] | None], steps: int, choose_actions: ActionChooser, n: int = 6
) -> tuple[list[BatchedCore], int]:
    """Step an ``n``-slot core and ``n`` one-slot cores side by side; assert identical rewards, flags, infos, frames
    and debug views. Slot k uses ``options[k % len(options)]``; finished slots restart with continued generators.
    The batched core resets the slots that share options together (``reset_slots``), the one-slot cores one by one.
    Returns the one-slot cores and the number of finished episodes."""
    batched = envs.make_core(env_id, num_envs=n)
    singles = [envs.make_core(env_id) for _ in range(n)]

    def reset_batched(slots: Sequence[int], seeds: Sequence[int | None]) -> None:
        for group in range(len(options)):
            chosen = [i for i, k in enumerate(slots) if k % len(options) == group]
            if chosen:
                batched.reset_slots([slots[i] for i in chosen], [seeds[i] for i in chosen], options[group])

    reset_batched(range(n), [100 + k for k in range(n)])
    for k in range(n):
        singles[k].reset_slot(0, seed=100 + k, options=options[k % len(options)])
    rng = np.random.default_rng(0)
    episodes = 0
    for t in range(steps):
        actions = choose_actions(rng, singles)
        live = np.arange(n) if t % 5 else np.sort(rng.permutation(n)[: rng.integers(1, n)])  # a few slots at a time
        rewards, terminated, finals = batched.step(actions[live], idx=live)
        for i, k in enumerate(live.tolist()):
            r, term, final = singles[k].step(actions[k : k + 1])
            assert rewards[i] == r[0] and terminated[i] == term[0], (t, k)
            assert values_equal(jsonable(finals.get(k, {})), jsonable(final.get(0, {})))
            assert values_equal(jsonable(batched.step_info(k)), jsonable(singles[k].step_info(0)))
            if term[0]:
                episodes += 1
                singles[k].reset_slot(0, options=options[k % len(options)])
        reset_batched(live[terminated].tolist(), [None] * int(terminated.sum()))  # the generators continue
        assert_observations_equal(batched.observations(), [s.observations() for s in singles])
        if t % 25 == 0:
            for k in range(n):
                np.testing.assert_array_equal(batched.debug_frame(k), singles[k].debug_frame(0))
    return singles, episodes


def assert_observations_equal(batched: Any, singles: list[Any]) -> None:
    """Observations of all slots of a batched core equal those of the one-slot cores (arrays or dicts of arrays)."""
    if isinstance(batched, dict):
        for key, value in batched.items():
            np.testing.assert_array_equal(value, np.stack([single[key][0] for single in singles]), err_msg=key)
    else:
        np.testing.assert_array_equal(batched, np.stack([single[0] for single in singles]))


def check_vector_env_matches_singles(
    env_id: str, options: dict[str, Any], steps: int, choose_actions: ActionChooser, n: int = 3
) -> int:
    """``gymnasium.make_vec`` (next-step autoreset, generators continued) against ``n`` single envs reset without a
    seed after each episode; asserts identical observations, rewards and flags. Returns the number of autoresets."""
    import gymnasium as gym

    vec = gym.make_vec(env_id, num_envs=n, options=options)
    singles = [gym.make(env_id, disable_env_checker=True, options=options) for _ in range(n)]
    obs, _ = vec.reset(seed=40)
    for k, env in enumerate(singles):
        np.testing.assert_array_equal(obs[k], env.reset(seed=40 + k)[0])
    rng = np.random.default_rng(1)
    restart, resets = [False] * n, 0
    for _ in range(steps):
        actions = choose_actions(rng, [env.unwrapped.core for env in singles])
        obs, rewards, terminated, truncated, _ = vec.step(actions)
        assert not truncated.any()
        for k, env in enumerate(singles):
            if restart[k]:  # this step reset slot k (its action is ignored)
                single_obs, _ = env.reset()
                assert rewards[k] == 0 and not terminated[k]
                restart[k], resets = False, resets + 1
            else:
                single_obs, reward, single_terminated, _, _ = env.step(actions[k])
                assert reward == rewards[k] and single_terminated == terminated[k]
                restart[k] = single_terminated
            np.testing.assert_array_equal(obs[k], single_obs)
    return resets
