"""The tiny training run of the reliability and sweep tests: a GRU on ProofOfMemory, 4 workers x 16 steps an update."""

from __future__ import annotations

from typing import Any


def tiny_run(ppo: dict[str, Any], run: dict[str, Any], evaluation: dict[str, Any] | None = None) -> dict[str, Any]:
    """The tiny run's config as a dict, with the test's own ``ppo`` and ``run`` settings (and ``eval`` block)."""
    config: dict[str, Any] = {
        "env": {"id": "ProofOfMemory-v0", "options": {"delay": 3}},
        "model": {"memory": "gru", "memory_size": 16, "hidden_size": 16, "vector_encoder_size": 8},
        "ppo": dict(ppo),
        "run": {"workers": 4, "worker_steps": 16, "progress_bar": False, **run},
    }
    if evaluation is not None:
        config["eval"] = dict(evaluation)
    return config


def with_run(config: dict[str, Any], **run: Any) -> dict[str, Any]:
    """``config`` with some of its ``run`` settings replaced."""
    return {**config, "run": {**config["run"], **run}}
