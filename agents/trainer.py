"""The training loop: collect -> GAE -> epochs of minibatch updates -> log -> checkpoint.

The environments run in-process as one natively batched core. The trainer resets a finished slot right after the
step that ended its episode, with a seed drawn from the training seed range by its own generator, and zeroes that
slot's memory state and previous action/reward.

Resuming is exact: checkpoints are taken at update boundaries and hold, besides model, optimizer and every random
generator, the episode each slot is in (its seed and the actions taken since it started). On resume each slot is
reset with its seed and replayed, which reproduces the environment state because a slot's episode depends only on
its seed and actions (a digest of the observations checks this). With the same seed on CPU, a resumed run ends with
the same weights as an uninterrupted one.
"""

from __future__ import annotations

import contextlib
import copy
import datetime
import hashlib
import io
import json
import math
import os
import platform
import random
import sys
import time
from collections import deque
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
import yaml

import envs
from agents.buffer import RolloutBuffer
from agents.config import Config, config_from_dict, config_to_dict, dump_config
from agents.io import atomic_write_bytes, now, provenance, write_json_atomic
from agents.models import ActorCritic, sample_actions
from agents.ppo import explained_variance, gae_advantages, ppo_update
from agents.sequences import split_sequences

CHECKPOINT_FORMAT = 1
RECENT_EPISODES = 100  # episodes behind the progress bar's "recent return"


class TrainingDiverged(RuntimeError):
    """A loss or gradient became NaN/inf; the message names the last good checkpoint."""


class Trainer:
    """Trains one config into one run directory (``train()``); ``Trainer.resume(run_dir)`` continues a run."""

    def __init__(self, config: Config, run_dir: str | Path) -> None:
        if config.grid:
            raise ValueError("this config has a grid: block; expand it with the sweep tool, train.py runs one config")
        self.config = config
        self.run_dir = Path(run_dir)
        self.device = _device(config.run.device)
        torch.set_num_threads(config.run.torch_threads or os.cpu_count() or 1)
        if self.device.type == "cpu":
            keep_freed_memory()
        self.num_updates = config.num_updates
        self.update = 0
        self.global_step = 0

        seed = config.run.seed
        torch.manual_seed(seed)  # the weight init; every later draw uses the generators below
        seeds = np.random.SeedSequence(seed).spawn(3)
        self.episode_seed_rng = np.random.default_rng(seeds[0])
        self.shuffle_rng = np.random.default_rng(seeds[1])
        self.action_generator = torch.Generator(device=self.device)
        self.action_generator.manual_seed(int(seeds[2].generate_state(1)[0]))

        self.core = envs.make_core(config.env.id, config.run.workers, config.env.options)
        self.action_space = self.core.single_action_space
        self.model = ActorCritic(self.core.single_observation_space, self.action_space, config.model).to(self.device)
        self.rollout_model = self._make_rollout_model()
        # The fused kernel updates all parameters at once: ~10x faster than the per-tensor loop on CPU.
        self.optimizer = torch.optim.AdamW(self.model.parameters(), lr=config.ppo.learning_rate.initial, fused=True)
        branches = len(self.model.action_dims)
        state_shape = self.model.state_shape
        self.buffer = RolloutBuffer(
            config.run.workers, config.run.worker_steps, self.model.inputs, branches, state_shape, self.device
        )
        self.staging = _HostStaging(self.buffer.inputs, self.device)

        workers = config.run.workers
        self.memory_state = self.model.initial_state(workers, self.device)
        self.previous_action = torch.zeros((workers, branches), dtype=torch.int64, device=self.device)
        self.previous_reward = torch.zeros(workers, device=self.device)
        self.episode_seeds = [0] * workers
        self.episode_actions: list[list[np.ndarray]] = [[] for _ in range(workers)]
        self._start_episodes(list(range(workers)))
        self.staging.load(self.core.observations())
        self.recent_returns: deque[float] = deque(maxlen=RECENT_EPISODES)
        self.history: list[dict[str, float]] = []

    # ------------------------------------------------------------------------------------------------ public
    @classmethod
    def resume(cls, run_dir: str | Path) -> Trainer:
        """The trainer of ``run_dir`` restored from its newest checkpoint."""
        run_dir = Path(run_dir)
        config_path = run_dir / "config.yaml"
        if not config_path.is_file():
            raise FileNotFoundError(f"{run_dir} is not a run directory: {config_path} is missing")
        checkpoint_path = latest_checkpoint(run_dir)
        if checkpoint_path is None:
            raise FileNotFoundError(f"{run_dir} holds no checkpoint to resume from (checkpoints/update_*.pt)")
        trainer = cls(config_from_dict(yaml.safe_load(config_path.read_text())), run_dir)
        trainer.load_checkpoint(checkpoint_path)
        return trainer

    def train(self) -> list[dict[str, float]]:
        """Run the remaining updates; returns one metrics dict per update run by this call."""
        self._write_run_files()
        writer = _summary_writer(self.run_dir, self.global_step)
        progress = _progress_bar(self.config, self.global_step)
        try:
            while self.update < self.num_updates:
                metrics = self.train_update()
                self.history.append(metrics)
                _log(writer, metrics, self.global_step)
                _show(progress, metrics, self.recent_returns, self.config.batch_size)
                interval = self.config.run.checkpoint_interval
                if self.update == self.num_updates or (interval and self.update % interval == 0):
                    self.save_checkpoint()
        finally:
            writer.close()
            if progress is not None:
                progress.close()
        return self.history

    # ------------------------------------------------------------------------------------------- one update
    def train_update(self) -> dict[str, float]:
        """One update: collect a rollout, compute advantages, run the PPO epochs. Returns its metrics."""
        config, update = self.config, self.update
        learning_rate = config.ppo.learning_rate.value(update, self.num_updates)
        entropy_coef = config.ppo.entropy_coef.value(update, self.num_updates)
        clip = config.ppo.clip_range.value(update, self.num_updates)
        for group in self.optimizer.param_groups:
            group["lr"] = learning_rate

        started = time.perf_counter()
        finished_episodes = self._collect_rollout()
        rollout_seconds = time.perf_counter() - started

        buffer = self.buffer
        with torch.inference_mode():
            _, last_values, _ = self.rollout_model.step(self._current_inputs(), self.memory_state)
        buffer.advantages.copy_(
            gae_advantages(
                buffer.rewards,
                buffer.values,
                buffer.terminated,
                last_values.float(),
                config.ppo.gamma,
                config.ppo.gae_lambda,
            )
        )
        torch.add(buffer.advantages, buffer.values, out=buffer.returns)
        sequences = split_sequences(buffer.terminated_numpy(), self._sequence_length())
        try:
            losses = ppo_update(
                self.model,
                self.optimizer,
                buffer,
                sequences,
                config.ppo,
                clip,
                entropy_coef,
                self.shuffle_rng,
                self._autocast,
            )
        except FloatingPointError as err:
            last = latest_checkpoint(self.run_dir)
            kept = f"the last good checkpoint is {last}" if last else "no checkpoint was written yet"
            raise TrainingDiverged(f"training stopped at update {update + 1}: {err}; {kept}") from err
        self._refresh_rollout_model()
        self.update += 1
        self.global_step += config.batch_size
        seconds = time.perf_counter() - started

        metrics: dict[str, float] = {
            "charts/SPS": config.batch_size / seconds,
            "charts/rollout_SPS": config.batch_size / rollout_seconds,
            "charts/learning_rate": learning_rate,
            "charts/entropy_coef": entropy_coef,
            "charts/clip_range": clip,
            "charts/sequences": float(len(sequences)),
            "losses/explained_variance": explained_variance(buffer.values.flatten(), buffer.returns.flatten()),
        }
        metrics.update({f"losses/{name}": value for name, value in losses.items()})
        metrics.update(_episode_metrics(finished_episodes))
        metrics["global_step"] = float(self.global_step)
        metrics["update"] = float(self.update)
        return metrics

    def _collect_rollout(self) -> list[dict[str, Any]]:
        """Fill the buffer with ``worker_steps`` steps of every worker; returns the final infos of ended episodes."""
        buffer, finished = self.buffer, []
        with torch.inference_mode():
            for t in range(buffer.steps):
                inputs = self._current_inputs()
                for name, value in inputs.items():
                    buffer.inputs[name][:, t] = value
                buffer.memory_states[:, t] = self.memory_state
                logits, values, next_state = self.rollout_model.step(inputs, self.memory_state)
                actions, log_probs = sample_actions(logits, self.action_generator)
                buffer.actions[:, t] = actions
                buffer.log_probs[:, t] = log_probs
                buffer.values[:, t] = values

                actions_host = actions.cpu().numpy()
                rewards, terminated, finals = self.core.step(self._env_actions(actions_host))
                rewards_t = torch.from_numpy(rewards.astype(np.float32)).to(self.device)
                terminated_t = torch.from_numpy(terminated).to(self.device)
                buffer.rewards[:, t] = rewards_t
                buffer.terminated[:, t] = terminated_t

                # The step's memory output carries on unless the episode ended: a new episode starts from zeros.
                alive = ~terminated_t
                self.memory_state = next_state.float() * alive.view(-1, *([1] * len(self.model.state_shape)))
                self.previous_action = actions * alive.unsqueeze(-1)
                self.previous_reward = rewards_t * alive
                for slot in range(buffer.workers):
                    self.episode_actions[slot].append(actions_host[slot])
                for info in finals.values():
                    finished.append(info)
                    self.recent_returns.append(info["reward"])
                if finals:
                    self._start_episodes(list(finals))
                self.staging.load(self.core.observations())
        return finished

    def _current_inputs(self) -> dict[str, torch.Tensor]:
        inputs = dict(self.staging.current)
        if "previous_action" in self.model.inputs:
            inputs["previous_action"] = self.previous_action
        if "previous_reward" in self.model.inputs:
            inputs["previous_reward"] = self.previous_reward
        return inputs

    def _start_episodes(self, slots: list[int]) -> None:
        """New episodes in ``slots``, each with a seed drawn from the training range (one draw per slot, in order)."""
        low, high = self.config.env.train_seeds
        seeds = [int(self.episode_seed_rng.integers(low, high + 1)) for _ in slots]
        self.core.reset_slots(slots, seeds)
        for slot, seed in zip(slots, seeds, strict=True):
            self.episode_seeds[slot] = seed
            self.episode_actions[slot] = []

    def _env_actions(self, actions: np.ndarray) -> np.ndarray:
        """(workers, branches) -> the env's layout: (workers,) for Discrete, (workers, branches) otherwise."""
        return actions[:, 0] if isinstance(self.action_space, gym.spaces.Discrete) else actions

    def _sequence_length(self) -> int | None:
        if self.config.model.memory == "none":
            return 1  # no recurrence: every step is a sequence of its own, no padding exists
        length = self.config.ppo.sequence_length
        return None if length == "max" else int(length)

    def _make_rollout_model(self) -> ActorCritic:
        """The model that acts in the rollout. With bf16 it is a bfloat16 copy of the weights, refreshed after every
        update: acting at a batch of one step per worker is bound by reading the weights, and autocast would cast
        them anew at every step. With fp32 it is the model itself."""
        if self.config.run.precision != "bf16":
            return self.model
        return copy.deepcopy(self.model).to(torch.bfloat16).requires_grad_(False)

    def _refresh_rollout_model(self) -> None:
        if self.rollout_model is not self.model:
            with torch.no_grad():
                for low, weight in zip(self.rollout_model.parameters(), self.model.parameters(), strict=True):
                    low.copy_(weight)

    def _autocast(self) -> contextlib.AbstractContextManager:
        enabled = self.config.run.precision == "bf16"
        return torch.autocast(self.device.type, dtype=torch.bfloat16, enabled=enabled)

    # ------------------------------------------------------------------------------------------ checkpoints
    def save_checkpoint(self) -> Path:
        """Write ``checkpoints/update_NNNNNNN.pt`` atomically and prune old ones; returns its path."""
        if not all(torch.isfinite(p).all() for p in self.model.parameters()):
            raise TrainingDiverged(f"non-finite weights at update {self.update}; no checkpoint written")
        state = {
            "format": CHECKPOINT_FORMAT,
            "update": self.update,
            "global_step": self.global_step,
            "config": config_to_dict(self.config),
            "model": self.model.state_dict(),
            "optimizer": self.optimizer.state_dict(),
            "schedules": {
                "learning_rate": self.config.ppo.learning_rate.value(self.update, self.num_updates),
                "entropy_coef": self.config.ppo.entropy_coef.value(self.update, self.num_updates),
                "clip_range": self.config.ppo.clip_range.value(self.update, self.num_updates),
            },
            "rng": {  # the global generators are unused after the init, but saved so code that uses them resumes too
                "torch": torch.get_rng_state(),
                "numpy": np.random.get_state(),  # noqa: NPY002
                "python": random.getstate(),
                "actions": self.action_generator.get_state(),
                "shuffle": self.shuffle_rng.bit_generator.state,
                "episode_seeds": self.episode_seed_rng.bit_generator.state,
            },
            "env": {
                "seeds": list(self.episode_seeds),
                "actions": [np.array(a) for a in self.episode_actions],
                "observation_digest": self._observation_digest(),
            },
            "rollout": {
                "memory_state": self.memory_state.clone(),
                "previous_action": self.previous_action.clone(),
                "previous_reward": self.previous_reward.clone(),
            },
            "recent_returns": list(self.recent_returns),
        }
        directory = self.run_dir / "checkpoints"
        directory.mkdir(parents=True, exist_ok=True)
        path = directory / f"update_{self.update:07d}.pt"
        buffer = io.BytesIO()
        torch.save(state, buffer)
        atomic_write_bytes(path, buffer.getvalue())
        keep = self.config.run.keep_checkpoints
        if keep:
            for old in sorted(directory.glob("update_*.pt"))[:-keep]:
                old.unlink()
        return path

    def load_checkpoint(self, path: str | Path) -> None:
        # Loaded on the CPU: RNG states must stay CPU tensors; weights and optimizer state move to their device.
        state = torch.load(path, map_location="cpu", weights_only=False)
        if state.get("format") != CHECKPOINT_FORMAT:
            raise ValueError(f"{path}: checkpoint format {state.get('format')!r}, expected {CHECKPOINT_FORMAT}")
        if state["config"] != config_to_dict(self.config):
            raise ValueError(f"{path} was written by a different config than {self.run_dir / 'config.yaml'}")
        self.update, self.global_step = state["update"], state["global_step"]
        self.model.load_state_dict(state["model"])
        self._refresh_rollout_model()
        self.optimizer.load_state_dict(state["optimizer"])
        rng = state["rng"]
        torch.set_rng_state(rng["torch"])
        np.random.set_state(rng["numpy"])  # noqa: NPY002
        random.setstate(rng["python"])
        self.action_generator.set_state(rng["actions"])
        self.shuffle_rng.bit_generator.state = rng["shuffle"]
        self.episode_seed_rng.bit_generator.state = rng["episode_seeds"]
        self._replay_episodes(state["env"]["seeds"], state["env"]["actions"])
        if self._observation_digest() != state["env"]["observation_digest"]:
            raise RuntimeError(
                f"replaying the episodes of {path} did not reproduce the environment state: "
                f"{self.config.env.id} is not deterministic given seed and actions, so the run cannot resume exactly"
            )
        rollout = state["rollout"]
        self.memory_state = rollout["memory_state"].to(self.device)
        self.previous_action = rollout["previous_action"].to(self.device)
        self.previous_reward = rollout["previous_reward"].to(self.device)
        self.recent_returns = deque(state["recent_returns"], maxlen=RECENT_EPISODES)

    def _replay_episodes(self, seeds: list[int], actions: list[np.ndarray]) -> None:
        """Reset every slot with its episode's seed and step it through the episode's actions (in lockstep)."""
        self.core.reset_slots(range(len(seeds)), seeds)
        for slot, seed in enumerate(seeds):
            self.episode_seeds[slot] = seed
            self.episode_actions[slot] = list(actions[slot])
        longest = max((len(a) for a in actions), default=0)
        for t in range(longest):
            slots = np.array([k for k, a in enumerate(actions) if len(a) > t], dtype=np.int64)
            step_actions = np.stack([actions[k][t] for k in slots])
            _, terminated, _ = self.core.step(self._env_actions(step_actions), idx=slots)
            if terminated.any():
                raise RuntimeError("an episode ended during checkpoint replay: the environment is not deterministic")
        self.staging.load(self.core.observations())

    def _observation_digest(self) -> str:
        digest = hashlib.sha256()
        for name in sorted(self.staging.current):
            digest.update(self.staging.current[name].cpu().numpy().tobytes())
        return digest.hexdigest()

    # ------------------------------------------------------------------------------------------- run files
    def _write_run_files(self) -> None:
        self.run_dir.mkdir(parents=True, exist_ok=True)
        config_path = self.run_dir / "config.yaml"
        if not config_path.exists():
            atomic_write_bytes(config_path, dump_config(self.config).encode())
        info_path = self.run_dir / "run_info.json"
        info = json.loads(info_path.read_text()) if info_path.exists() else run_info(self.config)
        if self.update > 0:
            info.setdefault("resumed", []).append({"time": now(), "update": self.update, "command": sys.argv})
        write_json_atomic(info_path, info, sort_keys=False)


# ----------------------------------------------------------------------------------------------- helpers
class _HostStaging:
    """The current observation of every worker, on the training device (``current``: name -> (workers, ...)).

    On CUDA the numpy arrays go through pinned host tensors and asynchronous copies. Reusing a pinned tensor is
    safe because every rollout step synchronises (the sampled actions come back to the host) before it is refilled.
    """

    KEYS = {"visual_observation": "image", "vector_observation": "vector"}

    def __init__(self, buffer_inputs: dict[str, torch.Tensor], device: torch.device) -> None:
        names = [name for name in ("image", "vector") if name in buffer_inputs]
        self.current = {name: torch.zeros_like(buffer_inputs[name][:, 0]) for name in names}
        self.pinned = None
        if device.type == "cuda":
            self.pinned = {name: torch.zeros_like(t, device="cpu").pin_memory() for name, t in self.current.items()}

    def load(self, observations: np.ndarray | dict[str, np.ndarray]) -> None:
        """Make the observations of all workers (as ``BatchedCore.observations()`` returns them) current."""
        if isinstance(observations, np.ndarray):
            observations = {"visual_observation": observations}
        for key, array in observations.items():
            name = self.KEYS[key]
            target = self.current[name]
            source = torch.from_numpy(array).reshape(target.shape)
            if self.pinned is None:
                target.copy_(source)
            else:
                self.pinned[name].copy_(source)
                target.copy_(self.pinned[name], non_blocking=True)


def _episode_metrics(finals: list[dict[str, Any]]) -> dict[str, float]:
    """Mean return and length of the episodes that ended, plus every numeric metric the environment reports."""
    if not finals:
        return {}
    metrics = {
        "charts/episodic_return": float(np.mean([f["reward"] for f in finals])),
        "charts/episodic_length": float(np.mean([f["length"] for f in finals])),
        "charts/episodes": float(len(finals)),
    }
    keys = sorted({key for f in finals for key, value in f.items() if _is_numeric(value)} - {"reward", "length"})
    for key in keys:
        values = [float(f[key]) for f in finals if key in f and _is_numeric(f[key])]
        metrics[f"env/{key}"] = float(np.mean(values))
    return metrics


def _is_numeric(value: Any) -> bool:
    return isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool)


def _log(writer: Any, metrics: dict[str, float], step: int) -> None:
    for name, value in metrics.items():
        if "/" in name and math.isfinite(value):
            writer.add_scalar(name, value, step)


def _show(progress: Any, metrics: dict[str, float], recent_returns: deque, batch_size: int) -> None:
    if progress is None:
        return
    progress.update(batch_size)
    recent = f"{np.mean(recent_returns):.3f}" if recent_returns else "-"
    progress.set_postfix(SPS=f"{metrics['charts/SPS']:.0f}", recent_return=recent, refresh=False)


def _progress_bar(config: Config, initial: int) -> Any:
    if not config.run.progress_bar:
        return None
    from tqdm import tqdm

    total = config.num_updates * config.batch_size
    return tqdm(total=total, initial=initial, unit="step", unit_scale=True, dynamic_ncols=True)


def _summary_writer(run_dir: Path, step: int) -> Any:
    from torch.utils.tensorboard import SummaryWriter

    # purge_step drops events a killed run logged after its last checkpoint, so curves stay single-valued
    return SummaryWriter(log_dir=str(run_dir), purge_step=step if step > 0 else None)


# glibc's mallopt parameters (malloc.h) and their values here: blocks up to 32 MiB (the largest mmap threshold glibc
# accepts) come from the heap, and the heap keeps up to 1 GiB of freed memory instead of returning it to the system.
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
_MMAP_THRESHOLD_BYTES, _TRIM_THRESHOLD_BYTES = 32 << 20, 1 << 30


def keep_freed_memory() -> bool:
    """Let the C allocator reuse freed memory for torch's CPU tensors instead of handing it back to the system.

    torch allocates each minibatch's activations and gradients anew (megabytes each). glibc serves such blocks with
    fresh mmap pages and unmaps them when freed, so every minibatch pays for tens of thousands of page faults and
    cold pages (measured: ~45k faults per update of the MortarMayhemB-Grid benchmark; ~25k with this). Returns
    whether the setting took effect (glibc only; elsewhere nothing changes).
    """
    if sys.platform != "linux" or platform.libc_ver()[0] != "glibc":
        return False
    import ctypes

    try:
        libc = ctypes.CDLL("libc.so.6")
    except OSError:
        return False
    return bool(
        libc.mallopt(_M_MMAP_THRESHOLD, _MMAP_THRESHOLD_BYTES)
        and libc.mallopt(_M_TRIM_THRESHOLD, _TRIM_THRESHOLD_BYTES)
    )


def _device(name: str) -> torch.device:
    device = torch.device(name)
    if device.type == "cuda" and not torch.cuda.is_available():
        raise ValueError(f"run.device={name!r} but CUDA is not available here; use run.device=cpu")
    return device


def latest_checkpoint(run_dir: str | Path) -> Path | None:
    """The newest ``checkpoints/update_*.pt`` of a run directory, or None."""
    paths = sorted((Path(run_dir) / "checkpoints").glob("update_*.pt"))
    return paths[-1] if paths else None


def run_info(config: Config) -> dict[str, Any]:
    """Seed, run size and provenance (versions, git revision, machine) of a run (``run_info.json``)."""
    return {"seed": config.run.seed, "num_updates": config.num_updates, "batch_size": config.batch_size, **provenance()}


def default_run_dir(config_path: str | Path, seed: int, root: str | Path = "runs") -> Path:
    """``runs/<config name>/<timestamp>-seed<seed>``; the name is the path below ``configs/`` without suffix."""
    path = Path(config_path).resolve()
    parts = path.with_suffix("").parts
    name = "/".join(parts[parts.index("configs") + 1 :]) if "configs" in parts[:-1] else path.stem
    stamp = datetime.datetime.now().strftime("%Y%m%d-%H%M%S")
    return Path(root) / name / f"{stamp}-seed{seed}"
