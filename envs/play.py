"""Play any Memory Gym environment with the keyboard: the console scripts ``mortar_mayhem``, ``mortar_mayhem_grid``,
``mortar_mayhem_b``, ``mortar_mayhem_b_grid``, ``endless_mortar_mayhem``, ``mystery_path``, ``mystery_path_grid``,
``endless_mystery_path``, ``searing_spotlights`` and ``endless_searing_spotlights``.

Each opens a 336x336 window with the ground-truth (debug) picture, plays one episode and prints its statistics.
``--seed`` picks the level (default 0); PageUp / PageDown change the seed by one (never below 0) and restart.
Closing the window ends the game. Controls, as in memory-gym:

* free movement (MM, MMB, Endless MM, MP, SS, Endless SS): the held keys are read every frame and one step runs per
  frame. W/Up = up, S/Down = down, A/Left = left, D/Right = right; down beats up and left beats right.
* grid movement (MM-Grid, MMB-Grid, MP-Grid): one step per key press. W/Up = forward, A/Left = turn left,
  D/Right = turn right, Space = wait (Mortar Mayhem grids only). MM-Grid plays the command icons by itself.
* Endless Mystery Path: held keys, one step per frame. D/Right = right, W/Up = up, S/Down = down, else wait.

The scripts need a display. Without ``DISPLAY`` and ``WAYLAND_DISPLAY`` (and without ``SDL_VIDEODRIVER``), or when
the display cannot be opened, they stop with exit status 2 and one line that says so, instead of playing in a window
nobody sees. ``SDL_VIDEODRIVER`` forces a video driver (``x11``, ``wayland``, ...; ``dummy`` plays without a window).
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym

os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
import pygame  # noqa: E402

import envs  # noqa: E402,F401  (registers the ids)
from envs.core import BatchedCore, HumanWindow  # noqa: E402

UP = (pygame.K_w, pygame.K_UP)
DOWN = (pygame.K_s, pygame.K_DOWN)
LEFT = (pygame.K_a, pygame.K_LEFT)
RIGHT = (pygame.K_d, pygame.K_RIGHT)


@dataclass(frozen=True)
class Controls:
    """How keys become actions.

    ``polled``: the held keys are read every frame and a step runs every frame; otherwise a step runs per key press.
    ``bindings``: (keys, action component index or None, value) in the order the reference tests them, so a later
    binding overrides an earlier one when several keys are held. ``noop``: the action when nothing is pressed.
    ``auto_noop``: while it is true for the core, a grid env steps with ``noop`` every frame by itself.
    """

    polled: bool
    noop: Any
    bindings: tuple[tuple[tuple[int, ...], int | None, int], ...]
    auto_noop: Callable[[BatchedCore], bool] | None = field(default=None, compare=False)

    def action(self, keys: Iterable[int]) -> Any:
        """The action for the pressed keys (held keys when polled, the key of one press otherwise); None = no step."""
        keys = set(keys)
        action = list(self.noop) if isinstance(self.noop, list) else self.noop
        bound = False
        for binding_keys, component, value in self.bindings:
            if keys & set(binding_keys):
                bound = True
                if component is None:
                    action = value
                else:
                    action[component] = value
        return action if (bound or self.polled) else None


FREE = Controls(True, [0, 0], ((UP, 1, 1), (RIGHT, 0, 2), (DOWN, 1, 2), (LEFT, 0, 1)))
GRID_TURNS = ((UP, None, 3), (RIGHT, None, 2), (LEFT, None, 1))
GRID = Controls(False, 0, GRID_TURNS)
GRID_WITH_WAIT = Controls(False, 0, (*GRID_TURNS, ((pygame.K_SPACE,), None, 0)))
GRID_WITH_CLUE = Controls(
    False, 0, (*GRID_TURNS, ((pygame.K_SPACE,), None, 0)), auto_noop=lambda core: bool(core.clue_left[0] > 0)
)
ENDLESS_PATH = Controls(True, 0, ((UP, None, 2), (RIGHT, None, 1), (DOWN, None, 3)))

# console script -> (environment id, controls)
SCRIPTS: dict[str, tuple[str, Controls]] = {
    "mortar_mayhem": ("MortarMayhem-v0", FREE),
    "mortar_mayhem_grid": ("MortarMayhem-Grid-v0", GRID_WITH_CLUE),
    "mortar_mayhem_b": ("MortarMayhemB-v0", FREE),
    "mortar_mayhem_b_grid": ("MortarMayhemB-Grid-v0", GRID_WITH_WAIT),
    "endless_mortar_mayhem": ("Endless-MortarMayhem-v0", FREE),
    "mystery_path": ("MysteryPath-v0", FREE),
    "mystery_path_grid": ("MysteryPath-Grid-v0", GRID),
    "endless_mystery_path": ("Endless-MysteryPath-v0", ENDLESS_PATH),
    "searing_spotlights": ("SearingSpotlights-v0", FREE),
    "endless_searing_spotlights": ("Endless-SearingSpotlights-v0", FREE),
}
SEED_KEYS = {pygame.K_PAGEUP: 1, pygame.K_PAGEDOWN: -1}
DISPLAY_VARIABLES = ("DISPLAY", "WAYLAND_DISPLAY")
INVISIBLE_DRIVERS = ("offscreen", "dummy")  # SDL's drivers without a window (it falls back to offscreen by itself)
FORCE_DRIVER = "to force a video driver, set SDL_VIDEODRIVER (e.g. x11 or wayland; dummy plays without a window)"


class DisplayError(RuntimeError):
    """No window can be shown: no display, or one that cannot be opened."""


def missing_display(environ: Mapping[str, str]) -> str | None:
    """Why the game cannot be shown in ``environ`` (None when a display is named or a video driver is forced)."""
    if environ.get("SDL_VIDEODRIVER") or any(environ.get(name) for name in DISPLAY_VARIABLES):
        return None
    return f"needs a display, and neither DISPLAY nor WAYLAND_DISPLAY is set; {FORCE_DRIVER}"


def open_window() -> HumanWindow:
    """The game's window. Opened before the environment is made, which defaults SDL_VIDEODRIVER to "dummy" for its
    own drawing; without a forced driver, SDL's fallback to an invisible one is a :class:`DisplayError`."""
    forced = os.environ.get("SDL_VIDEODRIVER")
    window = HumanWindow()
    driver = pygame.display.get_driver()
    if not forced and driver in INVISIBLE_DRIVERS:
        window.close()
        named = ", ".join(f"{name}={os.environ[name]!r}" for name in DISPLAY_VARIABLES if os.environ.get(name))
        raise DisplayError(
            f"cannot open a window on the display ({named}): SDL fell back to its invisible {driver!r} driver; "
            f"{FORCE_DRIVER}"
        )
    return window


@dataclass
class PlayResult:
    """What one game did: the steps taken, the seed played last, and the final info (None if the window closed)."""

    steps: int
    seed: int
    final_info: dict[str, Any] | None
    actions: list[Any]


def play(
    env_id: str,
    controls: Controls,
    seed: int = 0,
    events: Callable[[], list[pygame.event.Event]] | Iterator[list[pygame.event.Event]] | None = None,
    max_frames: int | None = None,
    realtime: bool = True,
) -> PlayResult:
    """Run the game loop until the episode ends, the window closes or ``max_frames`` frames have passed.

    ``events`` gives each frame's events (default: pygame's queue); tests pass scripted frames. With ``realtime``
    the loop holds the environment's frame rate (3 fps while Mortar Mayhem shows commands), otherwise it runs free.
    """
    next_events = _event_source(events)
    window = open_window()  # first: making the environment sets SDL_VIDEODRIVER's default
    try:
        env = gym.make(env_id, render_mode="debug_rgb_array", disable_env_checker=True)
    except BaseException:
        window.close()
        raise
    core: BatchedCore = env.unwrapped.core
    held: set[int] = set()
    actions: list[Any] = []
    steps = frames = 0
    final_info = None
    try:
        env.reset(seed=seed)
        while max_frames is None or frames < max_frames:
            frames += 1
            window.show(env.render(), f"seed {seed}", core.render_fps(0) if realtime else 0)
            pressed, quit_requested = [], False
            for event in next_events():
                if event.type == pygame.QUIT:
                    quit_requested = True
                elif event.type == pygame.KEYDOWN:
                    held.add(event.key)
                    pressed.append(event.key)
                elif event.type == pygame.KEYUP:
                    held.discard(event.key)
            if quit_requested:
                break
            if controls.polled:
                action = controls.action(held)
                seed_keys = [key for key in SEED_KEYS if key in held]
            else:
                # grid envs: one press per frame (the last one, as the reference reads it)
                key = pressed[-1] if pressed else None
                auto = controls.auto_noop is not None and controls.auto_noop(core)
                action = controls.action([key] if key is not None else [])
                if action is None and auto:
                    action = controls.noop
                seed_keys = [key] if key in SEED_KEYS else []
            if seed_keys:
                seed = max(seed + sum(SEED_KEYS[k] for k in seed_keys), 0)
                env.reset(seed=seed)
            if action is None:
                continue
            _, _, terminated, truncated, info = env.step(action)
            actions.append(action)
            steps += 1
            if terminated or truncated:
                final_info = info
                break
    finally:
        window.close()
        env.close()
    return PlayResult(steps, seed, final_info, actions)


def _event_source(events: Any) -> Callable[[], list[pygame.event.Event]]:
    if events is None:
        return pygame.event.get
    if callable(events):
        return events
    frames = iter(events)
    return lambda: next(frames, [pygame.event.Event(pygame.QUIT)])  # a script that runs out closes the window


def statistics(result: PlayResult) -> list[str]:
    """The lines the console scripts print at the end of a game."""
    if result.final_info is None:
        return [f"game closed after {result.steps} steps (episode not finished)"]
    labels = {"reward": "episode reward", "length": "episode length"}
    lines = []
    for key, value in result.final_info.items():
        if key == "ground_truth":
            continue
        shown = bool(value) if key == "success" else value
        lines.append(f"{labels.get(key, key.replace('_', ' '))}: {shown}")
    return lines


def main(script: str, argv: list[str] | None = None, **play_kwargs: Any) -> PlayResult:
    """Entry point of console script ``script`` (parses ``--seed``, plays, prints the statistics)."""
    env_id, controls = SCRIPTS[script]
    parser = argparse.ArgumentParser(prog=script, description=f"Play {env_id} with the keyboard.")
    parser.add_argument("--seed", type=int, default=0, help="seed of the first level (PageUp/PageDown change it)")
    args = parser.parse_args(argv)
    if args.seed < 0:
        parser.error("--seed must be >= 0")
    problem = missing_display(os.environ)
    try:
        if problem is not None:
            raise DisplayError(problem)
        result = play(env_id, controls, seed=args.seed, **play_kwargs)
    except DisplayError as err:
        print(f"{script}: {err}", file=sys.stderr)
        raise SystemExit(2) from None
    for line in statistics(result):
        print(line)
    return result


def mortar_mayhem() -> None:
    main("mortar_mayhem")


def mortar_mayhem_grid() -> None:
    main("mortar_mayhem_grid")


def mortar_mayhem_b() -> None:
    main("mortar_mayhem_b")


def mortar_mayhem_b_grid() -> None:
    main("mortar_mayhem_b_grid")


def endless_mortar_mayhem() -> None:
    main("endless_mortar_mayhem")


def mystery_path() -> None:
    main("mystery_path")


def mystery_path_grid() -> None:
    main("mystery_path_grid")


def endless_mystery_path() -> None:
    main("endless_mystery_path")


def searing_spotlights() -> None:
    main("searing_spotlights")


def endless_searing_spotlights() -> None:
    main("endless_searing_spotlights")
