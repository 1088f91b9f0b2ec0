"""The console scripts need a display: without one they stop at once with exit status 2 and one line that says so
(and how to force a video driver), instead of playing in a window nobody sees.

Run as the console scripts run: in a fresh process, with an environment cleaned of ``DISPLAY``, ``WAYLAND_DISPLAY``
and ``SDL_VIDEODRIVER``.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from envs import play as player

ROOT = Path(__file__).parents[2]
SCRIPT_NAMES = sorted(player.SCRIPTS)
DISPLAY_VARIABLES = ("DISPLAY", "WAYLAND_DISPLAY", "SDL_VIDEODRIVER")
UNUSED_DISPLAY = ":4242"  # an X display number that nothing serves here
TIMEOUT = 60  # seconds; a script that does not stop plays on, invisibly, until this


def clean_environment(**extra: str) -> dict[str, str]:
    environment = {key: value for key, value in os.environ.items() if key not in DISPLAY_VARIABLES}
    return {**environment, "PYGAME_HIDE_SUPPORT_PROMPT": "1", **extra}


def run_script(script: str, environment: dict[str, str], code: str | None = None) -> subprocess.CompletedProcess:
    """The console script ``script`` (its entry point ``envs.play:<script>``) in a fresh interpreter."""
    code = code or f"from envs.play import {script}; {script}()"
    return subprocess.run(
        [sys.executable, "-c", code],
        cwd=ROOT,
        env=environment,
        capture_output=True,
        text=True,
        timeout=TIMEOUT,
    )


@pytest.mark.parametrize("script", ["mortar_mayhem_grid", "searing_spotlights"])
def test_without_a_display_a_script_stops_with_status_2(script: str) -> None:
    done = run_script(script, clean_environment())
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2, (done.returncode, done.stderr)
    assert len(lines) == 1 and done.stdout == ""
    assert lines[0].startswith(f"{script}: needs a display") and "SDL_VIDEODRIVER" in lines[0]


@pytest.mark.skipif(Path(f"/tmp/.X11-unix/X{UNUSED_DISPLAY[1:]}").exists(), reason="an X server serves the display")
def test_a_display_that_cannot_be_opened_stops_the_script_too(tmp_path: Path) -> None:
    """SDL falls back to an invisible driver when the display named in DISPLAY cannot be opened. (A desktop session
    has a runtime directory; without one SDL adds a line of its own.)"""
    environment = clean_environment(DISPLAY=UNUSED_DISPLAY, XDG_RUNTIME_DIR=str(tmp_path))
    done = run_script("mystery_path", environment)
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2, (done.returncode, done.stderr)
    assert len(lines) == 1 and lines[0].startswith("mystery_path: cannot open a window on the display")
    assert UNUSED_DISPLAY in lines[0] and "SDL_VIDEODRIVER" in lines[0]


def test_setting_sdl_videodriver_forces_a_driver() -> None:
    """With SDL_VIDEODRIVER set the script runs (here on SDL's dummy driver, the window closed at once)."""
    code = (
        "import pygame; from envs.play import main; "
        "main('mortar_mayhem_grid', [], events=[[pygame.event.Event(pygame.QUIT)]], realtime=False)"
    )
    done = run_script("mortar_mayhem_grid", clean_environment(SDL_VIDEODRIVER="dummy"), code)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "game closed after 0 steps (episode not finished)"


@pytest.mark.parametrize("script", SCRIPT_NAMES)
def test_every_script_checks_for_a_display(
    script: str, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    for name in DISPLAY_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    with pytest.raises(SystemExit) as stop:  # (one frame at most, should it play)
        player.main(script, ["--seed", "3"], max_frames=1, realtime=False)
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"{script}: needs a display")
    with pytest.raises(SystemExit) as stop:  # --help needs no display
        player.main(script, ["--help"])
    assert stop.value.code == 0
