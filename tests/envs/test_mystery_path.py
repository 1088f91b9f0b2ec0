"""Mechanics of MysteryPath-v0, MysteryPath-Grid-v0 and Endless-MysteryPath-v0 (spec sections 5 and 6)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import envs
from envs.mystery_path import TILE, MysteryPathCore
from tests.support.batching import check_batched_equals_singles, check_vector_env_matches_singles

IDS = ["MysteryPath-v0", "MysteryPath-Grid-v0", "Endless-MysteryPath-v0"]
RED = np.array([255, 0, 0], dtype=np.uint8)
HEADING_STEP = {0: (0, -1), 90: (-1, 0), 180: (0, 1), 270: (1, 0)}


def make(env_id: str, **kwargs: object) -> gym.Env:
    return gym.make(env_id, disable_env_checker=True, **kwargs)


def core_of(env: gym.Env) -> MysteryPathCore:
    return env.unwrapped.core


def red_pixels(frame: np.ndarray) -> np.ndarray:
    return np.argwhere(np.all(frame == RED, axis=-1))


def free_action_towards(core: MysteryPathCore, tile: tuple[int, int]) -> list[int]:
    """MultiDiscrete action moving the free agent towards the centre of ``tile``."""
    x, y = core.pos[0].tolist()
    cx, cy = tile[0] * TILE + TILE // 2, tile[1] * TILE + TILE // 2
    horizontal = 0 if abs(cx - x) < 2 else (1 if cx < x else 2)
    vertical = 0 if abs(cy - y) < 2 else (1 if cy < y else 2)
    return [horizontal, vertical]


def grid_action_towards(core: MysteryPathCore, tile: tuple[int, int]) -> int:
    """Discrete grid action: turn towards the neighbouring ``tile`` (left turns), then step forward."""
    cell = divmod(int(core.grid_state[0]) >> 2, 7)
    want = {v: k for k, v in HEADING_STEP.items()}[(tile[0] - cell[0], tile[1] - cell[1])]
    return 3 if int(core.heading[0]) == want else 1


def agent_tile(core: MysteryPathCore) -> tuple[int, int]:
    x, y = core.pos[0].tolist()
    return x // TILE, y // TILE


def follow_path(env: gym.Env, max_steps: int = 400) -> list[tuple[float, bool, dict]]:
    """Walk a (non-endless) level along its path; returns (reward, terminated, info) per step."""
    core = core_of(env)
    path = core.levels[0][2].path
    out = []
    for _ in range(max_steps):
        here = agent_tile(core)
        target = path[path.index(here) + 1]
        action = grid_action_towards(core, target) if core.grid else free_action_towards(core, target)
        _, reward, terminated, truncated, info = env.step(action)
        assert not truncated
        out.append((reward, terminated, info))
        if terminated:
            return out
    raise AssertionError("the path was not followed to the goal")


# ----------------------------------------------------------------------------------------------- levels
@pytest.mark.parametrize("env_id", IDS[:2])
def test_reset_shows_only_the_agent_unless_origin_or_goal_are_shown(env_id: str) -> None:
    env = make(env_id)
    obs, info = env.reset(seed=3)
    assert obs.shape == (84, 84, 3) and obs.dtype == np.uint8 and info == {}
    core = core_of(env)
    origin, goal, _ = core.levels[0]
    x, y = core.pos[0].tolist()
    assert (x, y) == (origin[0] * TILE + 6, origin[1] * TILE + 6)
    lit = np.argwhere(obs.any(axis=-1))
    assert lit[:, 0].min() >= y - 14 and lit[:, 0].max() < y + 14 and lit[:, 1].min() >= x - 14
    obs, _ = env.reset(seed=3, options={"show_origin": True, "show_goal": True})
    gx, gy = goal
    assert (obs[gy * TILE : gy * TILE + TILE, gx * TILE : gx * TILE + TILE] == (0, 255, 0)).all()
    ox, oy = origin
    corners = obs[[oy * TILE, oy * TILE + 11], :][:, [ox * TILE, ox * TILE + 11]]  # around the agent's body
    assert (corners == (0, 0, 255)).all()


def test_following_the_path_pays_progress_once_per_tile_and_the_goal() -> None:
    env = make("MysteryPath-v0")
    env.reset(seed=11)
    path = core_of(env).levels[0][2].path
    steps = follow_path(env)
    rewards = [r for r, _, _ in steps]
    assert (
        rewards.count(0.1) == len(path) - 2
        and rewards[-1] == 1.0
        and sum(rewards[:-1]) == pytest.approx(0.1 * (len(path) - 2))
    )
    info = steps[-1][2]
    assert set(info) == {"reward", "length", "success", "num_fails"}
    assert info["success"] == 1 and info["num_fails"] == 0 and info["length"] == len(steps)
    assert info["reward"] == pytest.approx(0.1 * (len(path) - 2) + 1.0)
    assert all(not t and i == {} for _, t, i in steps[:-1])


def test_grid_variant_walks_tile_by_tile_and_pays_no_progress_by_default() -> None:
    env = make("MysteryPath-Grid-v0")
    env.reset(seed=5)
    steps = follow_path(env)
    assert [r for r, _, _ in steps] == [0.0] * (len(steps) - 1) + [1.0]
    assert steps[-1][2]["success"] == 1
    # Progress can be switched on; the origin and the goal never pay it.
    env.reset(seed=5, options={"reward_path_progress": 0.25})
    path = core_of(env).levels[0][2].path
    assert sum(r for r, _, _ in follow_path(env)) == pytest.approx(0.25 * (len(path) - 2) + 1.0)


def _off_path_neighbour(core: MysteryPathCore) -> tuple[int, int]:
    origin, _, layout = core.levels[0]
    for dx, dy in HEADING_STEP.values():
        tile = (origin[0] + dx, origin[1] + dy)
        if 0 <= tile[0] < 7 and 0 <= tile[1] < 7 and tile not in layout.path:
            return tile
    raise AssertionError("every neighbour of the origin is on the path")


@pytest.mark.parametrize("env_id", IDS[:2])
def test_fall_off_shows_the_cross_then_returns_to_the_origin_ignoring_the_action(env_id: str) -> None:
    env = make(env_id)
    env.reset(seed=2, options={"reward_fall_off": -0.5, "reward_step": -0.01})
    core = core_of(env)
    start = core.pos[0].copy()
    off = _off_path_neighbour(core)
    for _ in range(20):
        action = grid_action_towards(core, off) if core.grid else free_action_towards(core, off)
        obs, reward, terminated, _, _ = env.step(action)
        if agent_tile(core) == off:
            break
        assert reward == -0.01 and not red_pixels(obs).size
    else:
        raise AssertionError("the agent did not reach the off-path tile")
    # The fall-off step: penalty, and the red cross centred on the agent where it fell off.
    assert reward == pytest.approx(-0.51) and not terminated
    x, y = core.pos[0].tolist()
    red = red_pixels(obs)
    assert red.size and (red[:, 0].min(), red[:, 0].max(), red[:, 1].min(), red[:, 1].max()) == (
        y - 5,
        y + 4,
        x - 5,
        x + 4,
    )
    heading = int(core.heading[0])
    # Next step: back on the origin tile whatever the action, heading unchanged, no cross.
    obs, reward, *_ = env.step(3 if core.grid else [2, 2])
    np.testing.assert_array_equal(core.pos[0], start)
    assert int(core.heading[0]) == heading and reward == -0.01 and not red_pixels(obs).size
    # Without visual feedback the fall-off looks like any other step.
    env.reset(seed=2, options={"visual_feedback": False})
    for _ in range(20):
        obs, *_ = env.step(grid_action_towards(core, off) if core.grid else free_action_towards(core, off))
        assert not red_pixels(obs).size
        if core.off_path[0]:
            break
    assert core.off_path[0]


@pytest.mark.parametrize("env_id", IDS[:2])
def test_max_steps_ends_the_episode_as_terminated(env_id: str) -> None:
    env = make(env_id)
    env.reset(seed=0, options={"max_steps": 5})
    for t in range(5):
        _, _, terminated, truncated, info = env.step(env.action_space.sample() * 0)
        assert not truncated and terminated == (t == 4)
    assert info == {"reward": 0.0, "length": 5, "success": 0, "num_fails": 0}
    env.reset(seed=0)  # options apply to one episode: the default limit is back
    assert core_of(env).max_steps[0] == (128 if "Grid" in env_id else 512)


def test_free_agent_moves_three_px_straight_and_two_diagonally_and_stays_on_screen() -> None:
    env = make("MysteryPath-v0")
    env.reset(seed=0, options={"cardinal_origin_choice": [0], "max_steps": 100})
    core = core_of(env)
    x, y = core.pos[0].tolist()
    env.step([2, 0])
    assert core.pos[0].tolist() == [x + 3, y] and core.heading[0] == 270
    if not core.off_path[0]:
        env.step([1, 1])
        assert core.pos[0].tolist() == [x + 1, y - 2] and core.heading[0] == 45
    core.off_path[0] = False
    core.pos[0] = (8, 8)
    env.step([1, 1])
    assert core.pos[0].tolist() == [6, 6]  # the centre stays 6 px (the body radius) inside the screen


# ---------------------------------------------------------------------------------------------- endless
def endless_action_towards(core: MysteryPathCore, tile: tuple[int, int]) -> int:
    x, y = core.pos[0].tolist()
    cx, cy = tile[0] * TILE + TILE // 2, tile[1] * TILE + TILE // 2
    if abs(cy - y) >= 2:
        return 2 if cy < y else 3
    return 1 if cx > x else 0


def next_path_tile(core: MysteryPathCore) -> tuple[int, int]:
    xs, ys = core.path_tiles(0)
    node = int(core.current_node[0])
    return xs[node + 1], ys[node + 1]


def walk_endless_to_column(env: gym.Env, column: int) -> None:
    """Follow the endless path until the agent stands on a path tile in ``column`` or beyond."""
    core = core_of(env)
    for _ in range(400):
        node = int(core.current_node[0])
        if core.chain_x[0, node] >= column and agent_tile(core) == (core.chain_x[0, node], core.chain_y[0, node]):
            return
        *_, terminated, _, _ = env.step(endless_action_towards(core, next_path_tile(core)))
        assert not terminated and not core.off_path[0]
    raise AssertionError("did not get there")


def test_endless_actions_right_up_down_and_the_camera_keeps_the_agent_in_place() -> None:
    env = make("Endless-MysteryPath-v0")
    obs0, info = env.reset(seed=4)
    core = core_of(env)
    assert env.action_space == gym.spaces.Discrete(4) and env.unwrapped.has_ground_truth_info
    assert env.unwrapped.ground_truth_space.shape == (3,) and set(info) == {"ground_truth"}
    x, y = core.pos[0].tolist()
    assert core.heading[0] == 270 and x == 6
    lit = np.argwhere(obs0.any(axis=-1))
    assert lit[:, 1].min() >= 52 and lit[:, 1].max() < 80  # drawn at screen x 66, 5.5 tiles from the left
    moves = {0: (0, 0, 270), 1: (3, 0, 270), 2: (0, -3, 0), 3: (0, 3, 180)}
    for action in (1, 0, 2, 3):
        env.reset(seed=4)
        obs, *_ = env.step(action)
        dx, dy, heading = moves[action]
        assert core.pos[0].tolist() == [x + dx, y + dy] and core.heading[0] == heading
        assert core.camera_x[0] == -60 + dx
        lit = np.argwhere(obs.any(axis=-1))
        assert lit[:, 1].min() >= 52 and lit[:, 1].max() < 80


def test_endless_no_op_runs_out_of_stamina() -> None:
    env = make("Endless-MysteryPath-v0")
    for level, expected in ((None, 20), (7, 7)):
        env.reset(seed=1, options=None if level is None else {"stamina_level": level})
        for t in range(expected):
            _, reward, terminated, truncated, info = env.step(0)
            assert terminated == (t == expected - 1) and not truncated
        assert info["length"] == expected and info["num_fails"] == 0 and info["max_x"] == 0
        assert set(info) == {"reward", "length", "num_fails", "max_x", "tiles_visited", "ground_truth"}


def test_endless_stamina_refills_on_fresh_tiles_and_the_path_pays_once() -> None:
    env = make("Endless-MysteryPath-v0")
    env.reset(seed=6)
    core = core_of(env)
    walk_endless_to_column(env, 3)
    assert core.stamina[0] >= 20 - 4  # refilled on every fresh tile (about four steps per tile)
    assert core.tiles_visited[0] == core.current_node[0] > 0
    assert core.episode_return[0] == pytest.approx(0.1 * int(core.tiles_visited[0]))


def _fall_off_vertically(env: gym.Env) -> tuple[tuple[int, int], float, bool]:
    """Move up or down from the current path tile until the agent leaves the path; (tile, reward, terminated)."""
    core = core_of(env)
    tx, ty = agent_tile(core)
    on_path = set(zip(*core.path_tiles(0), strict=True))
    action = 2 if (tx, ty - 1) not in on_path else 3
    assert (tx, ty + (-1 if action == 2 else 1)) not in on_path, "both vertical neighbours are on the path"
    for _ in range(12):
        _, reward, terminated, _, _ = env.step(action)
        if core.off_path[0]:
            return agent_tile(core), reward, terminated
    raise AssertionError("did not fall off")


def test_endless_falling_off_twice_at_the_same_tile_ends_the_episode() -> None:
    env = make("Endless-MysteryPath-v0")
    env.reset(seed=0, options={"reward_fall_off": -1.0})
    core = core_of(env)
    first, reward, terminated = _fall_off_vertically(env)
    assert reward == -1.0 and not terminated and core.cross_visible[0]
    env.step(1)  # back to the first tile, the action is ignored
    assert core.pos[0].tolist() == core.return_pos[0].tolist() and core.camera_x[0] == -60
    second, _, terminated = _fall_off_vertically(env)
    assert second == first and terminated


def test_endless_falling_off_behind_the_best_column_ends_the_episode() -> None:
    env = make("Endless-MysteryPath-v0")
    for seed in range(20):
        env.reset(seed=seed)
        core = core_of(env)
        walk_endless_to_column(env, 3)
        tx, ty = agent_tile(core)
        on_path = set(zip(*core.path_tiles(0), strict=True))
        if {(tx, ty - 1), (tx, ty + 1)} <= on_path or {(0, core.chain_y[0, 0] - 1), (0, core.chain_y[0, 0] + 1)} <= (
            on_path
        ):
            continue
        break
    best = int(core.max_x[0])
    assert best >= 3
    _, _, terminated = _fall_off_vertically(env)  # in the best column: allowed once
    assert not terminated
    env.step(0)
    assert agent_tile(core)[0] == 0
    tile, _, terminated = _fall_off_vertically(env)  # column 0 < best column
    assert tile[0] < best and terminated


def test_endless_ground_truth_points_to_the_next_path_tile() -> None:
    env = make("Endless-MysteryPath-v0")
    _, info = env.reset(seed=9)
    core = core_of(env)
    columns = set()
    for _ in range(90):
        node = int(core.current_node[0])
        (x0, y0), (x1, y1) = (int(core.chain_x[0, node]), int(core.chain_y[0, node])), next_path_tile(core)
        if x1 - x0 != -1:  # a westward step keeps the previous value (quirk)
            expected = {(1, 0): [1, 0, 0], (0, -1): [0, 1, 0], (0, 1): [0, 0, 1]}[(x1 - x0, y1 - y0)]
            assert info["ground_truth"].tolist() == expected
        columns.add(x0)
        *_, info = env.step(endless_action_towards(core, (x1, y1)))
    assert 7 in columns  # the transition tile to the second segment was passed


def test_endless_past_path_is_drawn_behind_the_agent_only() -> None:
    env = make("Endless-MysteryPath-v0")
    env.reset(seed=6)
    walk_endless_to_column(env, 4)
    obs = env.unwrapped.core.observations()[0]
    white = np.argwhere(np.all(obs == 255, axis=-1))
    assert white.size and white[:, 1].max() < 80  # never ahead of the agent (at screen x 52..79)
    assert (obs[np.all(obs == 210, axis=-1)]).size  # the tiles' grey borders
    env.reset(seed=6, options={"show_past_path": False})
    walk_endless_to_column(env, 4)
    assert not np.all(env.unwrapped.core.observations()[0] == 255, axis=-1).any()


def test_endless_show_origin_has_no_effect_and_stamina_bar_and_background_options_do() -> None:
    frames = {}
    for name, options in {
        "plain": {},
        "origin": {"show_origin": True},
        "bar": {"show_stamina": True},
        "ice": {"show_background": True},
    }.items():
        env = make("Endless-MysteryPath-v0")
        obs, _ = env.reset(seed=3, options=options)
        for action in (1, 1, 0, 0):
            obs, *_ = env.step(action)
        frames[name] = obs
    np.testing.assert_array_equal(frames["plain"], frames["origin"])
    core = env.unwrapped.core  # the "ice" run made the same moves as the "bar" run
    red = int(84 * (1 - int(core.stamina[0]) / 20))
    bar = frames["bar"][:, 80:]
    assert red > 0 and (bar[:red] == RED).all() and (bar[red:] == (0, 255, 0)).all()
    assert (frames["ice"] == (125, 177, 250)).all(axis=-1).sum() > 84 * 84 // 2


def test_debug_views_show_the_ground_truth() -> None:
    env = make("MysteryPath-v0", render_mode="debug_rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (336, 336, 3)
    small = frame[::4, ::4]
    origin, goal, layout = core_of(env).levels[0]
    for (x, y), colour in [(goal, (0, 255, 0)), (layout.path[1], (255, 255, 255)), (layout.walls[0], (255, 0, 0))]:
        assert (small[y * TILE, x * TILE] == colour).all()
    env = make("Endless-MysteryPath-v0", render_mode="debug_rgb_array")
    env.reset(seed=0)
    small = env.render()[::4, ::4]
    assert (small[:, 80:] == (0, 255, 0)).all()  # the stamina bar is always drawn in the debug view
    assert (np.all(small == 200, axis=-1)).any()  # all path tiles at alpha 200 over black


def test_render_fps_and_metadata() -> None:
    for env_id, fps in zip(IDS, (25, 3, 25), strict=True):
        env = make(env_id)
        assert env.metadata["render_fps"] == fps and core_of(env).render_fps(0) == fps


# ---------------------------------------------------------------------------------------------- options
@pytest.mark.parametrize(
    ("env_id", "options", "message"),
    [
        ("MysteryPath-Grid-v0", {"agent_speed": 3.0}, "unknown option 'agent_speed'"),
        ("Endless-MysteryPath-v0", {"reward_goal": 1.0}, "unknown option 'reward_goal'"),
        ("MysteryPath-v0", {"cardinal_origin_choice": [4]}, "'cardinal_origin_choice'"),
        ("MysteryPath-v0", {"cardinal_origin_choice": []}, "'cardinal_origin_choice'"),
        ("MysteryPath-v0", {"show_goal": 1}, "'show_goal'"),
        ("MysteryPath-v0", {"agent_scale": 0.0}, "'agent_scale'"),
        ("MysteryPath-v0", {"agent_speed": -1.0}, "'agent_speed'"),
        ("Endless-MysteryPath-v0", {"camera_offset_scale": 6.0}, r"'camera_offset_scale'=6.0 is invalid.*\[0, 5.5\]"),
        ("Endless-MysteryPath-v0", {"stamina_level": 0}, "'stamina_level'"),
    ],
)
def test_bad_options_raise_value_errors_naming_the_key(env_id: str, options: dict, message: str) -> None:
    env = make(env_id)
    with pytest.raises(ValueError, match=message):
        env.reset(seed=0, options=options)


def test_grid_and_endless_together_is_not_a_variant() -> None:
    with pytest.raises(ValueError, match="no grid variant"):
        MysteryPathCore(grid=True, endless=True)


# -------------------------------------------------------------------------------- batched = one by one
OPTIONS = {
    "MysteryPath-v0": [
        {"max_steps": 70},
        {"show_origin": True, "show_goal": True, "agent_scale": 0.4, "agent_speed": 4.5, "max_steps": 90},
    ],
    "MysteryPath-Grid-v0": [
        {"max_steps": 50},
        {"show_goal": True, "reward_step": -0.01, "cardinal_origin_choice": [1, 2], "max_steps": 40},
    ],
    "Endless-MysteryPath-v0": [
        {"max_steps": 130},
        {"show_background": True, "show_stamina": True, "camera_offset_scale": 2.3, "max_steps": 110},
        {"camera_offset_scale": 0.5, "agent_speed": 4.0, "agent_scale": 0.4, "max_steps": 150},
    ],
}


def _actions(space: gym.Space, rng: np.random.Generator, cores: list[MysteryPathCore]) -> np.ndarray:
    """Random actions; endless agents mostly follow their path (so that they reach later segments)."""
    n = len(cores)
    if hasattr(space, "nvec"):
        return rng.integers(0, space.nvec, size=(n, 2))
    actions = rng.integers(0, space.n, size=n)
    if cores[0].endless:
        for k, core in enumerate(cores):
            if rng.random() < 0.9 and not core.off_path[0]:
                actions[k] = endless_action_towards(core, next_path_tile(core))
    return actions


@pytest.mark.parametrize("env_id", IDS)
def test_batched_slots_equal_single_environments(env_id: str) -> None:
    """A 6-slot core (stepped all at once, or a few live slots at a time) equals six 1-slot cores."""
    singles, episodes = check_batched_equals_singles(
        env_id,
        OPTIONS[env_id],
        300,
        lambda rng, singles: _actions(singles[0].single_action_space, rng, singles),
    )
    assert episodes >= 3
    if env_id.startswith("Endless"):
        assert max(int(s.num_segments[0]) for s in singles) > 3  # segments were generated during steps


@pytest.mark.parametrize("env_id", IDS)
def test_vector_env_matches_single_envs(env_id: str) -> None:
    """gymnasium.make_vec (next-step autoreset, generators continued) equals single envs reset without a seed."""
    resets = check_vector_env_matches_singles(
        env_id, {"max_steps": 25}, 70, lambda rng, cores: _actions(cores[0].single_action_space, rng, cores)
    )
    assert resets >= 3


def _reference_segments(rng: np.random.Generator, count: int) -> list[list[tuple[int, int]]]:
    """The reference's endless reset: start row, then per segment a goal row and a level (8 columns apart)."""
    from envs.mystery_path.generator import generate_path

    segments, start = [], int(rng.integers(0, 7))
    for s in range(count):
        goal = int(rng.integers(0, 7))
        path = generate_path(rng, 7, 7, (0, start), (6, goal)).path
        segments.append([(x + 8 * s, y) for x, y in path] + [(8 * s + 7, goal)])
        start = goal
    return segments


def test_endless_segments_are_built_lazily_with_the_reference_stream() -> None:
    """Only the first segment is built at reset; a reset that continues the generator first makes the draws of
    the segments the reference built in the previous episode, so the next level is the reference's."""
    rng = envs.core.seeded_generator(21)
    first = _reference_segments(rng, 3)
    second = _reference_segments(rng, 3)
    env = make("Endless-MysteryPath-v0")
    env.reset(seed=21)
    core = core_of(env)
    assert core.num_segments[0] == 1
    for _ in range(20):  # the no-op episode never leaves the first segment
        env.step(0)
    assert core.num_segments[0] == 1
    env.reset()  # generator continued
    tiles = list(zip(*core.path_tiles(0), strict=True))
    assert tiles == [t for seg in second for t in seg]
    env.reset(seed=21)
    walk_endless_to_column(env, 8)  # entering the second segment builds what the reference has: three segments
    assert core.num_segments[0] == 3
    assert list(zip(*core.chain_lists[0], strict=True)) == [t for seg in first for t in seg]
    walk_endless_to_column(env, 16)  # entering the third segment: the reference builds a fourth
    assert core.num_segments[0] == 4
    rng = envs.core.seeded_generator(21)
    _reference_segments(rng, 4)
    after_four = _reference_segments(rng, 3)
    env.reset()  # generator continued: the draws of all four segments come first
    assert list(zip(*core.path_tiles(0), strict=True)) == [t for seg in after_four for t in seg]


def test_a_reset_that_continues_the_generator_draws_but_does_not_build_the_last_episodes_segments(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The finished episode's remaining segments (the reference built them) only advance the generator: their
    draws are made, their tiles never built; the new episode's level is still the reference's."""
    rng = envs.core.seeded_generator(33)
    _reference_segments(rng, 3)
    second = _reference_segments(rng, 3)
    env = make("Endless-MysteryPath-v0")
    env.reset(seed=33)
    core = core_of(env)
    built = []
    original = type(core)._add_segment
    monkeypatch.setattr(type(core), "_add_segment", lambda self, k, draws: built.append(k) or original(self, k, draws))
    env.reset()  # generator continued: the draws of two unbuilt segments come first
    assert built == [0] and core.num_segments[0] == 1
    assert list(zip(*core.path_tiles(0), strict=True)) == [t for seg in second for t in seg]


def test_endless_resets_of_many_slots_equal_resets_one_by_one() -> None:
    """Endless slots reset together (the arrays of all of them written at once, the past-path starts of many slots
    computed by ``walk_starts``) equal one-slot cores, with seeds and with continued generators."""
    options = [
        {"max_steps": 40},
        {"camera_offset_scale": 2.3, "agent_speed": 4.0, "max_steps": 55},
        {"show_past_path": False, "max_steps": 30},
    ]
    singles, episodes = check_batched_equals_singles(
        "Endless-MysteryPath-v0",
        options,
        160,
        lambda rng, singles: _actions(singles[0].single_action_space, rng, singles),
        n=15,
    )
    assert episodes >= 30
    assert max(int(s.num_segments[0]) for s in singles) >= 3  # segments were generated during steps


def test_walk_starts_of_many_chains_equal_walk_start() -> None:
    from envs.mystery_path import walk_start, walk_starts

    rng = np.random.default_rng(5)
    for depth in (0, 1, 2, 5):
        chains = []
        for _ in range(40):  # chains that go east and sometimes back west, as paths may
            steps = rng.choice([-1, 0, 0, 1, 1, 1], size=int(rng.integers(1, 30)))
            chains.append(np.maximum(np.cumsum(np.concatenate([[0], steps])), 0).tolist())
        columns = np.full((len(chains), max(map(len, chains))), 99)
        for s, xs in enumerate(chains):
            columns[s, : len(xs)] = xs
        starts = walk_starts(columns, depth)
        for s, xs in enumerate(chains):
            assert starts[s, : len(xs)].tolist() == [walk_start(xs, i, xs[i] - 1, depth) for i in range(len(xs))]


# agents away from the screen's edge, at the edge (their sheet windows reach past it), and both in one batch
@pytest.mark.parametrize("options", [[{}], [{"camera_offset_scale": 0.0}], [{}, {"camera_offset_scale": 0.0}]])
def test_endless_agents_of_one_scale_pasted_through_their_sheet_equal_single_environments(options: list) -> None:
    """When every endless slot uses one agent scale, the batched frames paste the agents through a SpriteSheet
    (windowed composite) instead of the pixel scatter of mixed scales: same frames as one-slot cores."""
    core = envs.make_core("Endless-MysteryPath-v0", num_envs=8)
    core.reset_slots(range(8), range(8), options[0])
    assert core.agent_sheet is not None
    core.reset_slot(3, seed=3, options={"agent_scale": 0.4})
    assert core.agent_sheet is None
    check_batched_equals_singles(
        "Endless-MysteryPath-v0",
        [{"max_steps": 45, **o} for o in options],
        90,
        lambda rng, singles: _actions(singles[0].single_action_space, rng, singles),
        n=8,
    )


def test_endless_chains_stored_for_many_slots_equal_one_slot_at_a_time() -> None:
    """_store_chains with array operations (several slots, any first tile) writes what the one-slot path writes."""
    core = envs.make_core("Endless-MysteryPath-v0", num_envs=5)
    core.reset_slots(range(5), range(5))
    for k in range(5):  # longer chains: the reference's three segments (and more for two slots)
        core.reference_segments[k] += k % 2
        core._catch_up(k)
    names = ("chain_x", "chain_y", "direction", "flags", "tile_node")
    slots, begins = [0, 2, 3, 4], [3, 0, 11, 8]
    written = {}
    for many in (False, True):
        for name in names:
            getattr(core, name)[:] = 0
        if many:
            core._store_chains(slots, begins)
        else:
            for k, begin in zip(slots, begins, strict=True):
                core._store_chains([k], [begin])
        written[many] = [getattr(core, name).copy() for name in names]
    for name, one, batch in zip(names, written[False], written[True], strict=True):
        np.testing.assert_array_equal(batch, one, err_msg=name)
