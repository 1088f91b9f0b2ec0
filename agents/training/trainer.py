"""The training loop: collect -> GAE -> epochs of minibatch updates -> log -> evaluate -> checkpoint.

The environments run in-process as one natively batched core, driven by the actor (:mod:`agents.policy.actor`), which
resets a finished slot right after the step that ended its episode with a seed drawn from the training range by the
trainer's own generator. Every ``eval.interval`` updates (and after the last one) the current policy plays the
novel seeds through :func:`agents.evaluation.loop.evaluate`; the records go to ``eval/episodes.csv`` and TensorBoard.

Resuming is exact: checkpoints are taken at update boundaries and hold, besides model, optimizer and every random
generator, the episode each slot is in (its seed and the actions taken since it started). On resume each slot is
reset with its seed and replayed, which reproduces the environment state because a slot's episode depends only on
its seed and actions (a digest of the observations checks this). With the same seed on CPU, a resumed run ends with
the same weights, logs and records as an uninterrupted one.

Faults (docs/reliability.md): a pre-emption signal (:mod:`agents.runtime.preemption`) ends the run after the update in
progress, with a checkpoint (:class:`Preempted`); a non-finite loss, gradient or weight stops it at that update
(:class:`TrainingDiverged`) and a failed write at that file (:class:`WriteFailed`), the newest checkpoint intact.
Every checkpoint records what ``training.csv`` and ``eval/episodes.csv`` held at its step
(:func:`agents.training.logs.run_records`), and a resume takes the newest checkpoint that is intact and matches them
(:func:`agents.policy.checkpoint.intact_checkpoint`).

A run can be lengthened when it resumes (``Trainer.resume(run_dir, ["run.total_steps=N"])``):
``config.yaml`` then holds the new length, ``run_info.json`` records the extension, and the schedules that decay over
the whole run go on from their current values to their final values at the new end (:meth:`Schedule.value`). A resume
may also change the settings no record depends on (progress bar, checkpoint interval and count, W&B:
:data:`agents.config.RESULT_NEUTRAL`); nothing else (:func:`agents.config.resume_may_change`, the one rule).
"""

from __future__ import annotations

import contextlib
import json
import os
import random
import sys
import time
from collections import deque
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from agents.analysis.digest import config_digest
from agents.analysis.metrics import metric_of
from agents.config import (
    Config,
    config_to_dict,
    dump_config,
    resume_changes,
    resume_config,
    sets_length,
)
from agents.evaluation.loop import evaluate
from agents.evaluation.records import record_means, seed_list, write_records
from agents.policy.actor import Actor, refresh_copy, rollout_copy
from agents.policy.checkpoint import (
    build_agent,
    check_checkpoint_config,
    check_helm,
    checkpoint_path,
    checkpoint_update,
    intact_checkpoint,
    latest_checkpoint,
    read_checkpoint,
    run_config,
    write_checkpoint,
)
from agents.runtime import faults
from agents.runtime.allocator import keep_freed_memory
from agents.runtime.devices import check_device
from agents.runtime.io import atomic_write_text, now, write_json_atomic
from agents.runtime.preemption import Preempted, StopRequests, signal_name
from agents.runtime.tracking import TrackingError, WandbWriter, scalar_writer, start_wandb
from agents.training.buffer import RolloutBuffer
from agents.training.logs import (
    TrainingLog,
    check_run_records,
    evaluation_records,
    extend_run,
    log_scalars,
    progress_bar,
    records_past,
    run_info,
    run_records,
    show_progress,
    summary_writer,
)
from agents.training.ppo import explained_variance, gae_advantages, ppo_update
from agents.training.sequences import split_sequences

RECENT_EPISODES = 100  # episodes behind the progress bar's "recent return"


class TrainingDiverged(RuntimeError):
    """A loss, gradient or parameter became NaN/inf; the message names the update and the last good checkpoint."""


class WriteFailed(RuntimeError):
    """A file of the run could not be written (a full disk, a failing device); the message names it and the newest
    checkpoint, from which the run resumes (the files written before stay whole: every write is atomic)."""


class Trainer:
    """Trains one config into one run directory (``train()``); ``Trainer.resume(run_dir)`` continues a run."""

    def __init__(self, config: Config, run_dir: str | Path) -> None:
        if config.grid:
            raise ValueError(
                "this config has a grid: block: train one of its runs with scripts/train.py --config FILE --only "
                "KEY=VALUE[,...], or all of them with scripts/sweep.py"
            )
        self.config = config
        self.run_dir = Path(run_dir)
        self.device = check_device(config.run.device, "run.device")
        faults.active_faults()  # a malformed MEMGYM_FAULT is refused here, before any work (FaultSpecError)
        torch.set_num_threads(config.run.torch_threads or os.cpu_count() or 1)
        if self.device.type == "cpu":
            keep_freed_memory()
        self.num_updates = config.num_updates
        self.update = 0
        self.global_step = 0
        # (at update, previous num_updates) of every time the run was lengthened: the schedules need them
        self.extensions: list[tuple[int, int]] = []
        self.extension: dict[str, Any] | None = None  # the extension made by Trainer.resume, if any (run_info record)
        self.resume_notes: list[str] = []  # damaged checkpoints Trainer.resume passed over, for the user
        self.resumed_from: Path | None = None  # the checkpoint Trainer.resume restored
        self.dropped: dict[str, int] = {}  # per record file, what the run logged past that checkpoint (dropped)
        # {key: [old, new]} of the settings no record depends on that Trainer.resume changed (run_info, config.yaml)
        self.settings_changed: dict[str, list[Any]] = {}

        seed = config.run.seed
        torch.manual_seed(seed)  # the weight init; every later draw uses the generators below
        seeds = np.random.SeedSequence(seed).spawn(3)
        self.episode_seed_rng = np.random.default_rng(seeds[0])
        self.shuffle_rng = np.random.default_rng(seeds[1])
        self.action_generator = torch.Generator(device=self.device)
        self.action_generator.manual_seed(int(seeds[2].generate_state(1)[0]))

        workers = config.run.workers
        self.core = config.env.make_core(workers)
        self.model, self.helm = build_agent(config, self.core, self.device)
        self.rollout_model = rollout_copy(self.model, config.run.precision)
        # The fused kernel updates all parameters at once: ~10x faster than the per-tensor loop on CPU.
        self.optimizer = torch.optim.AdamW(self.model.parameters(), lr=config.ppo.learning_rate.initial, fused=True)
        self.buffer = RolloutBuffer(
            workers,
            config.run.worker_steps,
            self.model.inputs,
            len(self.model.action_dims),
            self.model.record_shape,
            self.device,
            config.model.frame_stack,
            self.model.memory.history,
            self.model.memory.state_dtype,
            self.model.ground_truth_size,
        )
        self.actor = Actor(
            self.core,
            self.rollout_model,
            config,
            self.action_generator,
            self.helm,
            self.device,
            ground_truth=self.buffer.ground_truth is not None,
        )
        self.actor.start(self._episode_seeds(workers), seed_source=self._episode_seeds)
        self.recent_returns: deque[float] = deque(maxlen=RECENT_EPISODES)
        self.history: list[dict[str, float]] = []
        self._training_log: TrainingLog | None = None  # training.csv while train() runs
        self.eval_records: list[dict[str, Any]] = []
        self._eval_core: Any = None

    # ------------------------------------------------------------------------------------------------ public
    @classmethod
    def resume(cls, run_dir: str | Path, overrides: Sequence[str] = ()) -> Trainer:
        """The trainer of ``run_dir`` restored from its newest checkpoint. ``overrides`` (``key=value``) may raise
        ``run.total_steps``, and the run is then extended from that checkpoint on
        (:func:`agents.training.logs.extend_run`), finished or not, and change the settings no record depends on
        (:func:`agents.config.resume_config`: written to ``config.yaml`` and ``run_info.json`` when training goes on);
        any other key is a :class:`ConfigError` naming it, raised before anything is touched.

        A damaged checkpoint (truncated or corrupted), or one whose records (``training.csv``,
        ``eval/episodes.csv``) no longer hold what it recorded of them, is passed over for the newest intact one
        and moved aside (``resume_notes`` says which and why); :class:`DamagedCheckpoint` naming the files when
        none is intact. ``resumed_from`` and ``dropped`` say which checkpoint was restored and how much of what the
        run logged past it is dropped."""
        run_dir = Path(run_dir)
        saved = run_config(run_dir)
        config = resume_config(saved, overrides, run_dir / "config.yaml")
        path, state, notes = intact_checkpoint(run_dir, lambda found, saved: check_run_records(run_dir, found, saved))
        extension = None
        if sets_length(overrides):
            _, extension = extend_run(run_dir, saved, config.run.total_steps, checkpoint_update(path))
        trainer = cls(config, run_dir)
        trainer.load_checkpoint(path, state)
        trainer.extension = extension
        trainer.settings_changed = resume_changes(saved, config)
        trainer.resumed_from = path
        trainer.dropped = records_past(run_dir, trainer.global_step)
        trainer.resume_notes = [*notes, f"resuming from {path.name}"] if notes else []
        return trainer

    @property
    def finished(self) -> bool:
        """Whether every update of the run is done (a finished run's train() does nothing)."""
        return self.update >= self.num_updates

    @property
    def sequence_length(self) -> int | None:
        """Steps per training sequence: 1 without a memory module, None for whole episode pieces ('max')."""
        if self.model.memory.stateless:
            return 1  # no memory: every step is a sequence of its own, no padding exists
        length = self.config.ppo.sequence_length
        return None if length == "max" else int(length)

    def autocast(self) -> contextlib.AbstractContextManager:
        """The precision context of the training passes (bfloat16 autocast with ``run.precision: bf16``)."""
        enabled = self.config.run.precision == "bf16"
        return torch.autocast(self.device.type, dtype=torch.bfloat16, enabled=enabled)

    def train(self) -> list[dict[str, float]]:
        """Run the remaining updates; returns one metrics dict per update run by this call. A finished run is left
        exactly as it is (no resume record, no event file): lengthen it with ``Trainer.resume(dir, overrides)``.

        Stops with :class:`Preempted` after a pre-emption signal (:mod:`agents.runtime.preemption`: the update in
        progress finishes and is checkpointed first), :class:`TrainingDiverged` at a non-finite loss, gradient or
        parameter, and :class:`WriteFailed` when a file cannot be written; the newest checkpoint is intact in every
        case."""
        if self.finished:
            return []
        wandb_writer = self._start_tracking()  # first: a W&B that cannot start stops the run before any file
        try:
            with self._writing(self.run_dir / "run_info.json"):
                self._write_run_files()
            with self._writing(self.run_dir / "training.csv"):
                self._training_log = TrainingLog(self.run_dir / "training.csv", self.global_step)
            writer = scalar_writer(summary_writer(self.run_dir, self.global_step), wandb_writer)
        except BaseException:
            if wandb_writer is not None:
                wandb_writer.close()
            raise
        progress = progress_bar(self.config, self.global_step)
        try:
            with StopRequests() as stops:
                while self.update < self.num_updates:
                    metrics = self.train_update()
                    self.history.append(metrics)
                    with self._writing(self._training_log.path):
                        self._training_log.append(self._training_row(metrics))
                    last = self.update == self.num_updates
                    eval_interval = self.config.eval.interval
                    if eval_interval and (self.update % eval_interval == 0 or last):
                        metrics.update(self.evaluate_now())
                    log_scalars(writer, metrics, self.global_step)
                    show_progress(progress, metrics, self.recent_returns, self.config.batch_size)
                    interval = self.config.run.checkpoint_interval
                    saved = None
                    if last or (interval and self.update % interval == 0):
                        saved = self._checkpoint()
                    if stops.received is not None and not last:  # the safe point: this update is complete
                        saved = saved or self._checkpoint()
                        signum = stops.received
                        if not stops.pass_on():  # no earlier handler (submitit's) took it over: stop here
                            with self._writing(self.run_dir / "run_info.json"):
                                self._mark_stopped(signum)
                            raise Preempted(
                                f"stopped by {signal_name(signum)} after update {self.update} of {self.num_updates};"
                                f" checkpoint {saved} written: resume with scripts/train.py --resume {self.run_dir}",
                                signum,
                            )
        finally:
            self._training_log.close()
            self._training_log = None
            writer.close()
            if progress is not None:
                progress.close()
        if self.update == self.num_updates:
            with self._writing(self.run_dir / "run_info.json"):
                self._mark_finished()
        return self.history

    def _start_tracking(self) -> WandbWriter | None:
        """The W&B run (``run.wandb``), started before the run writes anything: :class:`TrackingError` saying that
        the run directory was left as it was when W&B cannot start."""
        new_run = self.update == 0
        try:
            return start_wandb(self.config, self.run_dir)
        except TrackingError as err:
            left = (
                f"nothing was written to {self.run_dir}"
                if new_run
                else f"the run is unchanged: resume it with scripts/train.py --resume {self.run_dir}"
            )
            raise type(err)(f"{err}; {left}") from err

    def _checkpoint(self) -> Path:
        with self._writing(checkpoint_path(self.run_dir, self.update)):
            return self.save_checkpoint()

    @contextlib.contextmanager
    def _writing(self, path: Path) -> Any:
        """Turn a failed write of ``path`` (``OSError``: a full disk, a failing fsync) into :class:`WriteFailed`."""
        try:
            yield
        except OSError as err:
            reason = f"[Errno {err.errno}] {err.strerror}" if err.errno else str(err)
            raise WriteFailed(
                f"training stopped at update {self.update}: writing {path} failed ({reason}); {self._kept()}; free "
                f"space or fix the device, then resume with scripts/train.py --resume {self.run_dir}"
            ) from err

    def _kept(self) -> str:
        last = latest_checkpoint(self.run_dir)
        return f"the last good checkpoint is {last}" if last else "no checkpoint was written yet"

    def evaluate_now(self) -> dict[str, float]:
        """Evaluate the current policy on the novel seeds (the config's ``eval`` block), keep and write the records
        (``eval/episodes.csv``); returns their means as ``eval/...`` scalars."""
        config = self.config
        seeds = seed_list(config.eval_seeds)
        slots = len(seeds) * config.eval.repetitions
        if self._eval_core is None:
            self._eval_core = config.env.make_core(slots)
        records = evaluate(
            self.rollout_model,
            self.helm,
            config,
            seeds,
            config.eval.repetitions,
            greedy=config.eval.greedy,
            sampling_seed=config.eval.seed,
            step=self.global_step,
            run=self.run_dir.name,
            device=self.device,
            core=self._eval_core,
        )
        self.eval_records = [r for r in self.eval_records if r["step"] != self.global_step] + records
        with self._writing(self.run_dir / "eval" / "episodes.csv"):
            write_records(self.run_dir / "eval" / "episodes.csv", self.eval_records)
        return {f"eval/{key}": value for key, value in record_means(records).items()}

    # ------------------------------------------------------------------------------------------- one update
    def train_update(self) -> dict[str, float]:
        """One update: collect a rollout, compute advantages, run the PPO epochs. Returns its metrics."""
        config, update = self.config, self.update
        learning_rate = self.schedule("learning_rate", update)
        entropy_coef = self.schedule("entropy_coef", update)
        clip = self.schedule("clip_range", update)
        for group in self.optimizer.param_groups:
            group["lr"] = learning_rate

        started = time.perf_counter()
        finished_episodes = self._collect_rollout()
        rollout_seconds = time.perf_counter() - started

        buffer = self.buffer
        with torch.inference_mode():
            memory = self.actor.memory
            _, last_values, _ = self.rollout_model.step(self.actor.inputs(), memory.recurrent, memory.episode_step)
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
        faults.signal_during(update + 1)
        if (value := faults.update_value(update + 1, "loss")) is not None:
            buffer.advantages.fill_(value)
            buffer.returns.fill_(value)
        sequences = split_sequences(buffer.terminated_numpy(), self.sequence_length)
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
                self.autocast,
            )
        except FloatingPointError as err:
            raise TrainingDiverged(f"training stopped at update {update + 1}: {err}; {self._kept()}") from err
        if (value := faults.update_value(update + 1, "params")) is not None:
            with torch.no_grad():
                next(self.model.parameters()).view(-1)[0] = value
        # The loss and gradient were finite, but the last optimizer step can still overflow a weight: checked here,
        # or the next rollout would sample from NaN probabilities
        bad = non_finite_parameters(self.model)
        if bad:
            raise TrainingDiverged(
                f"training stopped at update {update + 1}: non-finite parameters after its optimizer steps "
                f"({', '.join(bad[:3])}{', ...' if len(bad) > 3 else ''}); {self._kept()}"
            )
        refresh_copy(self.rollout_model, self.model)
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
        metrics.update(self._episode_metrics(finished_episodes))
        metrics["global_step"] = float(self.global_step)
        metrics["update"] = float(self.update)
        return metrics

    def schedule(self, name: str, update: int) -> float:
        """The value of the schedule ``ppo.<name>`` at ``update`` (0-based), this run's extensions included."""
        return getattr(self.config.ppo, name).value(update, self.num_updates, self.extensions)

    def _collect_rollout(self) -> list[dict[str, Any]]:
        """Fill the buffer with ``worker_steps`` decisions of every worker; returns the final infos of ended
        episodes."""
        buffer, actor, finished = self.buffer, self.actor, []
        memory = self.model.memory
        buffer.begin(actor.memory.stacks, memory.history_records(actor.memory.recurrent) if memory.history else None)
        for t in range(buffer.steps):
            decision = actor.decide()
            buffer.store(t, decision.newest, decision.episode_step)
            buffer.store_record(t, decision.record)
            buffer.actions[:, t] = decision.actions
            buffer.log_probs[:, t] = decision.log_probs
            buffer.values[:, t] = decision.values
            if buffer.ground_truth is not None:
                buffer.ground_truth[:, t] = decision.ground_truth
            outcome = actor.advance(decision)
            buffer.rewards[:, t] = outcome.rewards
            buffer.terminated[:, t] = outcome.terminated
            for info in outcome.finals.values():
                finished.append(info)
                self.recent_returns.append(info["reward"])
        return finished

    def _episode_seeds(self, count: int) -> list[int]:
        """Seeds of ``count`` new episodes, drawn from the training range (one draw per slot, in slot order)."""
        low, high = self.config.env.train_seeds
        return [int(self.episode_seed_rng.integers(low, high + 1)) for _ in range(count)]

    def _episode_metrics(self, finals: list[dict[str, Any]]) -> dict[str, float]:
        """Mean return, length and task metric of the episodes that ended, plus every numeric metric the environment
        reports (under ``env/``)."""
        if not finals:
            return {}
        metric = metric_of(self.config.env.id, self.config.env.metric)
        metrics = {
            "charts/episodic_return": float(np.mean([f["reward"] for f in finals])),
            "charts/episodic_length": float(np.mean([f["length"] for f in finals])),
            "charts/episodes": float(len(finals)),
            f"charts/{metric.name}": float(np.mean([metric.value(f) for f in finals])),
        }
        keys = sorted({key for f in finals for key, value in f.items() if _is_numeric(value)} - {"reward", "length"})
        for key in keys:
            values = [float(f[key]) for f in finals if key in f and _is_numeric(f[key])]
            metrics[f"env/{key}"] = float(np.mean(values))
        return metrics

    def _training_row(self, metrics: dict[str, float]) -> dict[str, Any]:
        metric = metric_of(self.config.env.id, self.config.env.metric)
        return {
            "run": self.run_dir.name,
            "method": self.config.method,
            "task": self.config.task,
            "env_id": self.config.env.id,
            "step": self.global_step,
            "return": metrics.get("charts/episodic_return", ""),
            "length": metrics.get("charts/episodic_length", ""),
            "metric": metrics.get(f"charts/{metric.name}", ""),
            "config_digest": config_digest(self.config),
        }

    # ------------------------------------------------------------------------------------------ checkpoints
    def save_checkpoint(self) -> Path:
        """Write ``checkpoints/update_NNNNNNN.pt`` atomically and prune old ones; returns the checkpoint's path.
        ``training.csv`` already holds this update's row (appended after every update); it is synced to disk here."""
        if non_finite_parameters(self.model):
            raise TrainingDiverged(f"non-finite weights at update {self.update}; no checkpoint written")
        state = {
            "update": self.update,
            "global_step": self.global_step,
            "config": config_to_dict(self.config),
            "model": self.model.state_dict(),
            "optimizer": self.optimizer.state_dict(),
            "schedules": {
                name: self.schedule(name, self.update) for name in ("learning_rate", "entropy_coef", "clip_range")
            },
            "extensions": [list(extension) for extension in self.extensions],
            "rng": {  # the global generators are unused after the init, but saved so code that uses them resumes too
                "torch": torch.get_rng_state(),
                "numpy": np.random.get_state(),  # noqa: NPY002
                "python": random.getstate(),
                "actions": self.action_generator.get_state(),
                "shuffle": self.shuffle_rng.bit_generator.state,
                "episode_seeds": self.episode_seed_rng.bit_generator.state,
            },
            "actor": self.actor.state(),
            "helm": None if self.helm is None else self.helm.fingerprint(),  # rebuilt from the config, not stored
            "recent_returns": list(self.recent_returns),
        }
        if self._training_log is not None:
            self._training_log.sync()
        # what the run's records held at this checkpoint: a resume refuses records truncated or corrupted since
        state["records"] = run_records(self.run_dir, self.global_step)
        keep = self.config.run.keep_checkpoints
        return write_checkpoint(checkpoint_path(self.run_dir, self.update), state, keep)

    def load_checkpoint(self, path: str | Path, state: dict[str, Any] | None = None) -> None:
        """Restore the trainer from the checkpoint at ``path`` (``state``: its content, when already read)."""
        state = read_checkpoint(path) if state is None else state
        lengthened_from = check_checkpoint_config(state, self.config, path)  # config.yaml may hold a longer run
        check_helm(self.helm, state, path)
        self.update, self.global_step = state["update"], state["global_step"]
        self.extensions = [(int(at), int(previous)) for at, previous in state.get("extensions", [])]
        if lengthened_from is not None:  # extended after this checkpoint was written: from its update on
            self.extensions.append((self.update, lengthened_from))
        self.model.load_state_dict(state["model"])
        refresh_copy(self.rollout_model, self.model)
        self.optimizer.load_state_dict(state["optimizer"])
        rng = state["rng"]
        torch.set_rng_state(rng["torch"])
        np.random.set_state(rng["numpy"])  # noqa: NPY002
        random.setstate(rng["python"])
        self.action_generator.set_state(rng["actions"])
        self.shuffle_rng.bit_generator.state = rng["shuffle"]
        self.episode_seed_rng.bit_generator.state = rng["episode_seeds"]
        self.actor.load_state(state["actor"], seed_source=self._episode_seeds)
        self.recent_returns = deque(state["recent_returns"], maxlen=RECENT_EPISODES)
        # What a killed run wrote after this checkpoint is dropped, so the files hold what an uninterrupted run holds
        # (training.csv's rows past it are dropped when train() opens the file: TrainingLog)
        self.eval_records = evaluation_records(self.run_dir / "eval" / "episodes.csv", self.global_step)

    # ------------------------------------------------------------------------------------------- run files
    def _mark_finished(self) -> None:
        """Say in run_info.json that the run is complete: a sweep then knows it without the checkpoints (which a
        committed copy of the run directory leaves out)."""
        self._edit_run_info(
            lambda info: info.update(finished={"time": now(), "update": self.update, "step": self.global_step})
        )

    def _mark_stopped(self, signum: int) -> None:
        """Say in run_info.json when and where this process stopped: the committed records then tell a run's wall
        time less its pauses (TensorBoard's event files, the other witness, are not committed)."""
        stop = {"time": now(), "update": self.update, "signal": signal_name(signum)}
        self._edit_run_info(lambda info: info.setdefault("stopped", []).append(stop))

    def _edit_run_info(self, change: Callable[[dict[str, Any]], object]) -> None:
        """Apply ``change`` to run_info.json's contents and write it back atomically."""
        info_path = self.run_dir / "run_info.json"
        info = json.loads(info_path.read_text())
        change(info)
        write_json_atomic(info_path, info, sort_keys=False)

    def _write_run_files(self) -> None:
        self.run_dir.mkdir(parents=True, exist_ok=True)
        config_path = self.run_dir / "config.yaml"
        if not config_path.exists() or self.settings_changed:  # a resume's new settings are the run's from now on
            atomic_write_text(config_path, dump_config(self.config))
        info_path = self.run_dir / "run_info.json"
        info = json.loads(info_path.read_text()) if info_path.exists() else run_info(self.config)
        if self.update > 0:
            resumed = {"time": now(), "update": self.update, "command": sys.argv}
            if self.settings_changed:
                resumed["changed"] = self.settings_changed
            info.setdefault("resumed", []).append(resumed)
        write_json_atomic(info_path, info, sort_keys=False)


# ----------------------------------------------------------------------------------------------- helpers
def non_finite_parameters(model: torch.nn.Module) -> list[str]:
    """The names of the parameters that hold a NaN or an infinity (one device sync)."""
    named = list(model.named_parameters())
    finite = torch.stack([torch.isfinite(p).all() for _, p in named]).cpu()
    return [name for (name, _), ok in zip(named, finite.tolist(), strict=True) if not ok]


def _is_numeric(value: Any) -> bool:
    return isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool)
