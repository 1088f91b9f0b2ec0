"""The keyboard players (console scripts), driven by scripted or posted pygame events under the dummy video driver."""

from __future__ import annotations

import os
from pathlib import Path

import pygame
import pytest
import tomllib

os.environ["SDL_VIDEODRIVER"] = "dummy"

from envs import ENV_IDS  # noqa: E402
from envs import play as player  # noqa: E402
from envs.play import ENDLESS_PATH, FREE, GRID, GRID_WITH_WAIT, SCRIPTS  # noqa: E402

SCRIPT_NAMES = [
    "mortar_mayhem",
    "mortar_mayhem_grid",
    "mortar_mayhem_b",
    "mortar_mayhem_b_grid",
    "endless_mortar_mayhem",
    "mystery_path",
    "mystery_path_grid",
    "endless_mystery_path",
    "searing_spotlights",
    "endless_searing_spotlights",
]
PLAYABLE = [name for name in SCRIPT_NAMES if SCRIPTS[name][0] in ENV_IDS]  # grows as the families land


def key(kind: int, code: int) -> pygame.event.Event:
    return pygame.event.Event(kind, key=code)


def down(code: int) -> pygame.event.Event:
    return key(pygame.KEYDOWN, code)


def up(code: int) -> pygame.event.Event:
    return key(pygame.KEYUP, code)


def test_every_console_script_is_declared() -> None:
    scripts = tomllib.loads((Path(__file__).parents[2] / "pyproject.toml").read_text())["project"]["scripts"]
    for name in SCRIPT_NAMES:
        assert scripts[name] == f"envs.play:{name}"
        assert callable(getattr(player, name))
    assert set(SCRIPTS) == set(SCRIPT_NAMES)


def test_key_mappings() -> None:
    k = pygame
    assert FREE.action([]) == [0, 0]
    assert FREE.action([k.K_w]) == [0, 1] and FREE.action([k.K_UP, k.K_d]) == [2, 1]
    assert FREE.action([k.K_w, k.K_s]) == [0, 2], "down beats up"
    assert FREE.action([k.K_a, k.K_RIGHT]) == [1, 0], "left beats right"
    assert FREE.action([k.K_LEFT, k.K_DOWN]) == [1, 2]
    assert [GRID.action([c]) for c in (k.K_w, k.K_UP, k.K_d, k.K_a, k.K_LEFT)] == [3, 3, 2, 1, 1]
    assert GRID.action([k.K_SPACE]) is None and GRID.action([]) is None, "Mystery Path Grid has no wait key"
    assert GRID_WITH_WAIT.action([k.K_SPACE]) == 0
    assert ENDLESS_PATH.action([]) == 0 and ENDLESS_PATH.action([k.K_w]) == 2 and ENDLESS_PATH.action([k.K_d]) == 1
    assert ENDLESS_PATH.action([k.K_w, k.K_d]) == 1 and ENDLESS_PATH.action([k.K_w, k.K_s, k.K_d]) == 3


@pytest.mark.parametrize("script", PLAYABLE)
def test_scripted_game_steps_changes_seed_and_closes(script: str) -> None:
    env_id, controls = SCRIPTS[script]
    move = pygame.K_d
    frames = [
        [down(move)],
        [],
        [up(move)],
        [down(pygame.K_PAGEUP)],
        [up(pygame.K_PAGEUP)],
        [down(pygame.K_w)],
        [up(pygame.K_w)],
        [pygame.event.Event(pygame.QUIT)],
        [down(move)],  # never read: the window was closed
    ]
    result = player.play(env_id, controls, seed=4, events=frames, realtime=False)
    assert result.seed == 5 and result.final_info is None
    if controls.polled:  # one step per frame before the QUIT, with the held keys of that frame
        assert result.steps == 7
        assert result.actions[:3] == [controls.action([move])] * 2 + [controls.noop]
        assert result.actions[5] == controls.action([pygame.K_w])
    elif controls.auto_noop is None:  # one step per bound key press
        assert result.actions == [controls.action([move]), controls.action([pygame.K_w])]
    else:  # Mortar Mayhem Grid plays its command icons by itself: a step every frame while they are shown
        assert result.actions == [controls.action([move]), 0, 0, 0, 0, controls.action([pygame.K_w]), 0]


@pytest.mark.parametrize("script", PLAYABLE)
def test_seed_never_goes_below_zero(script: str) -> None:
    env_id, controls = SCRIPTS[script]
    frames = [[down(pygame.K_PAGEDOWN)], [up(pygame.K_PAGEDOWN)], [down(pygame.K_PAGEDOWN)]]
    result = player.play(env_id, controls, seed=1, events=frames, realtime=False)
    assert result.seed == 0


@pytest.mark.parametrize("script", PLAYABLE)
def test_posted_events_drive_the_default_loop(script: str) -> None:
    """Events posted to pygame's own queue (what a real keyboard does) reach the loop, and QUIT ends it."""
    env_id, controls = SCRIPTS[script]
    pygame.display.init()
    pygame.event.post(down(pygame.K_PAGEUP))
    result = player.play(env_id, controls, seed=0, max_frames=1, realtime=False)
    assert result.seed == 1, "the posted PageUp was read"
    pygame.display.init()
    pygame.event.post(pygame.event.Event(pygame.QUIT))
    result = player.play(env_id, controls, seed=0, max_frames=50, realtime=False)
    assert result.steps == 0 and result.final_info is None, "closing the window ends the game at once"


@pytest.mark.parametrize("script", [s for s in PLAYABLE if "mortar_mayhem" in s])
def test_game_to_the_end_prints_statistics(script: str, capsys: pytest.CaptureFixture[str]) -> None:
    env_id, controls = SCRIPTS[script]
    wait = [] if controls.polled else [down(pygame.K_SPACE), up(pygame.K_SPACE)]
    frames = ([wait[:1], wait[1:]] if wait else [[]]) * 400  # waiting fails a check sooner or later
    result = player.main(script, ["--seed", "2"], events=frames, realtime=False)
    assert result.final_info is not None and result.final_info["length"] == result.steps
    printed = capsys.readouterr().out
    assert f"episode length: {result.steps}" in printed and "episode reward:" in printed
    assert "commands completed:" in printed and "ground_truth" not in printed


def test_negative_seed_is_refused() -> None:
    with pytest.raises(SystemExit):
        player.main("mortar_mayhem", ["--seed", "-1"])
