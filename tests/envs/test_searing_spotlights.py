"""Mechanics of SearingSpotlights-v0 and Endless-SearingSpotlights-v0 (spec sections 7, 8 and 11)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import envs
from envs.core import seeded_generator
from envs.rng import DirectDraws
from envs.searing_spotlights import (
    ACTION_COLOURS,
    GREEN,
    HUD_GREY,
    RED,
    SCREEN,
    SPOTS,
    YELLOW,
    SearingSpotlightsCore,
    alpha_schedule,
    block_position,
    darken,
    draw_order,
    lighten,
    paint_hud_row,
    sample_position,
)
from tests.support.batching import check_batched_equals_singles, check_vector_env_matches_singles

IDS = ["SearingSpotlights-v0", "Endless-SearingSpotlights-v0"]
NO_SPOTLIGHTS = {"initial_spawns": 0}  # plus "num_spawns": 0 for SearingSpotlights-v0
ORANGE = (255, 165, 0)  # the coin
AGENT_BODY = (250, 204, 153)


def make(env_id: str, **kwargs: object) -> gym.Env:
    return gym.make(env_id, disable_env_checker=True, **kwargs)


def core_of(env: gym.Env) -> SearingSpotlightsCore:
    return env.unwrapped.core


def no_spotlights(env_id: str) -> dict:
    if env_id.startswith("Endless"):
        return {"initial_spawns": 0, "spawn_interval": 10**9}  # no limit on spawns, so: never spawn
    return {"initial_spawns": 0, "num_spawns": 0}


def count(frame: np.ndarray, colour: tuple[int, int, int]) -> int:
    return int(np.all(frame == np.array(colour, np.uint8), axis=-1).sum())


def hud_colour(frame: np.ndarray, x: int) -> tuple[int, ...]:
    return tuple(int(c) for c in frame[1, x])


def action_towards(core: SearingSpotlightsCore, x: int, y: int) -> list[int]:
    ax, ay = int(core.x[0]), int(core.y[0])
    horizontal = 0 if abs(x - ax) < 2 else (1 if x < ax else 2)
    vertical = 0 if abs(y - ay) < 2 else (1 if y < ay else 2)
    return [horizontal, vertical]


def walk_to(env: gym.Env, x: int, y: int, max_steps: int = 80) -> list[tuple]:
    """Step towards (x, y) until something is rewarded or the episode ends; returns (obs, reward, term, info)."""
    core = core_of(env)
    out = []
    for _ in range(max_steps):
        obs, reward, terminated, truncated, info = env.step(action_towards(core, x, y))
        assert not truncated
        out.append((obs, reward, terminated, info))
        if reward > 0 or terminated:
            return out
    raise AssertionError("target not reached")


# ------------------------------------------------------------------------------------------ spotlights
def spawn_steps(env_id: str, options: dict, steps: int) -> list[int]:
    env = make(env_id)
    env.reset(seed=3, options=options)
    core = core_of(env)
    spawned = []
    original = core._new_spot

    def recording(k, rng, opts):
        spawned.append(int(core.t[k]))
        return original(k, rng, opts)

    core._new_spot = recording
    for _ in range(steps):
        env.step([0, 0])
    return spawned


def test_spawn_schedule_is_a_constant_40_steps_until_num_spawns() -> None:
    invincible = {"spot_damage": 0.0, "max_steps": 1300}
    assert spawn_steps("SearingSpotlights-v0", invincible, 1250) == list(range(40, 1201, 40))  # 30 spawns
    assert spawn_steps("SearingSpotlights-v0", {**invincible, "num_spawns": 3}, 400) == [40, 80, 120]
    assert spawn_steps("SearingSpotlights-v0", {**invincible, "num_spawns": 0}, 200) == []


def test_endless_spawns_every_spawn_interval_without_limit() -> None:
    options = {"spot_damage": 0.0, "steps_per_coin": -1}
    assert spawn_steps("Endless-SearingSpotlights-v0", options, 600) == list(range(50, 601, 50))
    assert spawn_steps("Endless-SearingSpotlights-v0", {**options, "spawn_interval": 7}, 30) == [7, 14, 21, 28]


def test_spotlight_creation_makes_the_five_draws_in_the_reference_order() -> None:
    core = envs.make_core("SearingSpotlights-v0")
    opts = core.resolve(None)
    rng, twin = seeded_generator(5), seeded_generator(5)
    record = core._new_spot(0, DirectDraws(rng), opts)
    radius = twin.integers(7.5, 14.75)  # float bounds are truncated: an int in 7..13
    speed = twin.uniform(0.0025, 0.0075)
    start = twin.integers(0, 360)
    target = start + 180 + twin.integers(-45, 45)
    offset = target + twin.integers(-135, 135)
    spot = np.array(record, SPOTS)
    assert spot["radius"] == radius and spot["speed"] == speed
    assert rng.integers(0, 2**62) == twin.integers(0, 2**62)  # no further draws
    orbit = 42 * np.sqrt(2) + radius
    points = (spot["start"], spot["target"], spot["offset"])
    for point, angle in zip(points, (start, target, offset), strict=True):
        expected = complex(42 + orbit * np.cos(np.radians(angle)), 42 + orbit * np.sin(np.radians(angle)))
        assert abs(point - expected) < 1e-9  # angles grow clockwise on screen, around the screen centre


def test_radius_is_an_int_in_7_to_13() -> None:
    core = envs.make_core("SearingSpotlights-v0")
    opts = core.resolve(None)
    rng = seeded_generator(0)
    draws = DirectDraws(rng)
    radii = {core._new_spot(0, draws, opts)[0] for _ in range(400)}
    assert radii == set(range(7, 14))


def test_a_spotlight_after_a_removed_one_is_skipped_for_one_step() -> None:
    """Quirk 14: removal while iterating skips the next spotlight: not drawn, not moved."""
    env = make("SearingSpotlights-v0")
    env.reset(seed=1, options={"spot_damage": 0.0})
    core = core_of(env)
    spots = core.spots[0]
    spots["tau"][0] = 1.0 - spots["speed"][0] / 2  # finishes in the next step
    env.step([0, 0])
    assert spots["done"][0] and core.spot_count[0] == 4
    tau_next = spots["tau"][1]
    env.step([0, 0])  # the first one is removed, the second one skipped
    assert core.spot_count[0] == 3
    assert spots["tau"][0] == tau_next and not spots["drawn"][0]  # the former second spotlight, not moved
    assert spots["drawn"][1] and spots["drawn"][2]
    env.step([0, 0])
    assert spots["tau"][0] > tau_next and spots["drawn"][0]


def test_spotlights_live_and_hit_within_radius_plus_agent_radius() -> None:
    env = make("SearingSpotlights-v0")
    env.reset(seed=2, options={"spot_damage": 0.0, "max_steps": 600})
    core = core_of(env)
    lifetimes = np.ceil(1 / core.spots["speed"][0, :4])
    assert ((lifetimes >= 134) & (lifetimes <= 400)).all()
    for _ in range(60):
        spots = core.spots[0]
        centre = (
            spots["start"] * (1 - spots["tau"])
            + (spots["target"] * (1 - spots["tau"]) + spots["offset"] * spots["tau"]) * spots["tau"]
        )
        listed = spots["listed"] & ~spots["done"]
        distance = np.abs(centre - complex(core.x[0], core.y[0]))
        expect_hit = bool((listed & (distance <= spots["radius"] + 6)).any())
        env.step([0, 0])
        assert bool(core.hit[0]) == expect_hit


# ------------------------------------------------------------------------------------------ light & HUD
def test_alpha_sequence_and_the_blend_arithmetic() -> None:
    assert alpha_schedule(6, 255)[:9].tolist() == [0, 42, 84, 126, 168, 210, 252, 255, 255]
    assert alpha_schedule(6, 100)[:6].tolist() == [0, 42, 84, 126, 126, 126]  # first multiple above the threshold
    assert alpha_schedule(0, 200)[:3].tolist() == [200, 200, 200]
    values = np.arange(256, dtype=np.uint8)
    for alpha in range(256):  # SDL: D + trunc((S - D) * A / 255)
        expect_black = values.astype(int) + np.trunc((0 - values.astype(int)) * alpha / 255).astype(int)
        expect_white = values.astype(int) + np.trunc((255 - values.astype(int)) * alpha / 255).astype(int)
        assert (darken(values, np.array(alpha)) == expect_black).all()
        assert (lighten(values, alpha) == expect_white).all()
    env = make("SearingSpotlights-v0")
    obs, _ = env.reset(seed=0, options=no_spotlights("SearingSpotlights-v0"))
    white = []
    for _ in range(8):
        white.append(int(obs[SCREEN - 1, 0, 0]))  # the bottom-left square is white
        obs, *_ = env.step([0, 0])
    assert white == [255, 213, 171, 129, 87, 45, 3, 0]


def test_hud_shows_the_previous_action_and_reward_one_step_late() -> None:
    env = make("SearingSpotlights-v0")
    obs, _ = env.reset(seed=4, options={"spot_damage": 0.0})
    core = core_of(env)
    assert hud_colour(obs, 50) == ACTION_COLOURS[0] and hud_colour(obs, 70) == ACTION_COLOURS[0]
    assert hud_colour(obs, 60) == ACTION_COLOURS[0]  # no reward block before the first step
    previous = [0, 0]
    for action in ([1, 2], [2, 1], [0, 2], [2, 0]):
        obs, *_ = env.step(action)
        assert hud_colour(obs, 45) == ACTION_COLOURS[previous[0]] and hud_colour(obs, 80) == ACTION_COLOURS[previous[1]]
        assert hud_colour(obs, 60) == HUD_GREY
        previous = action
    coin = int(core.coin_x[0, 0]), int(core.coin_y[0, 0])
    steps = walk_to(env, *coin)
    assert steps[-1][1] == 0.25 and hud_colour(steps[-1][0], 60) == HUD_GREY  # the pickup frame: not yet
    obs, reward, *_ = env.step([0, 0])
    assert hud_colour(obs, 60) == YELLOW and reward == 0
    obs, *_ = env.step([0, 0])
    assert hud_colour(obs, 60) == HUD_GREY


def test_health_bar_widths() -> None:
    rows = [paint_hud_row(False, True, True, (0, 0), 1, int(42 * (1 - h / 5))).reshape(SCREEN, 3) for h in range(5)]
    widths = [int(np.all(row == RED, axis=1).sum()) for row in rows[::-1]]
    assert widths == [8, 16, 25, 33, 42]
    env = make("SearingSpotlights-v0")
    env.action_space.seed(0)
    seen = []
    for seed in range(40):
        obs, _ = env.reset(seed=seed)
        core = core_of(env)
        terminated = False
        while not terminated:
            obs, _, terminated, _, info = env.step(env.action_space.sample())
            red = int(np.all(obs[0] == np.array(RED, np.uint8), axis=1).sum())
            assert red == int(42 * (1 - core.health[0] / 5))
            assert count(obs[:4, red:42], GREEN) == 4 * (42 - red)
            seen.append(red)
        if {8, 16, 25, 33, 42} <= set(seen):
            break
    assert {0, 8, 16, 25, 33, 42} <= set(seen)


def test_red_floor_on_hit_steps_only() -> None:
    env = make("SearingSpotlights-v0")
    env.reset(seed=7, options={"light_threshold": 0})  # alpha stays 42: the floor is visible everywhere
    core = core_of(env)
    for _ in range(200):
        obs, _, terminated, _, _ = env.step([0, 0])
        reds = count(obs[4:], (255 - 42, 0, 0))
        assert (reds > 0) == bool(core.hit[0])
        if terminated:
            break


# ------------------------------------------------------------------------------------------ sampler
def test_sampler_blocks_the_radius_and_draws_free_pixels_uniformly_in_row_major_order() -> None:
    mask = np.zeros((SCREEN, SCREEN), bool)
    block_position(mask, 10, 20, 28)
    ys, xs = np.mgrid[:SCREEN, :SCREEN]
    assert (mask == ((xs - 10) ** 2 + (ys - 20) ** 2 < 28**2)).all()
    rng, twin = seeded_generator(9), seeded_generator(9)
    x, y = sample_position(mask, rng, 21)
    free = np.flatnonzero(~((xs - 10) ** 2 + (ys - 20) ** 2 < 28**2))
    assert (x, y) == divmod(int(free[twin.integers(0, free.size)]), SCREEN)[::-1]
    assert mask[y, x] and (x - 10) ** 2 + (y - 20) ** 2 >= 28**2


def test_spawn_positions_keep_their_distances_and_the_agent_is_not_clamped_at_reset() -> None:
    core = envs.make_core("SearingSpotlights-v0")
    agent_coin, positions = [], []
    for seed in range(200):
        core.reset_slot(0, seed=seed)
        ax, ay = int(core.x[0]), int(core.y[0])
        positions.append((ax, ay))
        cx, cy, ex, ey = int(core.coin_x[0, 0]), int(core.coin_y[0, 0]), int(core.exit_x[0]), int(core.exit_y[0])
        agent_coin.append(np.hypot(ax - cx, ay - cy))
        assert 7 <= min(cx, cy, ex, ey) and max(cx, cy, ex, ey) <= 77
        assert np.hypot(cx - ex, cy - ey) > 14
    assert min(agent_coin) > 19
    positions = np.array(positions)
    assert positions.min() < 6 or positions.max() > 78  # the agent starts anywhere in 2..86
    assert positions.min() >= 2 and positions.max() <= 86
    core.step(np.zeros((1, 2), int))
    assert 6 <= core.x[0] <= 78 and 10 <= core.y[0] <= 78


def test_choice_draws_like_integers() -> None:
    """The reset uses integers(0, n) where the reference calls rng.choice on an n-element list."""
    for seed in range(20):
        a, b = seeded_generator(seed), seeded_generator(seed)
        assert a.choice([0, 45, 90, 135, 180, 225, 270, 315]) == 45 * b.integers(0, 8)
        assert a.choice([2, 3]) == [2, 3][b.integers(0, 2)] and a.choice([1]) == [1][b.integers(0, 1)]
        assert a.integers(0, 2**62) == b.integers(0, 2**62)


# ------------------------------------------------------------------------------------------ coins & exit
def test_coin_then_exit_pays_and_ends_with_success() -> None:
    env = make("SearingSpotlights-v0")
    obs, _ = env.reset(seed=5, options={"spot_damage": 0.0, "exit_visible": True})
    core = core_of(env)
    assert count(obs, (55, 55, 55)) > 0 and count(obs, (48, 141, 70)) == 0  # closed exit (visible)
    steps = walk_to(env, int(core.coin_x[0, 0]), int(core.coin_y[0, 0]))
    obs, reward, terminated, info = steps[-1]
    assert reward == 0.25 and not terminated and info == {}
    assert count(obs, (48, 141, 70)) > 0  # the exit is open (green) in the same step
    steps = walk_to(env, int(core.exit_x[0]), int(core.exit_y[0]))
    obs, reward, terminated, info = steps[-1]
    assert reward == 1.0 and terminated
    assert set(info) == {"reward", "length", "agent_health", "coins_collected", "success"}
    assert info["success"] == 1 and info["coins_collected"] == 1.0 and info["reward"] == 1.25
    assert info["agent_health"] == 1.0


def test_without_exit_the_last_coin_ends_the_episode_and_no_coins_give_nan() -> None:
    env = make("SearingSpotlights-v0")
    env.reset(seed=6, options={"spot_damage": 0.0, "use_exit": False, "num_coins": [2]})
    core = core_of(env)
    rewards = []
    for j in range(2):
        steps = walk_to(env, int(core.coin_x[0, j]), int(core.coin_y[0, j]))
        rewards.append(steps[-1][1])
        if steps[-1][2]:
            break
    assert rewards == [0.25, 0.25] and steps[-1][2] and steps[-1][3]["success"] == 1
    env.reset(seed=6, options={"num_coins": [0], "max_steps": 3, "spot_damage": 0.0})
    obs, _, _, _, _ = env.step([0, 0])
    assert count(obs, (48, 141, 70)) == 0  # hidden under the darkness, but open
    assert core.exit_open[0]
    for _ in range(2):
        *_, terminated, _, info = env.step([0, 0])
    assert terminated and np.isnan(info["coins_collected"]) and info["success"] == 0


def test_time_limit_and_death_terminate() -> None:
    env = make("SearingSpotlights-v0")
    env.reset(seed=0, options={"max_steps": 12, "spot_damage": 0.0})
    for t in range(1, 13):
        *_, terminated, truncated, info = env.step([0, 0])
        assert terminated == (t == 12) and not truncated
    assert info["success"] == 0 and info["length"] == 12
    env.reset(seed=0, options={"spot_damage": 5.0, "reward_death": -1.0, "reward_inside_spotlight": -0.5})
    env.action_space.seed(0)
    core = core_of(env)
    terminated = False
    while not terminated:
        _, reward, terminated, _, info = env.step(env.action_space.sample())
    assert core.hit[0] and reward == -1.5 and info["agent_health"] == 0.0 and info["success"] == 0


# ------------------------------------------------------------------------------------------ endless
def test_endless_budget_of_160_steps_per_coin() -> None:
    env = make("Endless-SearingSpotlights-v0")
    for seed in range(20):
        _, info = env.reset(seed=seed, options={"spot_damage": 0.0})
        core = core_of(env)
        if np.hypot(core.x[0] - core.coin_x[0, 0], core.y[0] - core.coin_y[0, 0]) > 12:
            break
    assert set(info) == {"ground_truth"}
    for t in range(1, 161):
        *_, terminated, _, info = env.step([0, 0])
        assert terminated == (t == 160)
    assert set(info) == {"reward", "length", "agent_health", "coins_collected", "ground_truth"}
    assert info["coins_collected"] == 0 and info["length"] == 160


def test_endless_coin_respawns_shows_for_a_few_frames_and_restarts_the_budget() -> None:
    env = make("Endless-SearingSpotlights-v0")
    core = core_of(env)
    for seed in range(3, 40):  # a level whose first coin is not within reach (that happens: quirk 19)
        obs, info = env.reset(seed=seed, options={"spot_damage": 0.0, "initial_spawns": 0, "steps_per_coin": 60})
        if np.hypot(core.x[0] - core.coin_x[0, 0], core.y[0] - core.coin_y[0, 0]) > 12:
            break
    visible = [count(obs, ORANGE) > 0]
    for _ in range(8):
        obs, *_ = env.step([0, 0])
        visible.append(count(obs, ORANGE) > 0)
    assert visible == [True] * 6 + [False] * 3  # reset frame and steps 1-5
    old = int(core.coin_x[0, 0]), int(core.coin_y[0, 0])
    steps = walk_to(env, *old)
    obs, reward, terminated, info = steps[-1]
    assert reward == 0.25 and not terminated
    new = int(core.coin_x[0, 0]), int(core.coin_y[0, 0])
    np.testing.assert_allclose(info["ground_truth"], np.array([core.x[0], core.y[0], *new]) / 84)
    assert np.hypot(new[0] - old[0], new[1] - old[1]) > 20
    visible = [count(obs, ORANGE) > 0]
    for t in range(59):
        obs, _, terminated, _, info = env.step([0, 0])
        visible.append(count(obs, ORANGE) > 0)
        assert terminated == (t == 58)  # the clock reads 1 after the pickup step
    assert visible[:7] == [True] * 5 + [False] * 2  # frames t .. t+4 after the pickup
    assert info["coins_collected"] == 1


def test_endless_ground_truth_at_reset_can_exceed_one() -> None:
    env = make("Endless-SearingSpotlights-v0")
    values = [env.reset(seed=seed)[1]["ground_truth"] for seed in range(100)]
    assert all(v.dtype == np.float64 and v.shape == (4,) for v in values)
    assert max(v[:2].max() for v in values) > 78 / 84


def test_endless_show_last_action_false_works() -> None:
    """Quirk 22 fixed: the reference crashes; here the action blocks are simply not painted."""
    env = make("Endless-SearingSpotlights-v0")
    obs, _ = env.reset(seed=1, options={"show_last_action": False, "spot_damage": 0.0})
    assert hud_colour(obs, 60) == (0, 0, 0)  # the endless bar background
    for _ in range(3):
        obs, *_ = env.step([2, 2])
    assert hud_colour(obs, 60) == HUD_GREY and hud_colour(obs, 43) == HUD_GREY  # the wide reward block
    obs, *_ = make("Endless-SearingSpotlights-v0").reset(
        seed=1, options={"show_last_action": False, "show_last_positive_reward": False}
    )
    assert count(obs[:4, 42:], (0, 0, 0)) == 4 * 42


# ------------------------------------------------------------------------------------------ options
@pytest.mark.parametrize("env_id", IDS)
def test_floor_options_apply_to_one_episode_only(env_id: str) -> None:
    """Quirk 20 fixed: hide_chessboard and black_background do not leak into later episodes."""
    env = make(env_id)
    obs, _ = env.reset(seed=0)
    assert count(obs, (0, 0, 255)) > 1000
    obs, _ = env.reset(seed=0, options={"hide_chessboard": True})
    assert count(obs, (0, 0, 255)) == 0 and count(obs, (255, 255, 255)) > 4000
    obs, _ = env.reset(seed=0, options={"black_background": True})
    assert count(obs[4:], (0, 0, 0)) > 6000
    obs, _ = env.reset(seed=0)
    assert count(obs, (0, 0, 255)) > 1000


@pytest.mark.parametrize(
    ("env_id", "options", "message"),
    [
        ("SearingSpotlights-v0", {"light_treshold": 3}, "did you mean 'light_threshold'"),
        ("SearingSpotlights-v0", {"light_threshold": 300}, "'light_threshold'=300"),
        ("SearingSpotlights-v0", {"num_coins": 1}, "'num_coins'"),
        ("SearingSpotlights-v0", {"spot_min_radius": 14.0}, "'spot_min_radius'=14.0 is invalid"),
        ("SearingSpotlights-v0", {"spot_max_speed": 0.001}, "'spot_min_speed'"),
        ("SearingSpotlights-v0", {"agent_visible": 1}, "'agent_visible'=1"),
        ("Endless-SearingSpotlights-v0", {"num_coins": [1]}, "unknown option 'num_coins'"),
        ("Endless-SearingSpotlights-v0", {"spawn_interval": 0}, "'spawn_interval'=0"),
    ],
)
def test_bad_options_raise_value_errors_naming_the_key(env_id: str, options: dict, message: str) -> None:
    env = make(env_id)
    with pytest.raises(ValueError, match=message):
        env.reset(seed=0, options=options)
    with pytest.raises(ValueError, match=message):
        envs.make_core(env_id, options=options)


def test_draw_order_quirk_puts_some_visible_entities_above_the_hud() -> None:
    ss = [("coins", 1, False), ("exit", 2, False), ("agent", 3, False)]
    assert draw_order(ss) == ((), ())
    assert draw_order([("coins", 1, False), ("exit", 2, True), ("agent", 3, False)]) == ((), ("exit",))
    assert draw_order([("coins", 1, True), ("exit", 2, False), ("agent", 3, True)]) == (("coins",), ("agent",))
    assert draw_order([("coins", 1, True), ("exit", 2, True), ("agent", 3, True)]) == (("coins", "exit", "agent"), ())
    assert draw_order([("coins", 1, True), ("agent", 3, True)]) == (("coins",), ("agent",))  # endless: always


# ------------------------------------------------------------------------------------------ ablations
def dark_frame(env_id: str, options: dict, steps: int = 10) -> tuple[np.ndarray, SearingSpotlightsCore]:
    env = make(env_id)
    env.reset(seed=8, options={"spot_damage": 0.0, **options})
    for _ in range(steps):
        obs, *_ = env.step([0, 0])
    return obs, core_of(env)


@pytest.mark.parametrize("env_id", IDS)
def test_ablation_spotlights_off_leaves_only_the_hud(env_id: str) -> None:
    obs, core = dark_frame(env_id, no_spotlights(env_id), steps=60)
    assert core.spot_count[0] == 0 and not obs[4:].any()


@pytest.mark.parametrize("env_id", IDS)
def test_ablation_perfect_information_keeps_the_room_visible(env_id: str) -> None:
    obs, core = dark_frame(env_id, {"light_threshold": 0, **no_spotlights(env_id)})
    assert count(obs[4:], (213, 213, 213)) > 2000 and count(obs[4:], (0, 0, 213)) > 2000  # the floor at alpha 42
    body = tuple(int(c) for c in darken(np.array(AGENT_BODY, np.uint8), np.array(42)))
    assert count(obs, body) > 20  # the agent, darkened
    default, _ = dark_frame(env_id, no_spotlights(env_id))
    assert not default[4:].any()


@pytest.mark.parametrize("env_id", IDS)
def test_ablation_visible_agent_coin_and_exit(env_id: str) -> None:
    options = {"agent_visible": True, "coins_visible": True, **no_spotlights(env_id)}
    if env_id == "SearingSpotlights-v0":
        options["exit_visible"] = True
    obs, core = dark_frame(env_id, options)
    assert count(obs, AGENT_BODY) > 60 and count(obs, ORANGE) > 20
    if env_id == "SearingSpotlights-v0":
        assert count(obs, (55, 55, 55)) > 40


def test_ablation_black_floor_and_white_rings() -> None:
    obs, core = dark_frame("SearingSpotlights-v0", {"black_background": True}, steps=120)
    floor = obs[4:].reshape(-1, 3)
    assert count(obs[4:], (0, 0, 255)) == 0 and count(obs[4:], (255, 255, 255)) > 20  # the outlines
    assert set(map(tuple, np.unique(floor, axis=0).tolist())) <= {(0, 0, 0), (255, 255, 255), *_entity_colours()}


def _entity_colours() -> set[tuple[int, int, int]]:
    return {(250, 204, 153), (50, 50, 50), (255, 165, 0), (55, 55, 55), (48, 141, 70), (250, 250, 250)}


def test_ablation_hidden_chessboard_shows_a_white_floor_in_the_holes() -> None:
    obs, _ = dark_frame("SearingSpotlights-v0", {"hide_chessboard": True}, steps=120)
    assert count(obs[4:], (255, 255, 255)) > 100 and count(obs[4:], (0, 0, 255)) == 0


# ------------------------------------------------------------------------------------------ views
def test_debug_view_shows_every_entity_above_the_darkness() -> None:
    env = make("SearingSpotlights-v0", render_mode="debug_rgb_array")
    env.reset(seed=8, options={"spot_damage": 0.0, "initial_spawns": 0, "num_spawns": 0})
    for _ in range(10):
        obs, *_ = env.step([0, 0])
    debug = env.render()
    assert debug.shape == (336, 336, 3)
    small = debug[::4, ::4]
    np.testing.assert_array_equal(np.repeat(np.repeat(small, 4, 0), 4, 1), debug)
    assert not obs[4:].any()
    assert count(small, AGENT_BODY) > 60 and count(small, ORANGE) > 20 and count(small, (55, 55, 55)) > 40
    np.testing.assert_array_equal(small[:4], obs[:4])  # the same HUD
    assert env.metadata["render_fps"] == 25 and core_of(env).render_fps(0) == 25


# ------------------------------------------------------------------------------------------ batching
OPTIONS = {
    "SearingSpotlights-v0": [{}, {"light_threshold": 100}, {"black_background": True}, {"agent_visible": True}],
    "Endless-SearingSpotlights-v0": [{}, {"coins_visible": True}, {"hide_chessboard": True}, {"spot_damage": 3.0}],
}


@pytest.mark.parametrize("env_id", IDS)
def test_batched_slots_equal_single_environments(env_id: str) -> None:
    """A 6-slot core (all slots at once, or a few at a time) equals six 1-slot cores, frames and debug views."""
    _, episodes = check_batched_equals_singles(env_id, OPTIONS[env_id], 250, lambda rng, _: rng.integers(0, 3, (6, 2)))
    assert episodes >= 4


@pytest.mark.parametrize("env_id", IDS)
def test_vector_env_matches_single_envs(env_id: str) -> None:
    """gymnasium.make_vec (next-step autoreset, generators continued) equals single envs reset without a seed."""
    resets = check_vector_env_matches_singles(
        env_id, {"max_steps": 30}, 80, lambda rng, _: rng.integers(0, 3, size=(3, 2))
    )
    assert resets >= 3


@pytest.mark.parametrize("env_id", IDS)
def test_observations_hand_over_the_frames_and_the_core_draws_them_again(env_id: str) -> None:
    """``observations()`` hands its frame buffer to the caller: writing into it changes nothing in the core, and
    frames read before they are drawn again (partial steps, resets, other reads) are drawn from the state; a core
    that only hands out gathered copies sees the same frames."""
    lender, copier = (envs.make_core(env_id, num_envs=4, options={"light_dim_off_duration": 3}) for _ in range(2))
    for core in (lender, copier):
        core.reset_slots(range(4), [7, 8, 9, 10])
    everyone = np.arange(4)
    rng = np.random.default_rng(5)
    for t in range(60):
        actions = rng.integers(0, 3, (4, 2))
        idx = None if t % 3 else np.sort(rng.permutation(4)[: rng.integers(1, 4)])
        for core in (lender, copier):
            _, terminated, _ = core.step(actions if idx is None else actions[idx], idx=idx)
            if t % 7 == 0:
                core.reset_slots([t % 4])
        lent = lender.observations()
        expected = copier.observations(everyone)
        np.testing.assert_array_equal(lent, expected)
        assert not np.shares_memory(lent, lender.observations())  # a second read: drawn again, not the same buffer
        lent[:] = 99  # the caller owns it
        np.testing.assert_array_equal(lender.agent_frame(t % 4), expected[t % 4])


@pytest.mark.parametrize("options", [{}, {"agent_visible": True, "light_dim_off_duration": 0}])
def test_pictures_under_the_darkness_updated_one_by_one_equal_those_updated_in_a_batch(options: dict) -> None:
    """``_update_under`` has a batched path and a one-by-one path for a few changed slots: both give the same
    pictures and frames (moving agents, red floors on hits, new levels)."""
    batched, one_by_one = (SearingSpotlightsCore(num_envs=8, options=options) for _ in range(2))
    batched.FEW_UNDER_UPDATES, one_by_one.FEW_UNDER_UPDATES = 0, 10**9
    for core in (batched, one_by_one):
        core.reset_slots(range(8), list(range(100, 108)))
    rng = np.random.default_rng(11)
    hits = resets = 0
    for _ in range(200):
        actions = rng.integers(0, 3, (8, 2)) * (rng.random((8, 1)) < 0.5)  # some agents stand still
        for core in (batched, one_by_one):
            _, terminated, _ = core.step(actions)
            done = np.flatnonzero(terminated)
            core.reset_slots(done, (1000 + done + 8 * resets).tolist())
        resets += int(done.size > 0)
        hits += int(np.count_nonzero(batched.hit))
        np.testing.assert_array_equal(batched.under, one_by_one.under)
        np.testing.assert_array_equal(batched.observations(), one_by_one.observations())
    assert hits > 20 and resets > 0


def test_endless_first_coin_can_spawn_within_reach_of_the_agent() -> None:
    """Quirk 19 (kept): the sampler is cleared before the first coin, so it may land on the agent."""
    env = make("Endless-SearingSpotlights-v0")
    core = core_of(env)
    close = []
    for seed in range(150):
        env.reset(seed=seed, options={"spot_damage": 0.0})
        distance = np.hypot(core.x[0] - core.coin_x[0, 0], core.y[0] - core.coin_y[0, 0])
        if distance <= 9:
            _, reward, *_ = env.step([0, 0])
            close.append((seed, reward))
    assert close and all(reward == 0.25 for _, reward in close)


def test_hole_masks_of_many_overlapping_spotlights_are_the_union_of_their_discs() -> None:
    """Rows crossed by many spotlights (several lost spans per row, OR-ed in over several layers)."""
    from envs.drawing import disc_mask

    core = SearingSpotlightsCore(num_envs=2)
    core.reset_slots([0, 1], [3, 4], {"initial_spawns": 40, "spot_damage": 0.0})
    for _ in range(50):
        core.step(np.zeros((2, 2), np.int64))
    spots = core.spots
    out = np.empty((2, SCREEN, SCREEN * 3), np.uint8)
    core._hole_masks(out, spots["centre"], spots["base"], spots["drawn"])
    margin = 64
    for k in range(2):
        pixels = np.zeros((SCREEN + 2 * margin, SCREEN + 2 * margin), bool)
        for j in np.flatnonzero(spots["drawn"][k]):
            disc, offset = disc_mask(int(spots["radius"][k, j]))
            centre = spots["centre"][k, j]
            top, left = int(centre.imag) + offset + margin, int(centre.real) + offset + margin
            pixels[top : top + disc.shape[0], left : left + disc.shape[1]] |= disc
        expected = np.repeat(pixels[margin:-margin, margin:-margin], 3, axis=1).astype(np.uint8) * 255
        assert (out[k, 4:] == expected[4:]).all()
