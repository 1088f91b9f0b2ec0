"""Typed, documented training configuration loaded from YAML.

A config file has the blocks ``env``, ``model``, ``ppo``, ``run`` and ``eval`` (and an optional ``grid`` that
``scripts/sweep.py`` expands into runs: see "Grids" below); every block is a dataclass below and every field documents
itself. Loading is strict: an unknown key fails with the
closest valid name, a value of the wrong type or outside its range fails with what would have been valid.
Command-line overrides (``--set ppo.gamma=0.995``) are parsed as YAML scalars and validated the same way.

Example::

    env:   {id: ProofOfMemory-v0, options: {delay: 4}}
    model: {memory: gru, memory_size: 64, hidden_size: 64}
    ppo:   {learning_rate: {initial: 3.0e-4, final: 1.0e-4}, sequence_length: max}
    run:   {total_steps: 200000, workers: 16, worker_steps: 64, seed: 1}

Grids. A ``grid:`` block turns one file into a set of runs (one figure panel): the product of its axes.

* A **plain axis** is a dotted key with a list of values: ``run.seed: [0, 1, 2]``, ``ppo.gamma: [0.99, 0.995]``, or a
  whole block ``model.helm: [{lm: none}, {lm: random}]`` (a mapping value replaces that block; keys it omits take
  their defaults, not the base file's).
* A **named axis** (``method`` or ``task``) maps names to bundles of overrides, so that one value sets several keys::

      grid:
        method:
          ppo:    {model.memory: none}
          stack4: {model.memory: none, model.frame_stack: 4}
        task:
          mmact_grid: {env.id: MortarMayhemB-Grid-v0, env.options: {}}
        run.seed: [0, 1, 2, 3, 4]

  A bundle sets ``run.method`` / ``run.task`` to its name (the names in records and plots), then its own keys.
* ``panel:`` names the panel (default: the file's stem); ``slurm:`` holds the cluster settings of the sweep
  (:class:`SlurmConfig`).

Override order, lowest first: the base file (everything outside ``grid``) < the bundles, axis by axis in the order
the file lists the named axes (a bundle's keys in its own order) < the plain axes, in file order < command-line
``--set`` overrides. ``--set grid.AXIS=VALUE`` replaces an axis (``--set grid.run.seed=[0]``) and
``--set grid.slurm.KEY=VALUE`` one cluster setting, before the grid is expanded. Loading a grid config expands it and
validates every point (:func:`expand_grid`): an error names the point, the axis and bundle, and the key.
"""

from __future__ import annotations

import dataclasses
import difflib
import hashlib
import itertools
import json
import math
import numbers
import re
import types
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Union, get_args, get_origin, get_type_hints

import yaml

import envs

NO_LM = "none"
DEFAULT_EVAL_SEEDS = 30  # the paper: 30 novel seeds x 5 repetitions


class ConfigError(ValueError):
    """A config key or value is invalid; the message names the key and what would have been valid."""


def param(default: Any, doc: str, low: float | None = None, high: float | None = None, expect: str = "") -> Any:
    """A config field with its documentation, (inclusive) numeric bounds and, for unions, what it expects."""
    factory = (lambda: default.copy()) if isinstance(default, dict | list) else None
    meta = {"doc": doc, "low": low, "high": high, "expect": expect}
    if factory is not None:
        return field(default_factory=factory, metadata=meta)
    if dataclasses.is_dataclass(default):
        return field(default_factory=lambda: dataclasses.replace(default), metadata=meta)
    return field(default=default, metadata=meta)


@dataclass
class Schedule:
    """A value that decays linearly from ``initial`` to ``final`` over ``decay_updates`` PPO updates.

    In YAML a plain number is a constant; ``{initial: 3.0e-4, final: 1.0e-4}`` decays over the whole run. When a run
    is lengthened (``train.py --resume DIR --set run.total_steps=N``), a schedule that decays over the whole run goes
    on from the value it has reached to ``final`` at the new end (see :meth:`value`).
    """

    initial: float = param(0.0, "value at the first update", low=0.0)
    final: float | None = param(None, "value reached after decay_updates updates (null: constant)", low=0.0)
    decay_updates: int | None = param(None, "updates until final is reached (null: the whole run)", low=1)

    def value(self, update: int, num_updates: int, extensions: Sequence[tuple[int, int]] = ()) -> float:
        """The value used by update ``update`` (0-based) of a run of ``num_updates`` updates.

        ``extensions``: ``(at_update, previous_num_updates)`` for every time the run was lengthened, oldest first.
        From ``at_update`` on, a schedule that decays over the whole run goes linearly from the value it had reached
        there to ``final`` at the new end, so it never jumps back up (a finished run that is extended stays at
        ``final``). ``decay_updates`` is a number of updates, which an extension does not move."""
        if self.final is None:
            return self.initial
        if self.decay_updates:
            return self.initial + (self.final - self.initial) * min(update / self.decay_updates, 1.0)
        starts = [0, *(at for at, _ in extensions)]
        ends = [*(previous for _, previous in extensions), num_updates]
        value = self.initial
        for k, (start, end) in enumerate(zip(starts, ends, strict=True)):
            until = update if k + 1 == len(starts) or update < starts[k + 1] else starts[k + 1]
            value = value + (self.final - value) * min((until - start) / (end - start), 1.0)
            if until == update:
                break
        return value


@dataclass
class MetricConfig:
    """The task's metric when the metric table (agents/metrics.py) has none for the env id, or to replace it: an
    entry of the final info (e.g. a success flag), with its plot label and range. Empty key: the table's metric, or
    the episode return for an id it does not know."""

    key: str = param("", "final-info entry that is the task's metric (empty: the table's, else the return)")
    label: str = param("", "axis label of plots (empty: the key)")
    low: float | None = param(None, "smallest value the metric takes (null: unbounded)")
    high: float | None = param(None, "largest value the metric takes (null: unbounded)")


@dataclass
class EnvConfig:
    """Which environment to train on and how its episodes are seeded. Besides this project's ids (envs.ENV_IDS, run
    as natively batched cores), any gymnasium id works: a registered one or "module:EnvId" (see docs/gymnasium.md)."""

    id: str = param("ProofOfMemory-v0", "environment id: envs.ENV_IDS, a gymnasium id or 'module:EnvId'")
    options: dict[str, Any] = param({}, "reset options of the environment (its own names and ranges)")
    train_seeds: list[int] = param([0, 99_999], "inclusive range [low, high] that episode seeds are drawn from")
    frame_skip: int = param(
        1, "env steps per decision: the action is repeated, rewards summed, an episode end stops the repeat", low=1
    )
    make_kwargs: dict[str, Any] = param({}, "keyword arguments of gymnasium.make (gymnasium environments)")
    wrappers: list[Any] = param(
        [], "wrappers applied in order to each copy: 'module:Wrapper' or {path: 'module:Wrapper', kwargs: {...}}"
    )
    vectorization: str = param("sync", "how a gymnasium environment's copies run: 'sync' (one process) or 'async'")
    image_layout: str = param("hwc", "layout of a gymnasium environment's uint8 image: 'hwc' or 'chw'")
    check_seeding: bool = param(True, "refuse a gymnasium environment whose reset ignores the seed (false: warn)")
    metric: MetricConfig = param(MetricConfig(), "the task's metric: an entry of the final info (see MetricConfig)")

    def make_core(self, num_envs: int) -> Any:
        """The batched core of this environment with ``num_envs`` slots (a GymnasiumCore for gymnasium ids)."""
        return envs.make_core(
            self.id,
            num_envs,
            self.options,
            make_kwargs=self.make_kwargs,
            wrappers=self.wrappers,
            vectorization=self.vectorization,
            image_layout=self.image_layout,
            check_seeding=self.check_seeding,
        )

    @property
    def native(self) -> bool:
        """Whether this runs as one of this project's own cores (its options have specs and defaults)."""
        return self.id in envs.ENV_IDS and not self.make_kwargs and not self.wrappers


@dataclass
class HelmConfig:
    """The HELM branch: grayscale frame -> random projection -> frozen Hopfield retrieval over a language model's
    token embeddings -> the frozen causal transformer with a memory of the episode's last ``mem_len`` steps.
    Its output joins the CNN features; it is computed once during the rollout and cached (agents/helm.py)."""

    lm: str = param(NO_LM, "'none' (no branch), 'random' (a seeded random transformer), a hub name or a local dir")
    beta: float = param(1000.0, "inverse temperature of the Hopfield retrieval (the paper's 1000)", low=0.0)
    mem_len: int = param(128, "steps of the current episode the transformer attends to", low=1)
    seed: int = param(0, "seed of the random projection (and of the weights when lm is 'random')", low=0)
    random_layers: int = param(4, "layers of the 'random' transformer (a Pythia-shaped GPT-NeoX)", low=1)
    random_width: int = param(256, "embedding width of the 'random' transformer", low=8)
    random_heads: int = param(4, "attention heads of the 'random' transformer", low=1)
    random_vocab: int = param(8192, "token-embedding rows of the 'random' transformer", low=2)

    @property
    def enabled(self) -> bool:
        return self.lm != NO_LM


@dataclass
class TrxlConfig:
    """The Transformer-XL memory (``model.memory: trxl``, agents/memory/transformer.py): sequence-to-one blocks whose
    query is the current step and whose keys and values are the cached inputs of that block at the previous
    ``memory_length`` steps of the same episode."""

    layers: int = param(3, "transformer blocks", low=1)
    heads: int = param(4, "attention heads (dim must be a multiple)", low=1)
    dim: int = param(384, "width of the blocks (the memory's output size)", low=1)
    memory_length: int = param(119, "steps of the episode before the current one that a step attends to", low=1)
    positional_encoding: str = param(
        "relative",
        "'relative' (sinusoidal, by distance to the current step: any episode length), 'absolute' (sinusoidal) or "
        "'learned' (by episode step, refused past positional_size), or 'none'",
    )
    positional_size: int = param(
        1024, "episode steps the 'absolute' and 'learned' encodings cover (a longer episode is an error)", low=1
    )
    layer_norm: str = param("pre", "'pre', 'post' or 'none'")
    gating: bool = param(False, "GTrXL: GRU gates in place of the residual connections")
    gating_bias: float = param(2.0, "GTrXL gate bias (a positive bias starts the blocks near the identity)")
    shared_head_projections: bool = param(
        False, "CleanRL's variant: one (dim/heads)^2 projection shared by all heads, instead of full dim^2 ones"
    )
    cache_dtype: str = param("fp32", "dtype of the cached layer inputs in the slots and the buffer: 'fp32' or 'bf16'")


@dataclass
class LruConfig:
    """The Linear Recurrent Unit (``model.memory: lru``, agents/memory/lru.py): ``model.memory_layers`` residual blocks
    of width ``model.memory_size``, each a complex diagonal linear recurrence."""

    state_size: int = param(0, "complex state channels per block (0: model.memory_size)", low=0)
    r_min: float = param(0.4, "smallest initial |lambda| (the stable-init ring's inner radius)", low=0.0, high=1.0)
    r_max: float = param(0.99, "largest initial |lambda| (the ring's outer radius, < 1)", low=0.0, high=0.999999)
    max_phase: float = param(6.283185307179586, "largest initial phase of lambda (radians)", low=0.0)


@dataclass
class FfmConfig:
    """Fast and Forgetful Memory (``model.memory: ffm``, agents/memory/ffm.py): ``model.memory_layers`` residual
    blocks of width ``model.memory_size``, each trace_size x context_size decaying, oscillating complex traces."""

    trace_size: int = param(32, "gated input channels per block, each with context_size traces", low=1)
    context_size: int = param(4, "traces per channel (decay and frequency learned per channel x context)", low=1)
    max_horizon: float = param(1024.0, "longest initial time constant of a trace (steps)", low=1.0)


@dataclass
class MambaConfig:
    """A selective state-space memory (``model.memory: mamba``, agents/memory/mamba.py): ``model.memory_layers``
    residual Mamba blocks of width ``model.memory_size``, in pure PyTorch on the shared scan."""

    state_size: int = param(16, "SSM states per inner channel (N)", low=1)
    expand: int = param(2, "inner width = expand x memory_size", low=1)
    conv_size: int = param(4, "steps of the causal depthwise convolution before the SSM (1: none)", low=1)
    dt_rank: int = param(0, "rank of the step-size projection (0: ceil(memory_size / 16))", low=0)
    dt_min: float = param(0.001, "smallest initial step size", low=1e-6)
    dt_max: float = param(0.1, "largest initial step size", low=1e-6)


@dataclass
class Mamba2Config:
    """A state-space memory with one decay per head (``model.memory: mamba2``, agents/memory/mamba2.py; Mamba-2's
    block): ``model.memory_layers`` residual blocks of width ``model.memory_size``, trained through matrix products
    over chunks of steps."""

    state_size: int = param(
        16, "SSM states per head channel (N; the buffer keeps expand x memory_size x N floats per step)", low=1
    )
    expand: int = param(2, "inner width = expand x memory_size", low=1)
    head_dim: int = param(64, "channels per head (one decay per head); must divide the inner width", low=1)
    conv_size: int = param(4, "steps of the causal depthwise convolution over x, B and C (1: none)", low=1)
    chunk_size: int = param(64, "steps per chunk of the training pass (its Q x Q products)", low=1)
    dt_min: float = param(0.001, "smallest initial step size", low=1e-6)
    dt_max: float = param(0.1, "largest initial step size", low=1e-6)


@dataclass
class ModelConfig:
    """The actor-critic: encoders -> memory -> body -> separate policy and value streams."""

    encoder: str = param("nature_cnn", "observation encoder (agents.models.ENCODERS): nature_cnn (images) or mlp")
    memory: str = param(
        "gru",
        "memory module (agents.memory.MEMORY_MODULES): none, gru, lstm, trxl, lru, ffm, mamba, mamba2, or a class of "
        "your own by import path, 'package.module:ClassName' (docs/memory.md)",
    )
    memory_size: int = param(
        512, "hidden units of the recurrent layer (the width of lru, ffm, mamba and mamba2)", low=1
    )
    memory_layers: int = param(1, "stacked recurrent layers (blocks of lru, ffm, mamba and mamba2)", low=1)
    memory_options: dict[str, Any] = param(
        {}, "keyword arguments of a memory given by import path (its own hyperparameters)"
    )
    hidden_size: int = param(512, "units of the body layer and of each of the policy and value streams", low=1)
    vector_encoder_size: int = param(
        128, "units of the encoder of vector inputs (vector obs, previous action/reward)", low=1
    )
    mlp_sizes: list[int] = param(
        [64, 64], "hidden layers of the MLP that encodes vector observations (encoder: mlp), e.g. [64, 64]"
    )
    previous_action: bool = param(False, "feed the previous action (one-hot per branch, zeros at reset)")
    previous_reward: bool = param(False, "feed the previous reward (zero at reset)")
    frame_stack: int = param(
        1, "last k observations concatenated along channels (1: none; paper: 4 RGB, 16 gray)", low=1
    )
    grayscale: bool = param(False, "turn images into one luma channel (ITU-R 601) before stacking")
    helm: HelmConfig = param(HelmConfig(), "the HELM branch (off unless helm.lm is set)")
    trxl: TrxlConfig = param(TrxlConfig(), "the Transformer-XL memory (used with memory: trxl)")
    lru: LruConfig = param(LruConfig(), "the Linear Recurrent Unit (used with memory: lru)")
    ffm: FfmConfig = param(FfmConfig(), "Fast and Forgetful Memory (used with memory: ffm)")
    mamba: MambaConfig = param(MambaConfig(), "the selective state-space memory (used with memory: mamba)")
    mamba2: Mamba2Config = param(Mamba2Config(), "the state-space memory with a decay per head (memory: mamba2)")


@dataclass
class PPOConfig:
    """PPO with GAE; the defaults are the paper's Table 6."""

    gamma: float = param(0.99, "discount factor", low=0.0, high=1.0)
    gae_lambda: float = param(0.95, "GAE lambda", low=0.0, high=1.0)
    epochs: int = param(3, "passes over each batch", low=1)
    minibatches: int = param(8, "minibatches per epoch (equal numbers of sequences)", low=1)
    learning_rate: Schedule = param(Schedule(3e-4, 1e-4), "AdamW learning rate (linear schedule)")
    entropy_coef: Schedule = param(Schedule(1e-4, 1e-5), "entropy bonus coefficient (linear schedule)")
    clip_range: Schedule = param(Schedule(0.2), "PPO clip range of the policy ratio (and of the value)")
    clip_value_loss: bool = param(True, "clip the value loss with the clip range (max of clipped and unclipped)")
    value_coef: float = param(0.25, "value loss coefficient", low=0.0)
    max_grad_norm: float = param(0.5, "global gradient-norm clip", low=0.0)
    advantage_normalization: str = param("minibatch", "normalise advantages per 'minibatch', per 'batch' or 'none'")
    sequence_length: int | str = param(
        "max", "BPTT sequence length: an int >= 1 or 'max' (the longest episode)", expect="an int >= 1 or 'max'"
    )
    reconstruction_coef: float = param(
        0.0,
        "weight of the observation-reconstruction loss (a transposed-CNN decoder from the memory output, BCE against "
        "the newest frame / 255; the JMLR TrXL runs use 0.1 on some tasks); 0: no decoder",
        low=0.0,
    )
    ground_truth_coef: float = param(
        0.0,
        "weight of the ground-truth estimation loss (an MLP head from the memory output, mean squared error against "
        "the environment's info['ground_truth'] of each step; endless Memory Gym ids only); 0: no head",
        low=0.0,
    )


WANDB_MODES = ("online", "offline", "disabled")


@dataclass
class WandbConfig:
    """Weights & Biases logging (``pip install -e ".[wandb]"``), off while ``project`` is empty: the TensorBoard
    scalars, the resolved config and the run's git revision, one W&B run per run directory (a resume continues it).
    A setting left unset (empty, or null for ``mode``) is W&B's own: its environment variable (``WANDB_ENTITY``,
    ``WANDB_RUN_GROUP``, ``WANDB_MODE``) or its default; ``<run>/wandb.json`` records what each start resolved."""

    project: str = param("", "W&B project (empty: no W&B logging)")
    entity: str = param("", "W&B entity, a user or team (empty: WANDB_ENTITY, else the logged-in account's default)")
    group: str = param("", "W&B group, e.g. one per sweep panel (empty: WANDB_RUN_GROUP, else none)")
    mode: str | None = param(
        None,
        "'online', 'offline' (logs kept under <run>/wandb, synced later) or 'disabled' (null: WANDB_MODE, else online)",
    )


@dataclass
class RunConfig:
    """How long, how wide and where to train."""

    total_steps: int = param(163_840_000, "environment steps (rounded down to whole updates)", low=1)
    workers: int = param(32, "environments stepped in parallel (slots of one batched core)", low=1)
    worker_steps: int = param(512, "steps per worker per rollout", low=1)
    device: str = param("cpu", "torch device: 'cpu' or 'cuda' (or 'cuda:N')")
    precision: str = param("fp32", "'fp32', or 'bf16': train under bfloat16 autocast, act with bfloat16 weights")
    torch_threads: int = param(0, "torch intra-op threads (0: one per CPU core)", low=0)
    seed: int = param(0, "seed of the model init, action sampling, minibatch shuffling and episode seeds", low=0)
    checkpoint_interval: int = param(100, "updates between checkpoints (0: only at the end)", low=0)
    keep_checkpoints: int = param(2, "most recent checkpoints kept on disk (0: keep all)", low=0)
    progress_bar: bool = param(True, "show a tqdm progress bar")
    method: str = param("", "short name of the agent in records and plots (empty: derived, e.g. gru, stack4, helm)")
    task: str = param("", "short name of the task in records and plots (empty: env id + non-default options)")
    wandb: WandbConfig = param(WandbConfig(), "Weights & Biases logging (off unless wandb.project is set)")


@dataclass
class EvalConfig:
    """Evaluation on novel seeds during training (the paper: 30 seeds x 5 repetitions, actions sampled)."""

    interval: int = param(0, "updates between evaluations (0: none during training)", low=0)
    seeds: list[int] = param([], "inclusive range [low, high] of novel seeds (empty: the 30 after env.train_seeds)")
    repetitions: int = param(5, "episodes per seed", low=1)
    greedy: bool = param(False, "act by argmax instead of sampling (the paper samples)")
    seed: int = param(0, "seed of the evaluation's action sampling", low=0)


@dataclass
class SlurmConfig:
    """Cluster settings of a sweep (``grid.slurm``; ``scripts/sweep.py --slurm-*`` options override them). One run is
    one job; the jobs of a sweep form a job array."""

    partition: str = param("", "SLURM partition (empty: the cluster's default)")
    time: int | str = param(
        "",
        "time limit per job, quoted: '[D-]HH:MM:SS' or 'MINUTES' (empty: 24:00:00); a run that needs longer is "
        "requeued and resumes from its last checkpoint",
        expect="a quoted time limit, e.g. '24:00:00'",
    )
    gpus_per_job: int = param(0, "GPUs per job", low=0)
    cpus_per_job: int = param(
        0, "CPU cores per job (0: the cluster's default); new runs get as many torch threads", low=0
    )
    mem_gb: float = param(0.0, "memory per job in GB (0: the cluster's default)", low=0.0)
    array_parallelism: int = param(0, "array tasks allowed to run at once (0: submitit's default, 256)", low=0)
    account: str = param("", "account to charge (sbatch --account)")
    qos: str = param("", "quality of service (sbatch --qos)")
    constraint: str = param("", "node features (sbatch --constraint)")
    max_requeues: int = param(20, "times a timed-out job is requeued (pre-emptions are not counted)", low=0)
    setup: list[str] = param([], "shell lines run before each job, e.g. 'source .venv/bin/activate'")
    additional: dict[str, Any] = param({}, "further sbatch options, {name: value} (e.g. {mail-type: END})")

    @property
    def timeout_min(self) -> int:
        """The time limit in minutes (24 h when unset)."""
        return slurm_minutes(self.time) if self.time != "" else 24 * 60


@dataclass
class Config:
    """A whole training run. ``grid`` (see "Grids" in the module docstring) is expanded by :func:`expand_grid` for
    ``scripts/sweep.py``; a config that has one is not a single run."""

    env: EnvConfig = param(EnvConfig(), "environment")
    model: ModelConfig = param(ModelConfig(), "actor-critic model")
    ppo: PPOConfig = param(PPOConfig(), "PPO hyperparameters")
    run: RunConfig = param(RunConfig(), "run length, width, device and seed")
    eval: EvalConfig = param(EvalConfig(), "evaluation on novel seeds during training")
    grid: dict[str, Any] = param(
        {}, "runs for scripts/sweep.py: plain axes {dotted.key: [values]}, named axes method/task, panel, slurm"
    )

    @property
    def batch_size(self) -> int:
        return self.run.workers * self.run.worker_steps

    @property
    def num_updates(self) -> int:
        return self.run.total_steps // self.batch_size

    @property
    def method(self) -> str:
        """The agent's short name: ``run.method``, else derived from the model (ppo, gru, lstm, stack4, helm...)."""
        if self.run.method:
            return self.run.method
        model = self.model
        memory = model.memory.rpartition(":")[2]  # an import path is named by its class
        parts = [] if memory == "none" else [memory]
        if model.frame_stack > 1:
            parts.append(f"stack{model.frame_stack}")
        if model.helm.enabled:
            parts.append("helm")
        return "-".join(parts) or "ppo"

    @property
    def task(self) -> str:
        """The task's short name: ``run.task``, else the env id and its non-default options (:func:`task_name`)."""
        return self.run.task or task_name(self.env.id, self.env.options)

    @property
    def eval_seeds(self) -> list[int]:
        """The inclusive [low, high] of evaluation seeds: ``eval.seeds``, else the 30 right after the training ones."""
        if self.eval.seeds:
            return list(self.eval.seeds)
        high = self.env.train_seeds[1]
        return [high + 1, high + DEFAULT_EVAL_SEEDS]


def rounding_notice(config: Config) -> str | None:
    """What ``run.total_steps`` resolves to when it is not a whole number of updates (None when it is): training
    stops after the last whole update, and the command line says so instead of training fewer steps silently."""
    steps, batch = config.run.total_steps, config.batch_size
    if steps % batch == 0:
        return None
    updates = config.num_updates
    return (
        f"run.total_steps={steps} is not a whole number of updates of {batch} steps (run.workers x run.worker_steps "
        f"= {config.run.workers} x {config.run.worker_steps}): training {updates} updates, {updates * batch} steps"
    )


MAX_TASK_NAME = 96  # longer default task names end in a digest of the options instead (file names stay short)
_RESOLVED: dict[tuple[str, str], tuple[dict[str, Any], dict[str, Any]]] = {}  # (id, options) -> (resolved, defaults)


def resolved_options(env_id: str, options: Mapping[str, Any] | None = None, changed_only: bool = False) -> dict:
    """The reset options of ``env_id`` with ``options`` applied, validated and canonical (a float option as a float,
    so that ``1`` and ``1.0`` agree); ``changed_only``: only those that differ from the environment's defaults."""
    if env_id not in envs.ENV_IDS:  # a gymnasium environment: its reset options are its own, without known defaults
        return _deep_copy(dict(options or {}))
    key = (env_id, json.dumps(dict(options or {}), sort_keys=True, default=repr))
    if key not in _RESOLVED:  # one-slot cores know their variant's specs and defaults; built once per option set
        default = envs.make_core(env_id, 1)
        core = envs.make_core(env_id, 1, dict(options)) if options else default
        kinds = {name: spec.kind for name, spec in default.option_specs.items()}
        _RESOLVED[key] = tuple(_canonical(kinds, found.base_options) for found in (core, default))
    resolved, defaults = _RESOLVED[key]
    chosen = {name: value for name, value in resolved.items() if not changed_only or value != defaults[name]}
    return {name: list(value) if isinstance(value, list) else value for name, value in chosen.items()}  # cache intact


def _canonical(kinds: Mapping[str, str], options: Mapping[str, Any]) -> dict[str, Any]:
    found = {}
    for name, value in options.items():
        if kinds[name] in ("float", "float_list"):
            value = [float(item) for item in value] if isinstance(value, list) else float(value)
        found[name] = list(value) if isinstance(value, list) else value
    return found


def task_name(env_id: str, options: Mapping[str, Any] | None = None) -> str:
    """The default task name: ``env_id``, then ``+key=value`` for every option that differs from the environment's
    default, sorted by key (``ProofOfMemory-v0+delay=16``, ``MortarMayhem-Grid-v0+command_count=1``; a list's items
    joined by ``_``, booleans as ``true``/``false``). Runs with default options keep the plain id. Only letters,
    digits and ``_.+=-``: a valid CSV field and file name. A name longer than :data:`MAX_TASK_NAME` becomes
    ``env_id+options=<12 hex digits of the SHA-256 of the options as sorted JSON>``."""
    changed = resolved_options(env_id, options, changed_only=True)
    if env_id not in envs.ENV_IDS:  # "module:EnvId", "Namespace/Env-v0": the id without module, other characters as _
        env_id = re.sub(r"[^A-Za-z0-9_.+=-]", "_", env_id.rpartition(":")[2]).lstrip("_.+=-") or "env"
    if not changed:
        return env_id
    name = env_id + "".join(f"+{key}={_option_text(changed[key])}" for key in sorted(changed))
    if len(name) <= MAX_TASK_NAME:
        return name
    text = json.dumps(changed, sort_keys=True, separators=(",", ":"))
    return f"{env_id}+options={hashlib.sha256(text.encode()).hexdigest()[:12]}"


def _option_text(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, list):
        return "_".join(map(_option_text, value)) or "none"
    return repr(value)  # ints as digits, floats as Python's shortest round-trip form (0.5, 1e-05, -1.0)


# ------------------------------------------------------------------------------------------------- loading
def read_config_file(path: str | Path) -> dict[str, Any]:
    """The mapping a YAML config file holds, or a :class:`ConfigError` naming what is wrong with the file."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"config file {str(path)!r} does not exist")
    try:
        raw = yaml.safe_load(path.read_text()) or {}
    except yaml.YAMLError as err:
        raise ConfigError(f"{path}: {_yaml_error(err)}") from err
    if not isinstance(raw, dict):
        raise ConfigError(f"{path}: expected a mapping at the top level, got {type(raw).__name__}")
    return raw


def _yaml_error(err: yaml.YAMLError) -> str:
    """A YAML syntax error as 'line L, column C: problem' (1-based, where the parser stopped), without a traceback."""
    mark = getattr(err, "problem_mark", None)
    problem = getattr(err, "problem", None) or str(err)
    context = getattr(err, "context", None)
    where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark is not None else ""
    return f"{where}invalid YAML: {problem}" + (f" ({context})" if context else "")


def load_config(path: str | Path, overrides: Iterable[str] = ()) -> Config:
    """Read a YAML config, apply ``key=value`` overrides and validate everything."""
    return config_from_dict(read_config_file(path), overrides)


def config_from_dict(raw: Mapping[str, Any], overrides: Iterable[str] = ()) -> Config:
    """Build a validated :class:`Config` from nested dicts plus ``key=value`` overrides.

    With a ``grid`` block the result is the base of the grid (base file plus overrides, each block validated), and
    every point of the grid is expanded and validated as a whole config (:func:`expand_grid`)."""
    overrides = list(overrides)
    merged = _deep_copy(raw)
    for item in overrides:
        key, value = parse_override(item)
        _apply_override(merged, key, value)
    config = _build(Config, merged, prefix="")
    if not config.grid:
        _check_cross_fields(config)
        return config
    expand_grid(raw, overrides)
    return config


def parse_override(item: str) -> tuple[str, Any]:
    """Split ``a.b=value`` and parse the value as a YAML scalar (``0.1``, ``true``, ``[0, 9]``, ``max``)."""
    key, sep, text = item.partition("=")
    if not sep or not key.strip():
        raise ConfigError(f"override {item!r} is invalid: expected KEY=VALUE, e.g. ppo.gamma=0.995")
    try:
        value = yaml.safe_load(text) if text.strip() else ""
    except yaml.YAMLError as err:
        raise ConfigError(f"override {item!r}: cannot parse the value {text!r} ({err})") from err
    return key.strip(), value


def config_to_dict(config: Any) -> Any:
    """The config as plain nested dicts/lists (what ``config.yaml`` of a run holds)."""
    if dataclasses.is_dataclass(config):
        return {f.name: config_to_dict(getattr(config, f.name)) for f in dataclasses.fields(config)}
    if isinstance(config, dict):
        return {k: config_to_dict(v) for k, v in config.items()}
    if isinstance(config, list | tuple):
        return [config_to_dict(v) for v in config]
    return config


def dump_config(config: Config) -> str:
    return yaml.safe_dump(config_to_dict(config), sort_keys=False)


# ------------------------------------------------------------------------------------- what a resume may change
LENGTH_KEY = "run.total_steps"  # a resume may raise it: the run is lengthened (agents.trainer.extend_run)
RESULT_NEUTRAL = {  # config keys (a block: every key in it) that no record of a run depends on, and why
    "run.progress_bar": "display only",
    "run.checkpoint_interval": "when checkpoints are taken: a run continues exactly from any of them",
    "run.keep_checkpoints": "how many checkpoints stay on disk",
    "run.wandb": "where the scalars also go; TensorBoard, training.csv and the evaluation records are the same",
    "env.check_seeding": "whether an environment that ignores seeds is refused; a run that goes on is the same",
}
# keys a resume asked for on the command line accepts although they change the floating-point rounding of what
# follows (not the experiment: they are outside the config digest), and what the resume says of them
ROUNDING_ONLY = {
    "run.torch_threads": "the thread count changes the rounding of the updates (the weights differ by ~1e-5 after "
    "one update), so from here on the run is not bit for bit the one an uninterrupted run would have been",
}
# keys one might take for settings that no record depends on, and the record they change (said when refused)
CHANGE_RECORDS = {
    "run.device": "another device computes other floats",
    "run.method": "its name is in every record",
    "run.task": "its name is in every record",
    "eval.interval": "it decides the steps of the evaluation records",
    "env.metric.label": "it is in the records' metric_spec column",
}


def resume_may_change(key: str, lengthen: bool = True, rounding: bool = True) -> bool:
    """Whether a run that goes on (``scripts/train.py --resume``, a sweep's resume, a checkpoint under a newer
    ``config.yaml``) may take a new value of the dotted config ``key``: the settings no record depends on
    (:data:`RESULT_NEUTRAL`, a block's keys included), where the caller accepts it (``rounding``: a resume asked
    for by hand, not a sweep's, which keeps its runs bit for bit) the settings that change only the rounding
    (:data:`ROUNDING_ONLY`), and, where the run can be lengthened (``lengthen``), :data:`LENGTH_KEY`. Any other
    change would make the run's records those of no single config."""
    if lengthen and key == LENGTH_KEY or rounding and key in ROUNDING_ONLY:
        return True
    return any(key == neutral or key.startswith(neutral + ".") for neutral in RESULT_NEUTRAL)


def differing_keys(a: Any, b: Any, prefix: str = "") -> list[str]:
    """The dotted keys at which two nested dicts differ (``a``'s order, then keys only ``b`` has)."""
    if not (isinstance(a, dict) and isinstance(b, dict)):
        return [] if a == b else [prefix or "(config)"]
    keys = list(a) + [key for key in b if key not in a]
    return [k for key in keys for k in differing_keys(a.get(key), b.get(key), f"{prefix}.{key}" if prefix else key)]


def resume_config(saved: Config, overrides: Iterable[str], where: str | Path) -> Config:
    """The config a run resumes with: ``saved`` (its ``config.yaml``, at ``where``) with the ``key=value``
    ``overrides``, which may change only what :func:`resume_may_change` allows; a :class:`ConfigError` names every
    other key they change (whether a new ``run.total_steps`` lengthens the run is checked where it is extended)."""
    overrides = list(overrides)
    if not overrides:
        return saved
    new = config_from_dict(config_to_dict(saved), overrides)
    refused = [key for key in differing_keys(config_to_dict(saved), config_to_dict(new)) if not resume_may_change(key)]
    if refused:
        why = "".join(f"; {key}: {CHANGE_RECORDS[key]}" for key in refused if key in CHANGE_RECORDS)
        neutral = ", ".join([*RESULT_NEUTRAL, *ROUNDING_ONLY])
        raise ConfigError(
            f"{', '.join(refused)} cannot be changed on resume: the run goes on with the config saved in {where}"
            f"{why}; a resume may set {LENGTH_KEY} (to lengthen the run) and the settings no record depends on "
            f"({neutral})"
        )
    return new


def sets_length(overrides: Iterable[str]) -> bool:
    """Whether ``key=value`` overrides set :data:`LENGTH_KEY` (to whatever value: one that does not lengthen the run
    is an error where it is extended)."""
    return any(parse_override(item)[0] == LENGTH_KEY for item in overrides)


def resume_changes(saved: Config, new: Config) -> dict[str, list[Any]]:
    """``{key: [saved value, new value]}`` of the settings no record depends on that ``new`` changes."""
    old_tree, new_tree = config_to_dict(saved), config_to_dict(new)
    return {
        key: [_dotted(old_tree, key), _dotted(new_tree, key)]
        for key in differing_keys(old_tree, new_tree)
        if resume_may_change(key, lengthen=False)
    }


def with_neutral_settings(saved: Config, source: Config) -> Config:
    """``saved`` with the settings no record depends on (:data:`RESULT_NEUTRAL`) taken from ``source``: what a
    sweep's run that goes on takes from its grid."""
    tree, given = config_to_dict(saved), config_to_dict(source)
    for key in RESULT_NEUTRAL:
        *parents, name = key.split(".")
        into, take = tree, given
        for part in parents:
            into, take = into[part], take[part]
        into[name] = take[name]
    return saved if tree == config_to_dict(saved) else config_from_dict(tree)


def _dotted(tree: Mapping[str, Any], key: str) -> Any:
    for part in key.split("."):
        tree = tree.get(part) if isinstance(tree, Mapping) else None
    return tree


def _deep_copy(raw: Any) -> Any:
    if isinstance(raw, Mapping):
        return {k: _deep_copy(v) for k, v in raw.items()}
    if isinstance(raw, list):
        return [_deep_copy(v) for v in raw]
    return raw


def _set_dotted(tree: dict, key: str, value: Any) -> None:
    """Set ``tree[a][b] = value`` for ``key = "a.b"``, checking each part against the dataclass fields."""
    parts = key.split(".")
    cls: Any = Config  # None inside a free-form mapping (env.options), where any key is allowed
    node = tree
    for depth, part in enumerate(parts):
        here = ".".join(parts[: depth + 1])
        if cls is not None and part not in (names := [f.name for f in dataclasses.fields(cls)]):
            raise ConfigError(_unknown_key_message(here, part, names))
        if depth == len(parts) - 1:
            node[part] = value
            return
        child = get_type_hints(cls)[part] if cls is not None else None
        if cls is not None and not (_is_dataclass_type(child) or get_origin(child) is dict):
            raise ConfigError(f"key {key!r}: {here!r} is a {getattr(child, '__name__', child)}, it has no sub-keys")
        if child is Schedule and _is_number(_float_or_text(node.get(part))):
            node[part] = _constant_schedule(_float_or_text(node[part]))
        elif not isinstance(node.get(part), dict):
            node[part] = {}
        node = node[part]
        cls = child if _is_dataclass_type(child) else None


def _constant_schedule(value: float) -> dict:
    """A plain number written for a schedule: that value, constant."""
    return {"initial": value, "final": None, "decay_updates": None}


def _build(cls: type, raw: Any, prefix: str, defaults: Any = None) -> Any:
    """An instance of dataclass ``cls`` from ``raw``; missing keys come from ``defaults`` (or the class)."""
    if cls is Schedule and isinstance(raw, str):
        raw = _float_or_text(raw)  # YAML 1.1 reads 1e-3 (no dot) as a string
    if cls is Schedule and _is_number(raw):
        raw = _constant_schedule(raw)
    if cls is Schedule and not isinstance(raw, Mapping):  # neither form of a schedule: say both, not just one
        raise ConfigError(
            f"{prefix}={raw!r} is invalid: expected a number (a constant) or a mapping "
            "{initial: ..., final: ..., decay_updates: ...} (a linear schedule)"
        )
    if not isinstance(raw, Mapping):
        raise ConfigError(f"{prefix or 'config'} must be a mapping of keys to values, got {raw!r}")
    names = [f.name for f in dataclasses.fields(cls)]
    for key in raw:
        if key not in names:
            raise ConfigError(_unknown_key_message(_join(prefix, str(key)), str(key), names))
    hints = get_type_hints(cls)
    defaults = cls() if defaults is None else defaults
    values = {}
    for f in dataclasses.fields(cls):
        if f.name not in raw:
            continue
        key, tp = _join(prefix, f.name), hints[f.name]
        if _is_dataclass_type(tp):  # a partial block keeps this field's own defaults for the keys it omits
            values[f.name] = _build(tp, raw[f.name], key, defaults=getattr(defaults, f.name))
        else:
            values[f.name] = _convert(tp, raw[f.name], key, f.metadata)
    instance = dataclasses.replace(defaults, **values)
    _check_block(instance, prefix)
    return instance


def _convert(tp: Any, value: Any, key: str, meta: Mapping[str, Any], text_numbers: bool = True) -> Any:
    """Validate one value against its annotated type and bounds; return it in canonical form. ``text_numbers``: a
    string that spells a number is that number (off where the field also takes strings, e.g. ``int | str``)."""
    origin, args = get_origin(tp), get_args(tp)
    if origin in (Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        errors = []
        options = [a for a in args if a is not type(None)]
        for option in options:
            try:
                return _convert(option, value, key, meta, text_numbers=str not in options)
            except ConfigError as err:
                errors.append(str(err))
        expected = meta.get("expect") or _describe(tp)
        raise ConfigError(errors[0] if len(errors) == 1 else f"{key}={value!r} is invalid: expected {expected}")
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{key}={value!r} is invalid: expected true or false")
        return value
    if tp in (int, float):
        return _number(tp, value, key, meta, text_numbers)
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{key}={value!r} is invalid: expected a string")
        return value
    if origin is list:
        if not isinstance(value, list | tuple):
            raise ConfigError(f"{key}={value!r} is invalid: expected a list")
        (item_type,) = args or (Any,)
        return [value_ if item_type is Any else _convert(item_type, value_, key, {}) for value_ in value]
    if origin is dict:
        if not isinstance(value, Mapping):
            raise ConfigError(f"{key}={value!r} is invalid: expected a mapping")
        return _deep_copy(dict(value))
    raise TypeError(f"config field {key} has an unsupported annotation {tp!r}")  # a bug in this module


def _number(tp: type, value: Any, key: str, meta: Mapping[str, Any], text_numbers: bool = True) -> int | float:
    """A number field's value. Scientific notation is accepted for ints too (``total_steps: 1e5``, ``1.0e5``,
    ``100000.0``) as long as the value is whole; YAML 1.1 reads ``1e5`` and ``1.0e5`` as strings, hence the parse."""
    low, high = meta.get("low"), meta.get("high")
    bounds = ""
    if low is not None or high is not None:
        bounds = f" in [{'-inf' if low is None else f'{low:g}'}, {'inf' if high is None else f'{high:g}'}]"
    expected = f"{'an int' if tp is int else 'a number'}{bounds}"
    given = value
    if text_numbers and isinstance(value, str):
        value = _float_or_text(value)
    if isinstance(value, bool) or not _is_number(value):
        raise ConfigError(f"{key}={given!r} is invalid: expected {expected}")
    if tp is int and not isinstance(value, numbers.Integral):
        if not (math.isfinite(value) and float(value).is_integer()):
            raise ConfigError(f"{key}={given!r} is invalid: expected {expected}; {value:g} is not a whole number")
    value = int(value) if tp is int else float(value)
    if not math.isfinite(value) or (low is not None and value < low) or (high is not None and value > high):
        raise ConfigError(f"{key}={value!r} is invalid: expected {expected}")
    return value


def _check_block(block: Any, prefix: str) -> None:
    """Checks of one block that a type annotation cannot express."""
    if isinstance(block, Schedule):
        return
    if isinstance(block, EnvConfig):
        _check_env(block, prefix)
    elif isinstance(block, ModelConfig):
        from agents.memory import MEMORY_MODULES, memory_class  # the registries the model is built from
        from agents.models import ENCODERS

        _choice(f"{prefix}.encoder", block.encoder, tuple(ENCODERS))
        if not block.mlp_sizes or any(size < 1 for size in block.mlp_sizes):
            raise ConfigError(
                f"{prefix}.mlp_sizes={block.mlp_sizes!r} is invalid: expected a non-empty list of ints >= 1"
            )
        if ":" in block.memory:  # a memory of the user's own, by import path
            try:
                memory_class(block.memory)
            except (ImportError, AttributeError, TypeError, ValueError) as err:
                raise ConfigError(f"{prefix}.memory={block.memory!r}: {err}") from err
        else:
            _choice(f"{prefix}.memory", block.memory, tuple(MEMORY_MODULES))
        inner = block.mamba2.expand * block.memory_size  # Mamba-2's heads split its inner width
        if block.memory == "mamba2" and inner % block.mamba2.head_dim:
            raise ConfigError(
                f"{prefix}.mamba2.head_dim={block.mamba2.head_dim} is invalid: expected a divisor of the inner width "
                f"{prefix}.mamba2.expand x {prefix}.memory_size = {inner}"
            )
        if block.memory_options and ":" not in block.memory:
            raise ConfigError(
                f"{prefix}.memory_options={block.memory_options!r} is only for a memory given by import path; "
                f"{block.memory!r} takes its settings from {prefix}.{block.memory} (when it has a block)"
            )
    elif isinstance(block, LruConfig):
        if block.r_min > block.r_max:
            raise ConfigError(f"{prefix}.r_min={block.r_min} is invalid: expected <= {prefix}.r_max={block.r_max}")
    elif isinstance(block, (MambaConfig, Mamba2Config)):
        if block.dt_min > block.dt_max:
            raise ConfigError(f"{prefix}.dt_min={block.dt_min} is invalid: expected <= {prefix}.dt_max={block.dt_max}")
    elif isinstance(block, HelmConfig):
        if block.random_width % block.random_heads:
            raise ConfigError(
                f"{prefix}.random_width={block.random_width} is invalid: expected a multiple of "
                f"{prefix}.random_heads={block.random_heads}"
            )
    elif isinstance(block, TrxlConfig):
        _choice(f"{prefix}.positional_encoding", block.positional_encoding, ("relative", "absolute", "learned", "none"))
        _choice(f"{prefix}.layer_norm", block.layer_norm, ("pre", "post", "none"))
        _choice(f"{prefix}.cache_dtype", block.cache_dtype, ("fp32", "bf16"))
        if block.dim % block.heads:
            raise ConfigError(
                f"{prefix}.dim={block.dim} is invalid: expected a multiple of {prefix}.heads={block.heads}"
            )
    elif isinstance(block, EvalConfig):
        _seed_range(f"{prefix}.seeds", block.seeds, allow_empty=True)
    elif isinstance(block, PPOConfig):
        _choice(f"{prefix}.advantage_normalization", block.advantage_normalization, ("minibatch", "batch", "none"))
        length = block.sequence_length
        if isinstance(length, str) and length != "max" or isinstance(length, int) and length < 1:
            raise ConfigError(f"{prefix}.sequence_length={length!r} is invalid: expected an int >= 1 or 'max'")
    elif isinstance(block, SlurmConfig):
        if isinstance(block.time, int):  # YAML 1.1 reads an unquoted 24:00:00 as the integer 86400
            raise ConfigError(
                f"{prefix}.time={block.time!r} is invalid: write the time limit as a quoted string, e.g. '24:00:00' "
                "or '90' (minutes); unquoted, YAML reads 24:00:00 as the number 86400"
            )
        if block.time != "":
            slurm_minutes(block.time, f"{prefix}.time")
    elif isinstance(block, MetricConfig):
        if block.low is not None and block.high is not None and block.low > block.high:
            raise ConfigError(f"{prefix}.low={block.low} is above {prefix}.high={block.high}: expected low <= high")
    elif isinstance(block, WandbConfig):
        if block.mode is not None:  # null: W&B's own setting (WANDB_MODE)
            _choice(f"{prefix}.mode", block.mode, WANDB_MODES)
    elif isinstance(block, RunConfig):
        _choice(f"{prefix}.precision", block.precision, ("fp32", "bf16"))
        if not is_device_name(block.device):
            raise ConfigError(f"{prefix}.device={block.device!r} is invalid; valid choices: 'cpu', 'cuda', 'cuda:N'")


def is_device_name(name: str) -> bool:
    """Whether ``name`` is a device this project runs on: ``cpu``, ``cuda`` or ``cuda:N``."""
    return name == "cpu" or name == "cuda" or name.startswith("cuda:") and name[5:].isdigit()


def _check_env(block: EnvConfig, prefix: str) -> None:
    from envs.gymnasium_core import IMAGE_LAYOUTS, VECTORIZATIONS

    _choice(f"{prefix}.vectorization", block.vectorization, VECTORIZATIONS)
    _choice(f"{prefix}.image_layout", block.image_layout, IMAGE_LAYOUTS)
    if block.native:
        try:  # a one-slot core validates the options exactly as training will (families differ per variant)
            envs.make_core(block.id, 1, block.options)
        except ValueError as err:
            raise ConfigError(f"{prefix}.options: {err}") from err
    else:
        _check_gymnasium_env(block, prefix)
    _seed_range(f"{prefix}.train_seeds", block.train_seeds)


_GYMNASIUM_CHECKED: dict[str, str] = {}  # settings -> "" (valid) or the error: one probe environment per setting


def _check_gymnasium_env(block: EnvConfig, prefix: str) -> None:
    """That gymnasium makes the environment, its wrappers apply and its spaces are ones the model takes (one
    environment is made, in this process, and closed)."""
    from envs.gymnasium_core import UnknownEnvironmentError

    key = json.dumps([block.id, block.make_kwargs, block.wrappers, block.image_layout], sort_keys=True, default=repr)
    if key not in _GYMNASIUM_CHECKED:
        try:
            core = envs.make_core(
                block.id, 1, make_kwargs=block.make_kwargs, wrappers=block.wrappers, image_layout=block.image_layout
            )
            core.close()
            _GYMNASIUM_CHECKED[key] = ""
        except UnknownEnvironmentError as err:
            ids = list(envs.ENV_IDS)
            close = difflib.get_close_matches(block.id, ids, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            _GYMNASIUM_CHECKED[key] = f"{prefix}.id={block.id!r} is unknown{hint}: {err}"
        except (ValueError, TypeError, ImportError) as err:
            _GYMNASIUM_CHECKED[key] = f"{prefix}: {block.id} cannot be used: {err}"
    if _GYMNASIUM_CHECKED[key]:
        raise ConfigError(_GYMNASIUM_CHECKED[key])


def _seed_range(key: str, seeds: list[int], allow_empty: bool = False) -> None:
    if allow_empty and not seeds:
        return
    if len(seeds) != 2 or not 0 <= seeds[0] <= seeds[1]:
        empty = " (or [] for the default)" if allow_empty else ""
        raise ConfigError(f"{key}={seeds!r} is invalid: expected [low, high] with 0 <= low <= high{empty}")


def check_disjoint_seeds(train: list[int], evaluation: list[int]) -> None:
    """Evaluation seeds must be novel: refuse a range that overlaps the training range, naming both."""
    if evaluation[0] <= train[1] and train[0] <= evaluation[1]:
        raise ConfigError(
            f"evaluation seeds [{evaluation[0]}, {evaluation[1]}] overlap the training seeds (env.train_seeds) "
            f"[{train[0]}, {train[1]}]: evaluate on novel seeds, e.g. [{train[1] + 1}, {train[1] + DEFAULT_EVAL_SEEDS}]"
        )


def _check_cross_fields(config: Config) -> None:
    if config.run.total_steps < config.batch_size:
        raise ConfigError(
            f"run.total_steps={config.run.total_steps} is smaller than one batch "
            f"(run.workers x run.worker_steps = {config.batch_size}): expected at least {config.batch_size}"
        )
    if config.model.memory == "none" and config.ppo.sequence_length not in ("max", 1):
        raise ConfigError(
            f"ppo.sequence_length={config.ppo.sequence_length!r} needs a memory module; "
            "with model.memory=none use 'max' or 1 (every step is its own sequence)"
        )
    check_disjoint_seeds(config.env.train_seeds, config.eval_seeds)


# --------------------------------------------------------------------------------------------------- grids
NAMED_AXES = ("method", "task")  # axes whose values are named bundles; a bundle sets run.<axis> to its name
PANEL, SLURM = "panel", "slurm"
GRID_SETTINGS = (PANEL, SLURM)  # grid keys that are not axes
RESERVED_NAMES = ("results", "slurm")  # sub-directories of a panel's directory that runs cannot take
_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.+=-]*\Z")


@dataclass(frozen=True)
class GridPoint:
    """One point of a grid: its choice on every axis and the whole config it makes.

    ``choices``: ``(axis, label)`` per axis in application order (named axes, then plain axes), the label being the
    bundle's name or the plain value written as YAML. ``overrides``: ``(dotted key, value, source)`` in the order they
    were applied (``source`` names the grid entry, e.g. ``grid.method.stack4`` or ``grid.run.seed``); command-line
    overrides come after them and are not listed."""

    choices: tuple[tuple[str, str], ...]
    overrides: tuple[tuple[str, Any, str], ...]
    config: Config

    def choice(self, axis: str) -> str | None:
        """The label of ``axis`` at this point (None when the grid has no such axis)."""
        return dict(self.choices).get(axis)


def expand_grid(raw: Mapping[str, Any], overrides: Iterable[str] = ()) -> list[GridPoint]:
    """Every point of the grid of ``raw`` (a config with a ``grid`` block) as a validated config, in product order
    (the first axis varies slowest). ``overrides``: ``key=value`` items; ``grid.AXIS=...`` ones change the grid,
    the others apply to every point last. A config without a grid is one point."""
    base = _deep_copy(dict(raw))
    grid = base.pop("grid", None) or {}
    if not isinstance(grid, Mapping):
        raise ConfigError(f"grid must be a mapping of axes to values, got {grid!r}")
    grid = _deep_copy(dict(grid))
    late = []
    for item in overrides:
        key, value = parse_override(item)
        if key.split(".")[0] == "grid":
            holder = {"grid": grid}
            _apply_override(holder, key, value)
            grid = holder["grid"]
        else:
            late.append((key, value))
    if SLURM in grid:
        grid_slurm(grid)
    grid_panel(grid)
    axes = _grid_axes(grid, base)
    points = []
    for combination in itertools.product(*(options for _, options in axes)):
        tree = _deep_copy(base)
        applied = []
        for (axis, _), (label, sets) in zip(axes, combination, strict=True):
            source = f"grid.{axis}.{label}" if axis in NAMED_AXES else f"grid.{axis}"
            for key, value in sets:
                _set_dotted(tree, key, _deep_copy(value))
                applied.append((key, value, source))
        for key, value in late:
            _set_dotted(tree, key, _deep_copy(value))
        choices = tuple((axis, label) for (axis, _), (label, _) in zip(axes, combination, strict=True))
        try:
            config = _build(Config, tree, prefix="")
            _check_cross_fields(config)
        except ConfigError as err:
            where = ", ".join(f"{axis}={label}" for axis, label in choices)
            by_source: dict[str, list[str]] = {}
            for key, value, source in applied:
                by_source.setdefault(source, []).append(f"{key}={_flow(value)}")
            sets = "; ".join(f"{source} sets {', '.join(items)}" for source, items in by_source.items())
            raise ConfigError(f"grid point ({where}) is invalid: {err} [{sets}]") from err
        points.append(GridPoint(choices, tuple(applied), config))
    return points


def grid_panel(grid: Mapping[str, Any]) -> str | None:
    """The panel name a grid gives itself (``grid.panel``), or None."""
    panel = grid.get(PANEL)
    if panel is None:
        return None
    if not isinstance(panel, str):
        raise ConfigError(f"grid.panel={panel!r} is invalid: expected a name")
    check_name("grid.panel", panel)
    return panel


def grid_slurm(grid: Mapping[str, Any]) -> SlurmConfig:
    """The cluster settings of a grid (``grid.slurm``; defaults when absent), validated."""
    return _build(SlurmConfig, grid.get(SLURM) or {}, prefix="grid.slurm")


def check_name(key: str, name: str) -> None:
    """A panel, bundle or value name is one path component of run directories: letters, digits and ``_.+=-``."""
    if not _NAME.match(name) or name in RESERVED_NAMES:
        reserved = f" and not one of {', '.join(RESERVED_NAMES)}" if name in RESERVED_NAMES else ""
        raise ConfigError(
            f"{key}: {name!r} cannot name a directory: expected letters, digits and _.+=-, starting with a letter "
            f"or a digit{reserved}"
        )


def slurm_minutes(value: int | str, key: str = "slurm.time") -> int:
    """A SLURM time limit (minutes, ``MM``, ``HH:MM:SS``, ``D-HH:MM:SS``, ``D-HH``...) in whole minutes (>= 1)."""
    if isinstance(value, bool):
        value = "?"
    if isinstance(value, int):
        minutes = value
    else:
        days, _, clock = str(value).strip().rpartition("-")
        parts = clock.split(":")
        try:
            numbers_ = [int(part) for part in parts]
            day_count = int(days) if days else 0
        except ValueError:
            numbers_, day_count = [], 0
        if not numbers_ or len(numbers_) > 3 or any(n < 0 for n in numbers_):
            raise ConfigError(f"{key}={value!r} is invalid: expected minutes or [D-]HH:MM:SS, e.g. 12:00:00")
        if days:  # D-HH, D-HH:MM, D-HH:MM:SS
            hours, minutes_, seconds = (numbers_ + [0, 0])[:3]
        elif len(numbers_) == 1:  # MM
            hours, minutes_, seconds = 0, numbers_[0], 0
        elif len(numbers_) == 2:  # MM:SS
            hours, minutes_, seconds = 0, numbers_[0], numbers_[1]
        else:
            hours, minutes_, seconds = numbers_
        minutes = day_count * 1440 + hours * 60 + minutes_ + math.ceil(seconds / 60)
    if minutes < 1:
        raise ConfigError(f"{key}={value!r} is invalid: expected at least one minute")
    return minutes


def _grid_axes(grid: Mapping[str, Any], base: Mapping[str, Any]) -> list[tuple[str, list[tuple[str, list]]]]:
    """The axes of a grid in application order: ``(axis, [(label, [(key, value), ...]), ...])``, named axes first
    (file order), then plain axes (file order). Checks names and keys; values are checked with the whole point."""
    named, plain = [], []
    for axis, values in grid.items():
        axis = str(axis)
        if axis in GRID_SETTINGS:
            continue
        if axis in NAMED_AXES:
            named.append((axis, _bundles(axis, values, base)))
            continue
        if "." not in axis:
            raise ConfigError(
                f"grid.{axis} is not a grid key: expected a dotted config key with a list of values (e.g. run.seed), "
                f"a named axis ({', '.join(NAMED_AXES)}) or a setting ({', '.join(GRID_SETTINGS)})"
            )
        if axis.split(".")[0] == "grid":
            raise ConfigError(f"grid.{axis}: the grid cannot sweep itself")
        if not isinstance(values, list) or not values:
            raise ConfigError(f"grid.{axis}={values!r} is invalid: expected a non-empty list of values")
        _check_grid_key(f"grid.{axis}", axis, values[0], base)
        labels = [_flow(value) for value in values]
        for label in labels:
            if labels.count(label) > 1:
                raise ConfigError(f"grid.{axis} lists the value {label} more than once")
        plain.append((axis, [(label, [(axis, value)]) for label, value in zip(labels, values, strict=True)]))
    return named + plain


def _bundles(axis: str, values: Any, base: Mapping[str, Any]) -> list[tuple[str, list]]:
    if not isinstance(values, Mapping) or not values:
        raise ConfigError(
            f"grid.{axis}={values!r} is invalid: expected a mapping of names to bundles of overrides, "
            f"e.g. {{gru: {{model.memory: gru}}}}"
        )
    bundles = []
    for name, bundle in values.items():
        name = str(name)
        check_name(f"grid.{axis}.{name}", name)
        bundle = {} if bundle is None else bundle
        if not isinstance(bundle, Mapping):
            raise ConfigError(
                f"grid.{axis}.{name}={bundle!r} is invalid: expected a mapping of dotted keys to values, "
                "e.g. {model.memory: none, model.frame_stack: 4}"
            )
        sets = [(f"run.{axis}", name)]
        for key, value in bundle.items():
            key = str(key)
            if key.split(".")[0] == "grid":
                raise ConfigError(f"grid.{axis}.{name}: a bundle cannot set the grid ({key})")
            _check_grid_key(f"grid.{axis}.{name}", key, value, base)
            sets.append((key, value))
        bundles.append((name, sets))
    return bundles


def _check_grid_key(where: str, key: str, value: Any, base: Mapping[str, Any]) -> None:
    """That ``key`` names a config field (with a suggestion when it does not), whatever the other axes choose."""
    try:
        _set_dotted(_deep_copy(dict(base)), key, _deep_copy(value))
    except ConfigError as err:
        raise ConfigError(f"{where}: {err}") from err


def _apply_override(tree: dict, key: str, value: Any) -> None:
    """``_set_dotted``, except that ``grid.AXIS`` names an axis (its dots belong to the axis) and
    ``grid.slurm.KEY`` one cluster setting."""
    if key.split(".")[0] != "grid":
        _set_dotted(tree, key, value)
        return
    rest = key[len("grid.") :]
    if not rest:
        raise ConfigError(f"override {key!r}: name the grid entry, e.g. grid.run.seed=[0, 1]")
    grid = tree.get("grid")
    if not isinstance(grid, dict):
        grid = tree["grid"] = {}
    setting, _, sub = rest.partition(".")
    if setting == SLURM and sub:
        if not isinstance(grid.get(setting), dict):
            grid[setting] = {}
        grid[setting][sub] = value
    else:
        grid[rest] = value


def _flow(value: Any) -> str:
    """A value as one line of YAML (``0.99``, ``max``, ``[0, 9]``, ``{lm: random}``)."""
    text = yaml.safe_dump(value, default_flow_style=True, width=10_000, sort_keys=False).strip()
    return text[: -len("\n...")].strip() if text.endswith("\n...") else text.removesuffix("...").strip()


def _choice(key: str, value: str, choices: tuple[str, ...]) -> None:
    if value not in choices:
        close = difflib.get_close_matches(str(value), choices, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise ConfigError(f"{key}={value!r} is invalid{hint}; valid choices: {', '.join(choices)}")


def _unknown_key_message(full_key: str, key: str, names: list[str]) -> str:
    close = difflib.get_close_matches(key, names, n=1, cutoff=0.5)
    parent = full_key[: -len(key)]
    hint = f" (did you mean {parent + close[0]!r}?)" if close else ""
    return f"unknown config key {full_key!r}{hint}; valid keys here: {', '.join(names)}"


def _join(prefix: str, key: str) -> str:
    return f"{prefix}.{key}" if prefix else key


def _float_or_text(text: Any) -> Any:
    """A string that spells a number (``1e-3``, ``1.0e-3``, ``0.001``) as that float; anything else unchanged."""
    if not isinstance(text, str):
        return text
    try:
        return float(text)
    except ValueError:
        return text


def _is_number(value: Any) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def _is_dataclass_type(tp: Any) -> bool:
    return isinstance(tp, type) and dataclasses.is_dataclass(tp)


def _describe(tp: Any) -> str:
    args = [a for a in get_args(tp) if a is not type(None)]
    names = {int: "an int", float: "a number", str: "a string", bool: "true or false"}
    return " or ".join(names.get(a, getattr(a, "__name__", str(a))) for a in args)
