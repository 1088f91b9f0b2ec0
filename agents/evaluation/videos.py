"""GIFs of evaluation episodes: the agent's view (upscaled) beside the ground-truth debug view, each labelled, and
below them the step, the action just taken, its reward and the running return. :class:`EpisodeVideo` is a frame
hook of :func:`agents.evaluation.loop.evaluate`; Pillow draws the frames (imported when drawing).
"""

from __future__ import annotations

import io
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from agents.policy.actor import Actor, Outcome
from agents.runtime.io import atomic_write_bytes


class EpisodeVideo:
    """Frames of the first ``episodes`` slots of an evaluation, written as one GIF per episode: the agent's view
    (upscaled) beside the ground-truth debug view, each labelled above, and below them the step, the action just
    taken, its reward and the episode's running return."""

    VIEWS = ("agent's view", "ground truth")

    def __init__(self, episodes: int) -> None:
        self.episodes = episodes
        self.frames: list[list[np.ndarray]] = [[] for _ in range(episodes)]
        self.captions: list[list[str]] = [[] for _ in range(episodes)]
        self.returns = [0.0] * episodes
        self.ended = [False] * episodes

    def __call__(self, actor: Actor, outcome: Outcome | None) -> None:
        core = actor.core
        rewards = None if outcome is None else outcome.rewards.float().cpu().numpy()
        for slot in range(self.episodes):
            if self.ended[slot]:
                continue
            self.ended[slot] = not actor.active[slot]  # every frame while the slot plays, its last one included
            step = len(self.frames[slot])
            if rewards is None:
                caption = f"step 0   return {self.returns[slot]:.2f}"
            else:
                reward = float(rewards[slot])
                self.returns[slot] += reward
                action = _action_text(actor.memory.actions[slot][-1])
                caption = f"step {step}   action {action}   reward {reward:+.2f}   return {self.returns[slot]:.2f}"
            agent = core.agent_frame(slot)
            debug = core.debug_frame(slot)
            scale = debug.shape[0] // agent.shape[0]
            agent = np.repeat(np.repeat(agent, scale, axis=0), scale, axis=1)
            self.frames[slot].append(np.concatenate((agent, debug), axis=1))
            self.captions[slot].append(caption)

    def write(self, directory: Path, name: str, records: Sequence[dict[str, Any]]) -> list[Path]:
        paths = []
        for slot, frames in enumerate(self.frames):
            if not frames:
                continue
            record = records[slot]
            path = directory / f"{name}-seed{record['seed']}-rep{record['repetition']}.gif"
            captions = self.captions[slot]
            images = [labelled_frame(frame, self.VIEWS, text) for frame, text in zip(frames, captions, strict=True)]
            data = io.BytesIO()
            images[0].save(data, format="GIF", save_all=True, append_images=images[1:], duration=80, loop=0)
            atomic_write_bytes(path, data.getvalue())
            paths.append(path)
        return paths


def _action_text(action: np.ndarray) -> str:
    """One branch as its index, several as a tuple (MultiDiscrete)."""
    values = [int(value) for value in np.ravel(action)]
    return str(values[0]) if len(values) == 1 else "(" + ", ".join(map(str, values)) + ")"


def labelled_frame(frame: np.ndarray, views: Sequence[str], caption: str) -> Any:
    """``frame`` (views side by side, equally wide) as a PIL image with a black band above naming each view and
    one below holding ``caption``; the text is sized to the frame (Pillow's bundled font, no extra dependency)."""
    from PIL import Image, ImageDraw

    height, width = frame.shape[:2]
    font = _font(max(12, height // 22))
    band = int(font.size * 1.6) if hasattr(font, "size") else 16
    canvas = Image.new("RGB", (width, height + 2 * band))
    canvas.paste(Image.fromarray(np.ascontiguousarray(frame[..., :3])), (0, band))
    draw = ImageDraw.Draw(canvas)
    part = width / len(views)

    def put(text: str, centre_x: float, top: int) -> None:
        left, upper, right, lower = draw.textbbox((0, 0), text, font=font)
        x = max(2, centre_x - (right - left) / 2)
        draw.text((x, top + (band - (lower - upper)) / 2 - upper), text, fill=(255, 255, 255), font=font)

    for index, view in enumerate(views):
        put(view, part * (index + 0.5), 0)
    put(caption, width / 2, height + band)
    return canvas


def _font(size: int) -> Any:
    from PIL import ImageFont

    try:
        return ImageFont.load_default(size=size)  # scalable with FreeType (Pillow >= 10.1)
    except (TypeError, ImportError, OSError):
        return ImageFont.load_default()
