"""Checkpoints of a run directory, and the trained policy loaded back for evaluation.

A run directory holds ``config.yaml`` (the resolved config), ``run_info.json`` and ``checkpoints/update_NNNNNNN.pt``.
A checkpoint is written atomically with its size and SHA-256 (:data:`CHECKPOINT_MAGIC`), checked whenever it is read
(a damaged one raises :class:`DamagedCheckpoint`, never loads), and holds the model, optimizer, every random
generator, the counters and the actor's slot state (see :meth:`agents.policy.actor.Actor.state`), so that a killed run
resumes exactly. The acting parts of a run (model, frozen HELM branch) are built from the config by
:func:`build_agent`, the same way for training and for :func:`load_policy`.
"""

from __future__ import annotations

import io
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch
import yaml

from agents.config import LENGTH_KEY, Config, config_from_dict, config_to_dict, differing_keys, resume_may_change
from agents.policy.actor import rollout_copy
from agents.policy.models import ActorCritic, observation_fields
from agents.runtime.io import atomic_write_bytes, content_record

CHECKPOINT_FORMAT = 2  # of the saved state (the dict); the file around it is described by CHECKPOINT_MAGIC
CHECKPOINT_GLOB = "update_*.pt"
# A checkpoint file: this line, one line of JSON with the payload's size and SHA-256, then the payload (torch.save)
CHECKPOINT_MAGIC = b"memgym-checkpoint 1\n"
LEGACY_MAGIC = b"PK\x03\x04"  # a bare torch.save zip, as checkpoints were written before they had a checksum


class DamagedCheckpoint(ValueError):
    """A checkpoint file is truncated, corrupted or not a checkpoint (the message names it); it is never loaded."""


def ground_truth_size(config: Config, core: Any) -> int:
    """The size of the targets of ``ppo.ground_truth_coef`` in ``core`` (its ``ground_truth_space``), 0 when the
    coefficient is 0; a ValueError naming the key when the environment has no ground truth in its infos."""
    if config.ppo.ground_truth_coef == 0:
        return 0
    space = getattr(core, "ground_truth_space", None) if getattr(core, "has_ground_truth_info", False) else None
    if space is None:
        raise ValueError(
            f"ppo.ground_truth_coef={config.ppo.ground_truth_coef:g} needs an environment with info['ground_truth'] "
            f"(has_ground_truth_info), and {config.env.id} has none: use an endless id (Endless-MortarMayhem-v0, "
            "Endless-MysteryPath-v0, Endless-SearingSpotlights-v0) or set ppo.ground_truth_coef=0"
        )
    return int(space.shape[0])


def build_agent(config: Config, core: Any, device: torch.device | str = "cpu") -> tuple[ActorCritic, Any]:
    """The trainable model and the frozen HELM branch (None without one) of ``config``, on ``device``, for the
    environment of ``core`` (its spaces, and its ground truth with ``ppo.ground_truth_coef``)."""
    observation_space, action_space = core.single_observation_space, core.single_action_space
    named = f"{config.env.id}'s observation space {environment_space(core)}"
    helm = None
    if config.model.helm.enabled:
        from agents.policy.helm import HelmBranch

        h = config.model.helm
        image = observation_fields(observation_space).get("image")
        if image is None:
            raise ValueError(
                f"model.helm.lm={h.lm!r}: the HELM branch needs an image observation, but {named} has none: set "
                "model.helm.lm: none"
            )
        image_shape = image.shape
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
    ground_truth = ground_truth_size(config, core)
    model = ActorCritic(observation_space, action_space, config.model, helm_size, reconstruction, ground_truth, named)
    return model.to(device), helm


def environment_space(core: Any) -> str:
    """The environment's own observation space as one line: a gymnasium environment's (``core.layout.space``), not
    the Dict of ``visual_observation`` / ``vector_observation`` it is translated into for the model."""
    layout = getattr(core, "layout", None)
    space = layout.space if layout is not None else core.single_observation_space
    return " ".join(str(space).split())  # numpy pads the bounds of a Box with runs of spaces


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
    """Write ``state`` atomically with its size and checksum (:data:`CHECKPOINT_MAGIC`), read it back and check it,
    then keep only the ``keep`` newest checkpoints beside it (0: all): an older one goes only once this one is
    known to be whole."""
    path = Path(path)
    data = io.BytesIO()
    torch.save({"format": CHECKPOINT_FORMAT, **state}, data)
    payload = data.getvalue()
    header = json.dumps(content_record(payload), sort_keys=True).encode()
    atomic_write_bytes(path, b"".join((CHECKPOINT_MAGIC, header, b"\n", payload)))
    checked_payload(path)
    if keep:
        for old in sorted(path.parent.glob(CHECKPOINT_GLOB))[:-keep]:
            old.unlink()
    return path


def checked_payload(path: str | Path) -> bytes:
    """The payload of a checkpoint file after checking it against the size and SHA-256 its header records;
    :class:`DamagedCheckpoint` when the file is truncated, corrupted or not a checkpoint. A file written before
    checkpoints carried a checksum (a bare ``torch.save`` zip) is returned whole, unchecked."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as err:
        raise DamagedCheckpoint(f"{path} cannot be read: {err}") from err
    if raw.startswith(LEGACY_MAGIC):
        return raw
    if not raw.startswith(CHECKPOINT_MAGIC):
        raise DamagedCheckpoint(f"{path} is not a checkpoint (its first bytes are not {CHECKPOINT_MAGIC!r})")
    header, newline, payload = raw[len(CHECKPOINT_MAGIC) :].partition(b"\n")
    try:
        recorded = json.loads(header) if newline else None
    except ValueError:
        recorded = None
    if not isinstance(recorded, dict) or not {"bytes", "sha256"} <= set(recorded):
        raise DamagedCheckpoint(f"{path} is damaged: its header (size and checksum) is cut short or unreadable")
    if len(payload) != recorded["bytes"]:
        raise DamagedCheckpoint(
            f"{path} is damaged: {len(payload)} bytes of payload where its header records {recorded['bytes']} "
            "(truncated, or written over)"
        )
    if content_record(payload)["sha256"] != recorded["sha256"]:
        raise DamagedCheckpoint(f"{path} is damaged: its payload does not match the SHA-256 its header records")
    return payload


def checkpoint_damage(path: str | Path) -> str | None:
    """Why the checkpoint at ``path`` is damaged (:func:`checked_payload`'s message), or None when it is whole."""
    try:
        checked_payload(path)
    except DamagedCheckpoint as err:
        return str(err)
    return None


def read_checkpoint(path: str | Path) -> dict[str, Any]:
    """The state saved in a checkpoint, checked first (:func:`checked_payload`): a damaged file is never loaded."""
    payload = checked_payload(path)
    try:  # Loaded on the CPU: RNG states must stay CPU tensors; weights and optimizer state move to their device.
        state = torch.load(io.BytesIO(payload), map_location="cpu", weights_only=False)
    except Exception as err:  # noqa: BLE001 (an unchecked legacy file can fail in any way torch's unpickler fails)
        raise DamagedCheckpoint(f"{path} is damaged: torch.load failed ({type(err).__name__}: {err})") from err
    if not isinstance(state, dict) or state.get("format") != CHECKPOINT_FORMAT:
        found = state.get("format") if isinstance(state, dict) else type(state).__name__
        raise ValueError(f"{path}: checkpoint format {found!r}, expected {CHECKPOINT_FORMAT}")
    return state


def intact_checkpoint(run_dir: str | Path, usable: Any = None) -> tuple[Path, dict[str, Any], list[str]]:
    """The newest checkpoint of ``run_dir`` that is whole (:func:`read_checkpoint`) and, when given, passes
    ``usable(path, state)`` (which raises :class:`DamagedCheckpoint` otherwise), with its state and one line per
    newer checkpoint passed over (why). Those are renamed ``*.damaged``, out of the checkpoints' glob, so that no
    later pruning keeps them instead of good ones. :class:`DamagedCheckpoint` naming every file when none is
    usable; FileNotFoundError when there is no checkpoint."""
    paths = list_checkpoints(run_dir)
    if not paths:
        raise FileNotFoundError(f"{run_dir} holds no checkpoint to resume from (checkpoints/{CHECKPOINT_GLOB})")
    passed: list[str] = []
    for path in reversed(paths):
        try:
            state = read_checkpoint(path)
            if usable is not None:
                usable(path, state)
        except DamagedCheckpoint as err:
            passed.append(str(err))
            continue
        notes = []
        for line, damaged in zip(passed, reversed(paths), strict=False):
            aside = damaged.with_name(damaged.name + ".damaged")
            os.replace(damaged, aside)
            notes.append(f"{line}; moved to {aside.name}")
        return path, state, notes
    raise DamagedCheckpoint(f"{run_dir}: no intact checkpoint to resume from:\n  " + "\n  ".join(passed))


def check_checkpoint_config(state: dict[str, Any], config: Config, path: str | Path) -> int | None:
    """That the checkpoint at ``path`` was written by ``config`` (the run's ``config.yaml``), but for what a resume
    may change (:func:`agents.config.resume_may_change`): the settings no record depends on, and ``run.total_steps``
    raised since, i.e. the run was extended after this checkpoint (``train.py --resume DIR --set
    run.total_steps=N``). Returns the checkpoint's number of updates in that case, else None."""
    saved, current = _with_new_defaults(state["config"]), config_to_dict(config)
    changed = differing_keys(saved, current)
    refused = [key for key in changed if not resume_may_change(key)]
    if refused:
        keys = ", ".join(refused)
        raise ValueError(f"{path} was written by a different config than the run's config.yaml (differing: {keys})")
    if LENGTH_KEY not in changed:
        return None
    saved_steps = saved["run"]["total_steps"]
    saved_updates = saved_steps // config.batch_size
    if saved_updates > config.num_updates:
        raise ValueError(
            f"{path} belongs to a run of run.total_steps={saved_steps} ({saved_updates} updates), longer than the "
            f"run's config.yaml says ({config.run.total_steps}, {config.num_updates} updates): a run can be "
            "extended, not shortened"
        )
    return saved_updates if saved_updates < config.num_updates else None


def _with_new_defaults(saved: dict[str, Any]) -> dict[str, Any]:
    """A checkpoint's config with the fields added to the config since it was written, at their defaults (which keep
    the old behaviour), as ``config.yaml`` is read; as saved if the current code cannot read it."""
    try:
        return config_to_dict(config_from_dict(saved))
    except ValueError:
        return saved


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
    model, helm = build_agent(config, config.env.make_core(1), device)
    check_helm(helm, state, path)
    model.load_state_dict(state["model"])
    model.eval()
    acting = rollout_copy(model, config.run.precision)
    return Policy(config, acting, helm, state["update"], state["global_step"], run_dir, path)
