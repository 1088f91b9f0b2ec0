"""The batched core and its faces, exercised on the tiny ProofOfMemory-v0 family."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import envs
from envs.core import seeded_generator


def play(env: gym.Env, seed: int | None, actions: list[int]) -> list[tuple]:
    obs, info = env.reset(seed=seed)
    out = [(obs.tobytes(), info)]
    for a in actions:
        obs, reward, terminated, truncated, info = env.step(a)
        out.append((obs.tobytes(), reward, terminated, truncated, info))
        if terminated:
            break
    return out


def test_seeded_generator_matches_gymnasium_seeding() -> None:
    from gymnasium.utils import seeding

    ours, theirs = seeded_generator(123), seeding.np_random(123)[0]
    assert ours.integers(0, 10**9, size=5).tolist() == theirs.integers(0, 10**9, size=5).tolist()


def test_same_seed_same_episode_and_np_random_is_the_level_generator() -> None:
    env = gym.make("ProofOfMemory-v0")
    first = play(env, 7, [0] * 10)
    second = play(env, 7, [0] * 10)
    assert first == second
    env.reset(seed=7)
    assert env.unwrapped.np_random is env.unwrapped.core.rngs[0]


def test_unseeded_reset_continues_the_generator() -> None:
    env = gym.make("ProofOfMemory-v0")
    env.reset(seed=5)
    cues = [int(env.unwrapped.core.cue[0])]
    for _ in range(20):
        env.reset()
        cues.append(int(env.unwrapped.core.cue[0]))
    rng = seeded_generator(5)
    assert cues == [int(rng.integers(0, 2)) for _ in range(21)]


def test_options_apply_to_one_episode_and_constructor_options_are_defaults() -> None:
    env = gym.make("ProofOfMemory-v0")
    env.reset(seed=0, options={"delay": 2})
    assert env.unwrapped.core.delay[0] == 2
    env.reset(seed=0)
    assert env.unwrapped.core.delay[0] == 4
    env = gym.make("ProofOfMemory-v0", options={"delay": 9})
    env.reset(seed=0)
    assert env.unwrapped.core.delay[0] == 9
    with pytest.raises(ValueError, match="unknown option 'dealy'"):
        gym.make("ProofOfMemory-v0", options={"dealy": 9})


def test_invalid_reset_leaves_the_episode_untouched() -> None:
    env = gym.make("ProofOfMemory-v0")
    obs, _ = env.reset(seed=1)
    with pytest.raises(ValueError, match="'delay'=0"):
        env.reset(seed=2, options={"delay": 0})
    assert env.unwrapped.core.seeds[0] == 1
    np.testing.assert_array_equal(env.unwrapped.core.observations()[0], obs)


def test_reset_slots_equals_resetting_each_slot_and_validates_first() -> None:
    together, one_by_one = (
        envs.make_core("ProofOfMemory-v0", num_envs=5),
        envs.make_core("ProofOfMemory-v0", num_envs=5),
    )
    together.reset_slots([4, 1, 2], [30, None, 32], {"delay": 3})
    for k, seed in [(4, 30), (1, None), (2, 32)]:
        one_by_one.reset_slot(k, seed, {"delay": 3})
    for k in (2, 4):
        assert together.seeds[k] == one_by_one.seeds[k]
        np.testing.assert_array_equal(together.cue[k], one_by_one.cue[k])
        assert together.delay[k] == 3
    np.testing.assert_array_equal(together.observations([2, 4]), one_by_one.observations([2, 4]))
    before = together.observations()
    with pytest.raises(ValueError, match="got 1 seeds for 2 slots"):
        together.reset_slots([0, 3], [1])
    with pytest.raises(ValueError, match="seed=-1 is invalid"):
        together.reset_slots([0, 3], [1, -1])
    assert together.seeds[0] is None and together.seeds[3] is None  # nothing was reset
    np.testing.assert_array_equal(together.observations(), before)


def test_make_core_rejects_unknown_ids_and_bad_sizes() -> None:
    with pytest.raises(ValueError, match=r"unknown environment id 'Nope-v0'.*this project's own ids: ProofOfMemory-v0"):
        envs.make_core("Nope-v0")
    with pytest.raises(ValueError, match="num_envs=0"):
        envs.make_core("ProofOfMemory-v0", num_envs=0)


def test_bad_render_mode_and_autoreset_mode_are_named() -> None:
    with pytest.warns(UserWarning, match="render_mode"), pytest.raises(ValueError, match="render_mode='rgb'.*valid"):
        gym.make("ProofOfMemory-v0", render_mode="rgb")
    with pytest.raises(ValueError, match="autoreset_mode='later'"):
        gym.make_vec("ProofOfMemory-v0", num_envs=2, autoreset_mode="later")


def test_vector_next_step_autoreset_matches_single_envs() -> None:
    n, delay = 3, 2
    vec = gym.make_vec("ProofOfMemory-v0", num_envs=n, options={"delay": delay})
    assert vec.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    obs, _ = vec.reset(seed=10)
    singles = [gym.make("ProofOfMemory-v0", options={"delay": delay}) for _ in range(n)]
    single_obs = [env.reset(seed=10 + k)[0] for k, env in enumerate(singles)]
    np.testing.assert_array_equal(obs, np.stack(single_obs))
    rng = np.random.default_rng(0)
    for t in range(3 * (delay + 2)):
        actions = rng.integers(0, 2, size=n)
        obs, rewards, terminated, truncated, infos = vec.step(actions)
        if t % (delay + 2) == delay + 1:  # the step after an episode end: reset, reward 0, action ignored
            expect = [env.reset()[0] for env in singles]
            np.testing.assert_array_equal(obs, np.stack(expect))
            assert not rewards.any() and not terminated.any()
            continue
        for k, env in enumerate(singles):
            o, r, te, tr, info = env.step(int(actions[k]))
            np.testing.assert_array_equal(obs[k], o)
            assert (rewards[k], terminated[k], truncated[k]) == (r, te, tr)
            if te:
                assert infos["_success"][k] and infos["success"][k] == info["success"]
                assert infos["length"][k] == info["length"] == delay + 1


def test_vector_same_step_autoreset_reports_final_obs_and_info() -> None:
    vec = gym.make_vec("ProofOfMemory-v0", num_envs=2, autoreset_mode="SameStep", options={"delay": 1})
    vec.reset(seed=0)
    vec.step(np.zeros(2, dtype=np.int64))
    obs, rewards, terminated, _, infos = vec.step(np.zeros(2, dtype=np.int64))
    assert terminated.all()
    assert infos["_final_obs"].all() and infos["final_obs"][0].shape == (36, 36, 3)
    assert infos["final_info"]["length"].tolist() == [2, 2]  # gymnasium batches nested info dicts
    np.testing.assert_array_equal(obs, vec.unwrapped.core.observations())  # already the next episode's first frame
    assert vec.unwrapped.core.episode_length.tolist() == [0, 0]


def test_vector_reset_mask_resets_only_masked_slots() -> None:
    vec = gym.make_vec("ProofOfMemory-v0", num_envs=3)
    vec.reset(seed=[1, 2, 3])
    vec.step(np.zeros(3, dtype=np.int64))
    vec.reset(seed=[None, 9, None], options={"reset_mask": np.array([False, True, False])})
    core = vec.unwrapped.core
    assert core.t.tolist() == [1, 0, 1] and core.seeds == [1, 9, 3]
    with pytest.raises(ValueError, match="reset_mask has shape"):
        vec.reset(options={"reset_mask": np.ones(2, dtype=bool)})


def test_render_modes() -> None:
    env = gym.make("ProofOfMemory-v0", render_mode="rgb_array")
    obs, _ = env.reset(seed=0)
    np.testing.assert_array_equal(env.render(), obs)
    env = gym.make("ProofOfMemory-v0", render_mode="debug_rgb_array")
    obs, _ = env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (144, 144, 3)
    np.testing.assert_array_equal(frame[::4, ::4], obs)


def test_human_render_opens_a_dummy_window(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    env = gym.make("ProofOfMemory-v0", render_mode="human")
    env.reset(seed=0)
    env.step(0)
    assert env.unwrapped._window is not None
    env.close()


@pytest.mark.parametrize("env_id", ["ProofOfMemory-v0", "SearingSpotlights-v0", "MortarMayhem-Grid-v0"])
def test_step_without_an_episode_asks_for_a_reset_and_a_valid_reset_then_works(env_id: str) -> None:
    from gymnasium.error import ResetNeeded

    action = 0 if env_id != "SearingSpotlights-v0" else [0, 0]
    env = gym.make(env_id)  # with gymnasium's default wrappers
    with pytest.raises(ResetNeeded, match="reset"):
        env.step(action)
    with pytest.raises(ValueError, match="unknown option 'bogus'"):
        env.reset(seed=0, options={"bogus": 1})
    for _ in range(2):  # every step, not only the first, asks for a reset
        with pytest.raises(ResetNeeded, match="slot 0 .* no episode to step .*call reset first"):
            env.step(action)
    obs, _ = env.reset(seed=0)
    twin = gym.make(env_id, disable_env_checker=True)
    assert np.array_equal(obs, twin.reset(seed=0)[0])
    for _ in range(10):
        got, want = env.step(action), twin.step(action)
        assert np.array_equal(got[0], want[0]) and got[1:4] == want[1:4]

    # a reset that fails later (here: on its options) leaves no episode to continue either
    with pytest.raises(ValueError, match="unknown option"):
        env.reset(seed=1, options={"bogus": 1})
    with pytest.raises(ResetNeeded, match="call reset first"):
        env.step(action)
    env.reset(seed=1)
    env.step(action)

    # the raw face and the native vector face
    raw = envs.MemoryGymEnv(envs.ENV_IDS[env_id][0], **envs.ENV_IDS[env_id][1])
    with pytest.raises(ResetNeeded, match="slot 0 .*call reset first"):
        raw.step(action)
    venv = gym.make_vec(env_id, num_envs=3)
    actions = np.stack([np.asarray(action)] * 3)
    with pytest.raises(ResetNeeded, match="slots 0, 1, 2 .*call reset first"):
        venv.step(actions)
    with pytest.raises(ValueError, match="unknown option"):
        venv.reset(seed=0, options={"bogus": 1, "reset_mask": np.array([False, True, False])})
    venv.reset(seed=0, options={"reset_mask": np.array([True, False, True])})
    with pytest.raises(ResetNeeded, match="slot 1 .*call reset first"):
        venv.step(actions)
    venv.reset(seed=0)
    venv.step(actions)


def test_a_reset_that_fails_while_building_the_level_leaves_no_episode(monkeypatch: pytest.MonkeyPatch) -> None:
    from gymnasium.error import ResetNeeded

    core = envs.make_core("ProofOfMemory-v0", num_envs=3)
    core.reset_slots(range(3), [0, 1, 2])
    original = type(core)._reset_slot

    def failing(self, k, rng, opts):
        original(self, k, rng, opts)  # the level is half written when it fails
        if k == 1:
            raise RuntimeError("no room for the level")

    monkeypatch.setattr(type(core), "_reset_slot", failing)
    with pytest.raises(RuntimeError, match="no room"):
        core.reset_slots([0, 1], [5, 6])
    monkeypatch.undo()
    with pytest.raises(ResetNeeded, match="slots 0, 1 .*call reset first"):
        core.step(np.zeros(3, np.int64))
    core.step(np.zeros(1, np.int64), idx=[2])  # the slot whose reset did not fail plays on
    core.reset_slots([0, 1], [5, 6])
    core.step(np.zeros(3, np.int64))
