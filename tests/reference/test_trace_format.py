"""Sanity checks of the recorded reference data (format only; no memory_gym needed)."""

from __future__ import annotations

import re

import numpy as np
import pytest

from scripts.reference import REFERENCE_IDS
from scripts.reference.trace_format import image_digest, load_mp_paths, load_traces, obs_digest, vector_digest

PER_STEP = ("actions", "obs", "rewards", "terminated", "truncated", "infos")


@pytest.mark.parametrize("env_id", REFERENCE_IDS)
def test_trace_file_structure(env_id: str) -> None:
    data = load_traces(env_id)
    assert data["env_id"] == env_id
    assert data["reference"]["memory_gym"] == "1.0.2"
    digest = re.compile(r"[0-9a-f]{16}(:[0-9a-f]{16})?")
    seeds = [ep["seed"] for ep in data["episodes"]]
    assert any(s is None and prev is not None for prev, s in zip(seeds, seeds[1:], strict=False))
    for ep in data["episodes"]:
        n = len(ep["actions"])
        assert n > 0 and all(len(ep[k]) == n for k in PER_STEP), ep["name"]
        assert all(digest.fullmatch(d) for d in [ep["reset_obs"], *ep["obs"]])
        ends = [t or u for t, u in zip(ep["terminated"], ep["truncated"], strict=True)]
        assert not any(ends[:-1])
        assert ends[-1] != ep.get("cut", False), ep["name"]


def test_digest_helpers() -> None:
    img = np.arange(84 * 84 * 3, dtype=np.uint8).reshape(84, 84, 3)
    vec = np.zeros(180, dtype=np.float32)
    assert obs_digest(img) == image_digest(img) != image_digest(img.transpose(1, 0, 2))
    both = {"visual_observation": img, "vector_observation": vec}
    assert obs_digest(both) == image_digest(img) + ":" + vector_digest(vec)
    with pytest.raises(ValueError):
        image_digest(img.astype(np.float32))


def test_mp_paths() -> None:
    data = load_mp_paths()
    assert len(data["MysteryPath-v0"]) == 500 and len(data["Endless-MysteryPath-v0"]) == 100
    for rec in data["MysteryPath-v0"]:
        path = rec["path"]
        assert path[0] == rec["origin"] and path[-1] == rec["goal"]
        assert all(abs(a[0] - b[0]) + abs(a[1] - b[1]) == 1 for a, b in zip(path, path[1:], strict=False))
        assert not {tuple(p) for p in path} & {tuple(w) for w in rec["walls"]}
    for rec in data["Endless-MysteryPath-v0"]:
        assert len(rec["segments"]) == 3
