"""Exact mechanics of the Mortar Mayhem family (spec §3, §4, §10, §11), checked with oracle agents that read our core's
state (target tile, agent position, clue stream), the way the reference checks read the reference's members."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import envs
from envs.mortar_mayhem import (
    MortarMayhemCore,
    agent_sheet,
    arena_picture,
    command_walk,
    spawn_frames,
    walk_commands,
)
from envs.rng import BoundedDraws, seeded_generator
from tests.support.batching import check_batched_equals_singles

MM, MM_GRID, MMB, MMB_GRID, EMM = (
    "MortarMayhem-v0",
    "MortarMayhem-Grid-v0",
    "MortarMayhemB-v0",
    "MortarMayhemB-Grid-v0",
    "Endless-MortarMayhem-v0",
)
FINITE = [MM, MM_GRID, MMB, MMB_GRID]
RED, RED_BORDER = (81, 18, 26), (112, 24, 36)
BLUE, BLUE_BORDER = (21, 43, 77), (29, 60, 107)


# -------------------------------------------------------------------------------------------------- helpers
def make(env_id: str, **kwargs) -> tuple[gym.Env, MortarMayhemCore]:
    env = gym.make(env_id, disable_env_checker=True, **kwargs)
    return env, env.unwrapped.core


def image(obs) -> np.ndarray:
    return obs["visual_observation"] if isinstance(obs, dict) else obs


def oracle(core: MortarMayhemCore, miss: bool = False):
    """Walk to the current target tile (or, with ``miss``, to a tile two columns away)."""
    if core.clue_left[0] > 0:
        return 0 if core.grid else [0, 0]
    tx, ty = int(core.target_x[0]), int(core.target_y[0])
    size = int(core.size[0])
    if miss:
        tx = (tx + 2) % size
    left = int(core.left[0])
    if core.grid:
        x, y = (int(core.x[0]) - left) // 14, (int(core.y[0]) - left) // 14
        if (x, y) == (tx, ty):
            return 0
        want = 270 if tx > x else 90 if tx < x else 180 if ty > y else 0
        heading = int(core.heading[0])
        if heading == want:
            return 3
        return 1 if (want - heading) % 360 in (90, 180) else 2
    cx, cy = left + 14 * tx + 7, left + 14 * ty + 7
    ax, ay = int(core.x[0]), int(core.y[0])
    return [0 if abs(cx - ax) <= 2 else (1 if cx < ax else 2), 0 if abs(cy - ay) <= 2 else (1 if cy < ay else 2)]


def play(env: gym.Env, core: MortarMayhemCore, seed: int, options=None, policy=None, limit: int = 3000):
    """One episode; ``policy(core, t)`` gives the action of step t (default: the oracle). Returns per-step records."""
    policy = policy or (lambda c, t: oracle(c))
    obs, info = env.reset(seed=seed, options=options)
    target = (int(core.target_x[0]), int(core.target_y[0]))
    steps = [dict(t=0, obs=obs, info=info, reward=0.0, terminated=False, target=target)]
    for t in range(1, limit + 1):
        target = (int(core.target_x[0]), int(core.target_y[0]))  # the target a check at this step looks at
        obs, reward, terminated, truncated, info = env.step(policy(core, t))
        assert truncated is False
        steps.append(dict(t=t, obs=obs, info=info, reward=reward, terminated=terminated, target=target))
        steps[-1]["fps"] = core.render_fps(0)
        if terminated:
            break
    return steps


def tile_colours(step: dict, core: MortarMayhemCore) -> tuple[set, tuple]:
    """(fill colours of all non-target tiles, fill colour of the target tile) in a recorded step's observation."""
    img = image(step["obs"])
    left, size = int(core.left[0]), int(core.size[0])
    sprite = {(250, 204, 153), (50, 50, 50), (255, 255, 255)}  # agent body and hands, icon strokes

    def fill(i: int, j: int) -> tuple:
        inner = img[left + 14 * j + 1 : left + 14 * j + 13, left + 14 * i + 1 : left + 14 * i + 13].reshape(-1, 3)
        colours = {tuple(int(v) for v in px) for px in inner} - sprite
        assert len(colours) == 1, f"tile ({i}, {j}) has several fill colours {colours}"
        return colours.pop()

    tx, ty = step["target"]
    return {fill(i, j) for i in range(size) for j in range(size) if (i, j) != (tx, ty)}, fill(tx, ty)


# Spec §3.6: t0, first check, check spacing (D + E), episode length of a perfect agent, and E, with the defaults.
TIMELINE = {
    MM: (40, 58, 24, 274, 6),
    MMB: (1, 19, 24, 235, 6),
    MM_GRID: (40, 46, 8, 118, 2),
    MMB_GRID: (1, 7, 8, 79, 2),
}


def inward_turn(core: MortarMayhemCore) -> int:
    """The grid turn (1 left, 2 right) after which moving forward stays inside the arena."""
    heading, size = int(core.heading[0]), int(core.size[0])
    x, y = (int(core.x[0]) - int(core.left[0])) // 14, (int(core.y[0]) - int(core.left[0])) // 14
    forward = {0: (0, -1), 90: (-1, 0), 180: (0, 1), 270: (1, 0)}
    dx, dy = forward[(heading + 90) % 360]
    return 1 if 0 <= x + dx < size and 0 <= y + dy < size else 2


# ------------------------------------------------------------------------------------------------ timeline
@pytest.mark.parametrize("env_id", FINITE)
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_timeline_with_oracle(env_id: str, seed: int) -> None:
    t0, first, spacing, length, lethal = TIMELINE[env_id]
    env, core = make(env_id)
    steps = play(env, core, seed)
    checks = [first + spacing * k for k in range(10)]
    assert [s["t"] for s in steps if s["reward"] != 0] == checks
    assert all(s["reward"] == pytest.approx(0.1) for s in steps if s["reward"] != 0)
    assert len(steps) - 1 == length == checks[-1]
    final = steps[-1]["info"]
    assert set(final) == {"reward", "length", "success", "commands_completed", "checks_passed", "command_count"}
    assert final["length"] == length and final["success"] == 1 and final["commands_completed"] == 1.0
    assert final["checks_passed"] == final["command_count"] == 10
    assert final["reward"] == pytest.approx(1.0)
    assert all(s["info"] == {} for s in steps[:-1])
    # the clue phase lasts t0 - 1 steps after the reset frame; the act phase starts at t0
    assert [s["t"] for s in steps if s["t"] > 0 and s["fps"] == 3] == list(range(1, t0 - 1))
    for v in checks[:-1]:
        others, target = tile_colours(steps[v], core)
        assert others == {RED} and target == BLUE, f"step {v}: every tile but the target is lethal"
        assert tile_colours(steps[v + lethal - 1], core)[0] == {RED}
        assert tile_colours(steps[v + lethal], core)[0] == {BLUE}, "released after E steps"
    env.close()


@pytest.mark.parametrize("env_id", FINITE)
def test_missing_the_first_check_ends_the_episode_there(env_id: str) -> None:
    env, core = make(env_id)
    steps = play(env, core, 3, policy=lambda c, t: oracle(c, miss=True))
    assert len(steps) - 1 == TIMELINE[env_id][1]
    assert steps[-1]["info"] == {
        "reward": 0.0,
        "length": TIMELINE[env_id][1],
        "success": 0,
        "commands_completed": 0.0,
        "checks_passed": 0,
        "command_count": 10,
    }


@pytest.mark.parametrize("env_id", [MM, MMB_GRID])
def test_custom_timing_options(env_id: str) -> None:
    env, core = make(env_id)
    options = {"command_count": [4], "explosion_delay": [5], "explosion_duration": [3]}
    if env_id == MM:
        options |= {"command_show_duration": [2], "command_show_delay": [0]}
    steps = play(env, core, 4, options)
    t0 = 8 if env_id == MM else 1  # 4 commands x (2 + 0) frames
    assert [s["t"] for s in steps if s["reward"] != 0] == [t0 + 5 + 8 * k for k in range(4)]


@pytest.mark.parametrize("env_id", FINITE)
@pytest.mark.parametrize("custom", [False, True])
def test_max_episode_steps_bounds_the_perfect_episode(env_id: str, custom: bool) -> None:
    """memory-gym's ``max_episode_steps`` (C + n(D + E) - E + 1) is the length of a perfect episode, one step more
    with a clue stream (reset shows its first frame); list options count with their largest value."""
    env, core = make(env_id)
    options = {"command_count": [3], "explosion_delay": [5], "explosion_duration": [3]} if custom else {}
    if custom and env_id in (MM, MM_GRID):
        options |= {"command_show_duration": [2], "command_show_delay": [0]}
    steps = play(env, core, 4, options)
    assert steps[-1]["info"]["success"] == 1
    longest = TIMELINE[env_id][3] if not custom else (6 if env_id in (MM, MM_GRID) else 1) + 5 + 8 * 2
    assert len(steps) - 1 == longest
    assert env.unwrapped.max_episode_steps == longest + (1 if env_id in (MM, MM_GRID) else 0)
    if custom:  # several values: the figure bounds the episodes of the largest ones
        smaller = {"command_count": 1, "explosion_delay": 2, "explosion_duration": 1, "command_show_duration": 1}
        lists = {key: [smaller.get(key, 0), *value] for key, value in options.items()}
        lengths = [len(play(env, core, seed, lists)) - 1 for seed in range(6)]
        assert env.unwrapped.max_episode_steps == longest + (1 if env_id in (MM, MM_GRID) else 0)
        assert max(lengths) <= longest and min(lengths) < longest
    env.close()


# --------------------------------------------------------------------------------------- rewards and quirks
@pytest.mark.parametrize("env_id", FINITE)
def test_failed_last_check_counts_as_success(env_id: str) -> None:
    """Quirk §3.7/§11.2: the all-done test ignores the outcome of the last check."""
    env, core = make(env_id)
    options = {"reward_episode_success": 1.0, "reward_command_failure": -1.0}
    steps = play(env, core, 0, options, policy=lambda c, t: oracle(c, miss=c.current[0] == 9 and not c.tiles_on[0]))
    final = steps[-1]["info"]
    assert final["length"] == TIMELINE[env_id][3]
    assert final["success"] == 1 and final["commands_completed"] == 1.0
    assert final["checks_passed"] == 9 and final["command_count"] == 10  # what the agent actually did
    # the failure reward is assigned last that step, so the episode bonus is lost
    assert steps[-1]["reward"] == -1.0 and final["reward"] == pytest.approx(0.9 - 1.0)


@pytest.mark.parametrize("env_id", FINITE)
def test_lethal_phase_death_undercounts(env_id: str) -> None:
    """Quirk §3.7/§11.3: pass check 3, then leave the tile while it is lethal: 3 checks paid, 2/10 reported."""
    env, core = make(env_id)
    _, first, spacing, _, lethal = TIMELINE[env_id]
    third = first + 2 * spacing

    def policy(c: MortarMayhemCore, t: int):
        if c.grid and t == third:
            return inward_turn(c)  # turning keeps the tile, so the check passes
        if t > third:
            return 3 if c.grid else oracle(c, miss=True)  # walk off while the tiles are lethal
        return oracle(c)

    steps = play(env, core, 2, policy=policy)
    final = steps[-1]["info"]
    assert third < final["length"] < third + lethal
    assert final["reward"] == pytest.approx(0.3) and final["success"] == 0
    assert final["commands_completed"] == pytest.approx(0.2)
    assert final["checks_passed"] == 3 and final["command_count"] == 10  # what the agent actually did
    assert steps[-1]["reward"] == 0.0


@pytest.mark.parametrize("env_id", FINITE)
@pytest.mark.parametrize("count", [1, 3])
def test_checks_passed_and_command_count(env_id: str, count: int) -> None:
    """The added keys: the checks actually passed (last check failed / death in the lethal phase / all passed) and
    the episode's command count, beside the reference's quirky ``success`` and ``commands_completed``."""
    env, core = make(env_id)
    options = {"command_count": [count]}
    steps = play(env, core, 5, options)  # all checks passed
    assert steps[-1]["info"]["checks_passed"] == steps[-1]["info"]["command_count"] == count
    last = count - 1
    steps = play(env, core, 5, options, policy=lambda c, t: oracle(c, miss=c.current[0] == last and not c.tiles_on[0]))
    final = steps[-1]["info"]
    assert (final["success"], final["commands_completed"]) == (1, 1.0)  # the reference's quirk, kept
    assert (final["checks_passed"], final["command_count"]) == (last, count)
    if count > 1:
        final = play(env, core, 5, options, policy=leave_after_first_check)[-1]["info"]
        assert final["commands_completed"] == 0.0 and final["success"] == 0  # the reference undercounts
        assert final["reward"] == pytest.approx(0.1)
        assert (final["checks_passed"], final["command_count"]) == (1, count)


def leave_after_first_check(c: MortarMayhemCore, t: int):
    """Pass the first check, then leave the tile while the other tiles are lethal."""
    if c.current[0] == 0 and c.timer[0] == 0 and not c.tiles_on[0] and c.clue_left[0] == 0:  # the first check
        return inward_turn(c) if c.grid else oracle(c)  # (turning keeps the tile)
    if c.current[0] >= 1:
        return 3 if c.grid else oracle(c, miss=True)
    return oracle(c)


def test_endless_checks_passed_after_a_death_in_the_lethal_phase() -> None:
    env, core = make(EMM)
    final = play(env, core, 1, policy=lambda c, t: oracle(c, miss=t > 22))[-1]["info"]  # pass the check at 22
    assert final["length"] < 22 + 6 + 4 and final["reward"] == pytest.approx(0.1)
    assert final["checks_passed"] == final["commands_completed"] == 1
    assert "command_count" not in final


def test_added_info_keys_are_declared_for_the_parity_tools() -> None:
    assert MortarMayhemCore.added_info_keys == {"checks_passed", "command_count"}
    assert envs.make_core("MysteryPath-v0").added_info_keys == frozenset()


@pytest.mark.parametrize("env_id", [MM, MMB_GRID])
def test_reward_options(env_id: str) -> None:
    env, core = make(env_id)
    options = {"reward_command_success": 0.5, "reward_episode_success": 2.0, "command_count": [3]}
    steps = play(env, core, 1, options)
    assert [s["reward"] for s in steps if s["reward"]] == [0.5, 0.5, 2.5]
    steps = play(env, core, 1, {"reward_command_failure": -0.25}, policy=lambda c, t: oracle(c, miss=True))
    assert steps[-1]["reward"] == -0.25 and steps[-1]["info"]["reward"] == -0.25


def test_visual_feedback_off_keeps_tiles_blue() -> None:
    env, core = make(MMB)
    steps = play(env, core, 0, {"visual_feedback": False})
    checks = [s["t"] for s in steps if s["reward"] != 0]
    assert len(checks) == 10
    assert all(tile_colours(steps[t + 1], core)[0] == {BLUE} for t in checks[:-1])  # lethal, yet blue


def test_release_step_is_not_checked() -> None:
    """At V + E the tiles turn blue without a position check: the agent may already be leaving."""
    env, core = make(MMB_GRID)
    release = 7 + 2
    tiles = []

    def policy(c: MortarMayhemCore, t: int):
        tiles.append((int(c.x[0]), int(c.y[0])))
        if t == release - 1:
            return inward_turn(c)  # still lethal: turning keeps the tile
        return 3 if t == release else oracle(c)

    steps = play(env, core, 0, policy=policy)
    assert tiles[release] != tiles[release - 1], "the agent left its tile on the release step"
    assert steps[-1]["info"]["success"] == 1 and steps[-1]["info"]["length"] == 79


# ---------------------------------------------------------------------------------------------------- endless
def test_endless_round_timing() -> None:
    env, core = make(EMM)
    steps = play(env, core, 0, {"max_steps": 200})
    checks = [s["t"] for s in steps if s["reward"] != 0]
    assert checks == [22, 50, 74, 102, 126, 150, 178]
    # the stream of a new command is shown at V+1..V+4 (icon, icon, icon, blank); the window slows to 3 fps while
    # stream frames are still to come, i.e. from the step that queues them (V, or the reset) to the last but one
    icons = [s["t"] for s in steps if _icon_shown(s["obs"])]
    assert icons == [0, 1, 2, 23, 24, 25, 75, 76, 77, 151, 152, 153]
    slow = [s["t"] for s in steps if s["t"] > 0 and s["fps"] == 3]
    assert slow == [1, 2, 22, 23, 24, 25, 74, 75, 76, 77, 150, 151, 152, 153]
    for v in (22, 74, 150):  # during the stream after a round's last check the tiles stay red
        for t in range(v, v + 5):
            assert tile_colours(steps[t], core)[0] == {RED}, t
    final = steps[-1]["info"]
    assert len(steps) - 1 == 200 and steps[-1]["terminated"]
    assert set(final) == {
        "ground_truth",
        "reward",
        "length",
        "commands_completed",
        "max_command_sequence",
        "checks_passed",
    }
    assert final["commands_completed"] == final["checks_passed"] == 7 and final["max_command_sequence"] == 3
    assert final["reward"] == pytest.approx(0.7)


def _icon_shown(obs: np.ndarray) -> bool:
    return bool((obs[31:56, 31:56] == 255).all(axis=-1).any())


def test_endless_ground_truth_every_step() -> None:
    env, core = make(EMM)
    obs, info = env.reset(seed=5)
    assert env.unwrapped.has_ground_truth_info and env.unwrapped.ground_truth_space.shape == (2,)
    for _ in range(120):
        expected = np.array([core.target_x[0], core.target_y[0]]) / 5.0
        assert info["ground_truth"].dtype == np.float64 and np.array_equal(info["ground_truth"], expected)
        assert env.unwrapped.ground_truth_space.contains(info["ground_truth"].astype(np.float32))
        obs, reward, terminated, _, info = env.step(oracle(core))
    assert not terminated


@pytest.mark.parametrize(
    ("fail_after", "length", "max_sequence"),
    [(0, 22, 1), (1, 50, 1), (2, 74, 2)],  # fail the first check / the first of round 2 / the last of round 2
)
def test_endless_max_command_sequence_quirk(fail_after: int, length: int, max_sequence: int) -> None:
    """Quirk §4/§11.6: the new command is appended before the outcome counts, even when the last check failed."""
    env, core = make(EMM)
    steps = play(
        env, core, 1, policy=lambda c, t: oracle(c, miss=c.completed_total[0] == fail_after and not c.tiles_on[0])
    )
    final = steps[-1]["info"]
    assert final["length"] == length and final["commands_completed"] == final["checks_passed"] == fail_after
    assert final["max_command_sequence"] == max_sequence


def test_endless_wraps_around_the_torus() -> None:
    env, core = make(EMM)
    env.reset(seed=0)
    core.clue_left[0] = 0  # skip the stream to walk right away
    xs = []
    for _ in range(40):
        env.step([2, 0])
        xs.append(int(core.x[0]))
    assert max(xs) == 87 and -3 in xs, "the centre goes 3 px past the edge, then jumps to the other side"
    jump = xs.index(-3)
    assert xs[jump - 1] >= 85


# ---------------------------------------------------------------------------------------------- observations
@pytest.mark.parametrize("env_id", [MMB, MMB_GRID])
def test_vector_observation_layout(env_id: str) -> None:
    slot = {"stay": 0, "right": 1, "left": 2, "up": 3, "down": 4}
    slot |= {"right_down": 5, "right_up": 6, "left_down": 7, "left_up": 8}
    names = ["right", "down", "left", "up", "stay", "right_down", "right_up", "left_down", "left_up"]
    env, core = make(env_id)
    assert env.observation_space["vector_observation"].shape == (180,)
    for seed, count in [(0, 10), (1, 20), (2, 3)]:
        obs, _ = env.reset(seed=seed, options={"command_count": [count], "allowed_commands": 9})
        vector = obs["vector_observation"]
        assert vector.dtype == np.float32 and vector.shape == (180,)
        expected = np.zeros(180, dtype=np.float32)
        for c in range(count):
            expected[9 * c + slot[names[core.commands[0, c]]]] = 1.0
        assert np.array_equal(vector, expected)
        assert vector.reshape(20, 9)[count:].sum() == 0
        for _ in range(5):
            obs, *_ = env.step(env.action_space.sample())
            assert np.array_equal(obs["vector_observation"], expected), "constant over the episode"


def test_arena_geometry_and_colours() -> None:
    env, core = make(MM)
    obs, _ = env.reset(seed=0)
    assert (obs[:7] == 0).all() and (obs[:, :7] == 0).all() and (obs[77:] == 0).all() and (obs[:, 77:] == 0).all()
    assert tuple(obs[7, 7]) == BLUE_BORDER and tuple(obs[8, 8]) == BLUE and tuple(obs[20, 8]) == BLUE_BORDER
    obs, _ = env.reset(seed=0, options={"arena_size": 3})
    assert (obs[:21] == 0).all() and tuple(obs[21, 21]) == BLUE_BORDER and (obs[63:] == 0).all()
    for seed in range(20):
        env.reset(seed=seed)
        assert (int(core.x[0]) - 7) % 14 == 7 and (int(core.y[0]) - 7) % 14 == 7, "MM spawns on a tile centre"
    jitter = set()
    env, core = make(MMB)
    for seed in range(40):
        env.reset(seed=seed)
        jitter |= {(int(core.x[0]) - 7) % 14 - 7, (int(core.y[0]) - 7) % 14 - 7}
    assert jitter == {-2, -1, 0, 1}, "MMB adds a {-2..1} px offset"


def test_clue_phase_ignores_actions_and_shows_icons() -> None:
    env, core = make(MM_GRID)
    still, _ = env.reset(seed=0)
    for _ in range(10):
        obs, reward, *_ = env.step(3)  # "forward" is ignored while commands are shown
        assert reward == 0 and core.heading[0] == 0
    env.reset(seed=0)
    frames = [env.step(0)[0] for _ in range(10)]
    assert np.array_equal(obs, frames[-1])
    assert [_icon_shown(f) for f in [still, *frames]] == [True, True, True, False] * 2 + [True, True, True]


# Spec §3.3: the right arrow and the stay sign as they appear on screen (top-left pixel at (31, 31)).
RIGHT = """
..........##..........
...........##.........
............##........
.............##.......
..............##......
...............##.....
................##....
.................##...
..................##..
...................##.
######################
#####################.
..................##..
.................##...
................##....
...............##.....
..............##......
.............##.......
............##........
...........##.........
..........##..........
"""
STAY = """
.......######.......
.....##########.....
....####....####....
...###........###...
..##............##..
.###............###.
.##..............##.
###..............###
##................##
####################
####################
##................##
###..............###
.##..............##.
.###............###.
..##............##..
...###........###...
....####....####....
.....##########.....
.......######.......
"""


@pytest.mark.parametrize(("command", "art"), [(0, RIGHT), (4, STAY)])
def test_icon_pixels(command: int, art: str) -> None:
    env, core = make(MM)
    for seed in range(200):
        obs, _ = env.reset(seed=seed, options={"command_count": [1], "allowed_commands": 9})
        if core.commands[0, 0] == command:
            break
    rows = art.strip().splitlines()
    expected = np.array([[ch == "#" for ch in row] for row in rows])
    white = (obs == 255).all(axis=-1)
    assert np.array_equal(white[31 : 31 + len(rows), 31 : 31 + len(rows[0])], expected)
    assert white.sum() == expected.sum()


def test_diagonal_icons_sit_off_centre() -> None:
    """Quirk §3.3/§11.5: rotated canvases grow to 31 px but keep the corner at (31, 31)."""
    env, core = make(MM)
    centres = {}
    for seed in range(300):
        obs, _ = env.reset(seed=seed, options={"command_count": [1], "allowed_commands": 9})
        rows, cols = np.nonzero((obs == 255).all(axis=-1))
        centres[int(core.commands[0, 0])] = ((rows.min() + rows.max()) / 2, (cols.min() + cols.max()) / 2)
    assert len(centres) == 9
    for command, (row, col) in centres.items():
        if command >= 5:  # diagonals
            assert 45 <= row <= 47 and 45 <= col <= 47
        else:
            assert 40 <= row <= 42 and 40 <= col <= 42


def test_debug_view_and_render_fps() -> None:
    env, core = make(MM, render_mode="debug_rgb_array")
    env.reset(seed=0)
    picture = env.render()
    assert picture.shape == (336, 336, 3) and core.render_fps(0) == 3
    centre = 4 * (int(core.left[0]) + 14 * np.array([int(core.target_y[0]), int(core.target_x[0])]) + 7)
    green = (picture == (0, 255, 0)).all(axis=-1)
    rows, cols = np.nonzero(green)
    assert green.any() and abs(rows.mean() - centre[0]) < 4 and abs(cols.mean() - centre[1]) < 4
    assert (picture[124:216, 124:216] == 255).all(axis=-1).any(), "the icon shows in the debug view"
    for _ in range(39):
        env.step([0, 0])
    assert core.render_fps(0) == 25
    assert {make(i)[1].base_render_fps for i in (MM_GRID, MMB_GRID)} == {6} and make(MMB)[1].base_render_fps == 25


# --------------------------------------------------------------------------------------------------- options
@pytest.mark.parametrize(
    ("env_id", "options", "words"),
    [
        (MM, {"arena_size": 7}, ["'arena_size'", "[2, 6]"]),
        (MM_GRID, {"allowed_commands": 3}, ["'allowed_commands'", "[4, 9]"]),
        (MMB, {"command_count": [21]}, ["'command_count'", "[1, 20]"]),
        (MM, {"explosion_delay": [0]}, ["'explosion_delay'"]),
        (MM, {"command_count": 10}, ["'command_count'", "list"]),
        (MM, {"arena_sise": 5}, ["'arena_sise'", "did you mean 'arena_size'", "allowed_commands"]),
        (MM_GRID, {"agent_speed": 3.0}, ["'agent_speed'", "valid options"]),
        (EMM, {"arena_size": 5}, ["'arena_size'", "initial_command_count"]),
    ],
)
def test_option_errors(env_id: str, options: dict, words: list[str]) -> None:
    env, _ = make(env_id)
    with pytest.raises(ValueError) as err:
        env.reset(seed=0, options=options)
    for word in words:
        assert word in str(err.value)


def test_random_play_statistics_match_the_reference() -> None:
    """Spec §10: 50 episodes, seeds 1000-1049, ``action_space.seed(123)``; the reference's numbers, exactly."""
    reference = {
        MM: (58, 58.72, 82, 0.012, 0.002),
        MM_GRID: (46, 47.52, 62, 0.026, 0.018),
        MMB: (19, 21.24, 44, 0.020, 0.008),
        MMB_GRID: (7, 8.94, 23, 0.026, 0.024),
        EMM: (22, 24.5, 74, 0.014, 0.14),
    }
    for env_id, expected in reference.items():
        env = gym.make(env_id, disable_env_checker=True)
        env.action_space.seed(123)
        lengths, returns, completed = [], [], []
        for episode in range(50):
            env.reset(seed=1000 + episode)
            terminated = False
            while not terminated:
                _, _, terminated, _, info = env.step(env.action_space.sample())
            lengths.append(info["length"])
            returns.append(info["reward"])
            completed.append(info["commands_completed"])
        got = (min(lengths), np.mean(lengths), max(lengths), np.mean(returns), np.mean(completed))
        assert got == pytest.approx(expected, abs=1e-9), env_id


# ------------------------------------------------------------------------------------------------- batching
BATCH_OPTIONS = {
    MM: [
        {},
        {"command_count": [2, 5, 9], "command_show_duration": [1, 3], "command_show_delay": [0, 2]},
        {"agent_scale": 0.3, "visual_feedback": False},
        {"arena_size": 3, "explosion_delay": [4, 7], "explosion_duration": [1, 3]},
    ],
    MM_GRID: [{}, {"command_count": [1, 4], "arena_size": 2, "allowed_commands": 9, "explosion_delay": [3, 5]}],
    MMB: [{}, {"command_count": [3, 20]}, {"agent_scale": 0.5}],
    MMB_GRID: [{}],  # all six slots reset in one call at the start (the windowed sprite paste)
    EMM: [{}, {"initial_command_count": 2, "max_steps": 150}, {"agent_scale": 0.2}],
}


def oracle_or_random(rng: np.random.Generator, cores: list[MortarMayhemCore]) -> np.ndarray:
    """Mostly the oracle (so that checks pass and rounds go on), sometimes a random action (so that episodes end)."""
    space = cores[0].single_action_space
    high = space.nvec if isinstance(space, gym.spaces.MultiDiscrete) else space.n
    actions = [oracle(core) if rng.random() < 0.95 else rng.integers(0, high) for core in cores]
    return np.array(actions, dtype=np.int64)


@pytest.mark.parametrize("env_id", [*FINITE, EMM])
def test_batched_slots_equal_single_environments(env_id: str) -> None:
    """A 6-slot core (all slots at once, or a few at a time; finished slots reset together) equals six 1-slot cores,
    frames and debug views, with option sets that vary the command counts, timings and agent scales per slot."""
    longest = [0]

    def choose(rng: np.random.Generator, cores: list[MortarMayhemCore]) -> np.ndarray:
        longest[0] = max(longest[0], *(int(core.num_commands[0]) for core in cores))
        return oracle_or_random(rng, cores)

    _, episodes = check_batched_equals_singles(env_id, BATCH_OPTIONS[env_id], 400, choose)
    assert episodes >= 6
    if env_id == EMM:
        assert longest[0] > 3, longest  # rounds went on, so commands were appended during the steps


def test_reset_slots_with_a_repeated_slot_keeps_its_last_level() -> None:
    together, one_by_one = envs.make_core(MMB_GRID, num_envs=3), envs.make_core(MMB_GRID, num_envs=3)
    together.reset_slots([0, 2, 1, 2], [5, 6, 7, 8])
    for k, seed in [(0, 5), (2, 6), (1, 7), (2, 8)]:
        one_by_one.reset_slot(k, seed)
    np.testing.assert_array_equal(together.frames, one_by_one.frames)
    np.testing.assert_array_equal(together.vector, one_by_one.vector)
    np.testing.assert_array_equal(together.target, one_by_one.target)


def test_spawn_frames_equal_a_fresh_drawing_also_after_the_store_starts_over(monkeypatch) -> None:
    """Reset frames are copies of stored spawn frames; a store kept small starts over and still draws them right."""
    store = spawn_frames()
    monkeypatch.setattr(store, "LIMIT", 8)
    core = envs.make_core(MMB, num_envs=6)
    for seed in range(0, 120, 6):
        scale = 0.3 if seed % 12 else 0.25
        core.reset_slots(range(6), range(seed, seed + 6), {"agent_scale": scale, "arena_size": 4})
        assert len(store.index) <= 8 + 6
        for k in range(6):
            expected = arena_picture(4)
            agent_sheet(scale).paste_one(expected.reshape(84, 84 * 3), int(core.y[k]), int(core.x[k]), 0)
            np.testing.assert_array_equal(core.frames[k], expected)


@pytest.mark.parametrize(("size", "allowed"), [(2, 4), (3, 5), (5, 9)])
def test_walk_commands_inline_draws_equal_bounded_draws(size: int, allowed: int) -> None:
    """The walk's inline Lemire step equals BoundedDraws.below, also for words it hands over: 0 (rejected for
    n = 3, 5, ...: numpy draws again) and 1 (low bits == n: accepted at once)."""
    walk, count = command_walk(size, allowed), 12
    draws = []
    for _ in range(2):
        d = BoundedDraws(seeded_generator(7), reserve=count, fresh=True)
        d.words[2], d.words[3], d.words[7] = 0, 1, 0
        draws.append(d)
    fast, slow = draws
    walked = walk_commands(fast, walk, 0, count)
    expected, tile = [], 0
    for _ in range(count):
        command, tile = walk[tile][slow.below(len(walk[tile]))]
        expected.append(command)
    assert walked == expected
    assert fast.words == slow.words and fast.used == slow.used
    fast.close()
    slow.close()
    assert fast.rng.bit_generator.state == slow.rng.bit_generator.state
