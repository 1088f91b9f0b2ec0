"""Checkpoints of a run directory, and the trained policy loaded back for evaluation.

A run directory holds ``config.yaml`` (the resolved config), ``run_info.json`` and ``checkpoints/update_NNNNNNN.pt``.
A checkpoint is written atomically and holds the model, optimizer, every random generator, the counters and the
actor's slot state (see :meth:`agents.actor.Actor.state`), so that a killed run resumes exactly. The acting parts
of a run (model, frozen HELM branch) are built from the config by :func:`build_agent`, the same way for training
and for :func:`load_policy`.
"""

from __future__ import annotations

import io
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import torch
import yaml

from agents.actor import rollout_copy
from agents.config import Config, config_from_dict, config_to_dict
from agents.io import atomic_write_bytes
from agents.models import ActorCritic, observation_fields

CHECKPOINT_FORMAT = 2
CHECKPOINT_GLOB = "update_*.pt"


def build_agent(
    config: Config, observation_space: gym.Space, action_space: gym.Space, device: torch.device | str = "cpu"
) -> tuple[ActorCritic, Any]:
    """The trainable model and the frozen HELM branch (None without one) of ``config``, on ``device``."""
    helm = None
    if config.model.helm.enabled:
        from agents.helm import HelmBranch

        h = config.model.helm
        image_shape = observation_fields(observation_space)["image"].shape
        helm = HelmBranch(
            image_shape,  # type: ignore[arg-type]
            lm=h.lm,
            beta=h.beta,
            mem_len=h.mem_len,
            seed=h.seed,
            random_layers=h.random_layers,
            random_width=h.random_width,
            random_heads=h.random_heads,
            random_vocab=h.random_vocab,
        ).to(device)
    helm_size = 0 if helm is None else helm.output_size
    reconstruction = config.ppo.reconstruction_coef > 0
    model = ActorCritic(observation_space, action_space, config.model, helm_size, reconstruction).to(device)
    return model, helm


def check_helm(helm: Any, state: dict[str, Any], path: str | Path) -> None:
    """The HELM branch rebuilt from the config must be the one the checkpoint was trained with (its weights are not
    stored: a pretrained model's directory or the random seed could have changed)."""
    found = None if helm is None else helm.fingerprint()
    if found != state.get("helm"):
        raise ValueError(
            f"{path}: the HELM branch built from the config (fingerprint {found}) is not the one this checkpoint was "
            f"trained with ({state.get('helm')}): has the language model at model.helm.lm changed?"
        )


def checkpoint_path(run_dir: str | Path, update: int) -> Path:
    return Path(run_dir) / "checkpoints" / f"update_{update:07d}.pt"


def list_checkpoints(run_dir: str | Path) -> list[Path]:
    """The run's checkpoints, oldest first."""
    return sorted((Path(run_dir) / "checkpoints").glob(CHECKPOINT_GLOB))


def latest_checkpoint(run_dir: str | Path) -> Path | None:
    """The newest ``checkpoints/update_*.pt`` of a run directory, or None."""
    paths = list_checkpoints(run_dir)
    return paths[-1] if paths else None


def checkpoint_update(path: str | Path) -> int:
    """The update number in a checkpoint's file name."""
    return int(Path(path).stem.split("_")[-1])


def write_checkpoint(path: str | Path, state: dict[str, Any], keep: int = 0) -> Path:
    """Write ``state`` atomically, then keep only the ``keep`` newest checkpoints beside it (0: all)."""
    path = Path(path)
    data = io.BytesIO()
    torch.save({"format": CHECKPOINT_FORMAT, **state}, data)
    atomic_write_bytes(path, data.getvalue())
    if keep:
        for old in sorted(path.parent.glob(CHECKPOINT_GLOB))[:-keep]:
            old.unlink()
    return path


def read_checkpoint(path: str | Path) -> dict[str, Any]:
    # Loaded on the CPU: RNG states must stay CPU tensors; weights and optimizer state move to their device.
    state = torch.load(path, map_location="cpu", weights_only=False)
    if state.get("format") != CHECKPOINT_FORMAT:
        raise ValueError(f"{path}: checkpoint format {state.get('format')!r}, expected {CHECKPOINT_FORMAT}")
    return state


def check_checkpoint_config(state: dict[str, Any], config: Config, path: str | Path) -> int | None:
    """That the checkpoint at ``path`` was written by ``config`` (the run's ``config.yaml``). One difference is
    allowed: ``run.total_steps`` raised since, i.e. the run was extended after this checkpoint (``train.py --resume
    DIR --set run.total_steps=N``). Returns the checkpoint's number of updates in that case, else None."""
    saved, current = state["config"], config_to_dict(config)
    if saved == current:
        return None
    saved_steps = saved.get("run", {}).get("total_steps")
    same_but_length = {**saved, "run": {**saved["run"], "total_steps": current["run"]["total_steps"]}} == current
    if not same_but_length:
        keys = ", ".join(_differing_keys(saved, current)) or "?"
        raise ValueError(f"{path} was written by a different config than the run's config.yaml (differing: {keys})")
    saved_updates = saved_steps // config.batch_size
    if saved_updates > config.num_updates:
        raise ValueError(
            f"{path} belongs to a run of run.total_steps={saved_steps} ({saved_updates} updates), longer than the "
            f"run's config.yaml says ({config.run.total_steps}, {config.num_updates} updates): a run can be "
            "extended, not shortened"
        )
    return saved_updates if saved_updates < config.num_updates else None


def _differing_keys(a: Any, b: Any, prefix: str = "") -> list[str]:
    """The dotted keys at which two nested dicts differ."""
    if not (isinstance(a, dict) and isinstance(b, dict)):
        return [] if a == b else [prefix or "(config)"]
    keys = list(a) + [key for key in b if key not in a]
    return [k for key in keys for k in _differing_keys(a.get(key), b.get(key), f"{prefix}.{key}" if prefix else key)]


def finished_update(run_dir: str | Path) -> int | None:
    """The last update of a run that completed (``run_info.json``'s ``finished``), else None."""
    path = Path(run_dir) / "run_info.json"
    if not path.is_file():
        return None
    return json.loads(path.read_text()).get("finished", {}).get("update")


def run_config(run_dir: str | Path) -> Config:
    """The resolved config saved in a run directory."""
    path = Path(run_dir) / "config.yaml"
    if not path.is_file():
        raise FileNotFoundError(f"{run_dir} is not a run directory: {path} is missing")
    return config_from_dict(yaml.safe_load(path.read_text()))


@dataclass
class Policy:
    """A trained policy as evaluation needs it: the config it was trained with, the acting model (a bfloat16 copy
    under bf16, as in training), the frozen HELM branch, and when it was saved."""

    config: Config
    model: ActorCritic
    helm: Any
    update: int
    step: int
    run_dir: Path
    checkpoint: Path


def load_policy(
    run_dir: str | Path, checkpoint: str | Path | None = None, device: torch.device | str = "cpu"
) -> Policy:
    """The policy of ``run_dir`` at ``checkpoint`` (default: the newest), rebuilt exactly as it was trained."""
    run_dir = Path(run_dir)
    config = run_config(run_dir)
    path = Path(checkpoint) if checkpoint is not None else latest_checkpoint(run_dir)
    if path is None:
        raise FileNotFoundError(f"{run_dir} holds no checkpoint (checkpoints/{CHECKPOINT_GLOB})")
    state = read_checkpoint(path)
    check_checkpoint_config(state, config, path)
    spec_core = config.env.make_core(1)
    model, helm = build_agent(config, spec_core.single_observation_space, spec_core.single_action_space, device)
    check_helm(helm, state, path)
    model.load_state_dict(state["model"])
    model.eval()
    acting = rollout_copy(model, config.run.precision)
    return Policy(config, acting, helm, state["update"], state["global_step"], run_dir, path)
