"""The config's schema: one dataclass per block (``env``, ``model``, ``ppo``, ``run``, ``eval``, their sub-blocks, and
``grid.slurm``), every field documented with its default and bounds (:func:`agents.settings.param`), every block
checking what its field types cannot express (``check``), and :class:`Config`, a whole run.

The memories' blocks (``model.trxl``, ``model.lru``, ...) are not written here: each memory's file brings its
settings dataclass in its spec, and :class:`ModelConfig` gets one field per memory with settings from the registry
(:data:`agents.memory.MEMORY_SPECS`, in its order), as it gets ``model.memory``'s choices.
"""

from __future__ import annotations

import difflib
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import envs
from agents.config.tasks import task_name
from agents.memory import MEMORY_MODULES, MEMORY_SPECS, memory_class, memory_spec
from agents.settings import ConfigError, Settings, check_choice, param

NO_LM = "none"
DEFAULT_EVAL_SEEDS = 30  # the paper: 30 novel seeds x 5 repetitions


@dataclass
class Schedule(Settings):
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
class MetricConfig(Settings):
    """The task's metric when the metric table (agents/analysis/metrics.py) has none for the env id, or to replace it:
    an entry of the final info (e.g. a success flag), with its plot label and range. Empty key: the table's metric, or
    the episode return for an id it does not know."""

    key: str = param("", "final-info entry that is the task's metric (empty: the table's, else the return)")
    label: str = param("", "axis label of plots (empty: the key)")
    low: float | None = param(None, "smallest value the metric takes (null: unbounded)")
    high: float | None = param(None, "largest value the metric takes (null: unbounded)")

    def check(self, prefix: str) -> None:
        if self.low is not None and self.high is not None and self.low > self.high:
            raise ConfigError(f"{prefix}.low={self.low} is above {prefix}.high={self.high}: expected low <= high")


@dataclass
class EnvConfig(Settings):
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

    def check(self, prefix: str) -> None:
        from envs.gymnasium_core import IMAGE_LAYOUTS, VECTORIZATIONS

        check_choice(f"{prefix}.vectorization", self.vectorization, VECTORIZATIONS)
        check_choice(f"{prefix}.image_layout", self.image_layout, IMAGE_LAYOUTS)
        if self.native:
            try:  # a one-slot core validates the options exactly as training will (families differ per variant)
                envs.make_core(self.id, 1, self.options)
            except ValueError as err:
                raise ConfigError(f"{prefix}.options: {err}") from err
        else:
            _check_gymnasium_env(self, prefix)
        _seed_range(f"{prefix}.train_seeds", self.train_seeds)


@dataclass
class HelmConfig(Settings):
    """The HELM branch: grayscale frame -> random projection -> frozen Hopfield retrieval over a language model's
    token embeddings -> the frozen causal transformer with a memory of the episode's last ``mem_len`` steps.
    Its output joins the CNN features; it is computed once during the rollout and cached (agents/policy/helm.py)."""

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

    def check(self, prefix: str) -> None:
        if self.random_width % self.random_heads:
            raise ConfigError(
                f"{prefix}.random_width={self.random_width} is invalid: expected a multiple of "
                f"{prefix}.random_heads={self.random_heads}"
            )


# ``model.encoder``'s choices: an image encoder (the vector inputs then go through one layer of
# ``vector_encoder_size``; agents.policy.models.IMAGE_ENCODERS builds them), or ``mlp`` for observations without an
# image (the vector inputs go through an MLP of ``mlp_sizes``).
ENCODERS: dict[str, str] = {
    "nature_cnn": "image observations",
    "mlp": "vector observations: an MLP of model.mlp_sizes",
}


def with_memory_blocks(cls: type) -> type:
    """``cls`` (a block, before ``@dataclass``) with a field per registered memory that has settings: ``<name>``, its
    settings dataclass with its defaults, after the fields written in the class, in the registry's order."""
    for spec in MEMORY_SPECS.values():
        if spec.settings is None:
            continue
        if spec.name in cls.__annotations__:  # a memory named like a field of the block (helm, encoder...)
            raise TypeError(f"memory {spec.name!r} ({spec.module}): its settings block would replace model.{spec.name}")
        cls.__annotations__[spec.name] = spec.settings
        doc = f"settings of the memory {spec.name} (used with memory: {spec.name}; {spec.module})"
        setattr(cls, spec.name, param(spec.settings(), doc))
    return cls


@dataclass
@with_memory_blocks
class ModelConfig(Settings):
    """The actor-critic: encoders -> memory -> body -> separate policy and value streams. A memory with settings has
    its block here, ``model.<name>`` (added from the registry, :func:`with_memory_blocks`)."""

    encoder: str = param("nature_cnn", "observation encoder (agents.config.ENCODERS): nature_cnn (images) or mlp")
    memory: str = param(
        "gru",
        f"memory module (agents.memory.MEMORY_MODULES): {', '.join(MEMORY_MODULES)}, or a class of your own by "
        "import path, 'package.module:ClassName' (docs/memory.md)",
    )
    memory_size: int = param(512, "width of the memory: a recurrent layer's hidden units, a block's width", low=1)
    memory_layers: int = param(1, "stacked layers (or blocks) of the memory", low=1)
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
    # model.<memory>: the settings blocks of the registered memories follow here (with_memory_blocks)

    def check(self, prefix: str) -> None:
        check_choice(f"{prefix}.encoder", self.encoder, tuple(ENCODERS))
        if not self.mlp_sizes or any(size < 1 for size in self.mlp_sizes):
            raise ConfigError(
                f"{prefix}.mlp_sizes={self.mlp_sizes!r} is invalid: expected a non-empty list of ints >= 1"
            )
        if ":" in self.memory:  # a memory of the user's own, by import path
            try:
                memory_class(self.memory)
            except (ImportError, AttributeError, TypeError, ValueError) as err:
                raise ConfigError(f"{prefix}.memory={self.memory!r}: {err}") from err
        else:
            check_choice(f"{prefix}.memory", self.memory, tuple(MEMORY_MODULES))
            spec = MEMORY_SPECS[self.memory]
            if spec.check is not None:  # what spans this block and the memory's own (e.g. widths that must divide)
                spec.check(self, prefix)
        if self.memory_options and ":" not in self.memory:
            raise ConfigError(
                f"{prefix}.memory_options={self.memory_options!r} is only for a memory given by import path; "
                f"{self.memory!r} takes its settings from {prefix}.{self.memory} (when it has a block)"
            )


@dataclass
class PPOConfig(Settings):
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

    def check(self, prefix: str) -> None:
        check_choice(f"{prefix}.advantage_normalization", self.advantage_normalization, ("minibatch", "batch", "none"))
        length = self.sequence_length
        if isinstance(length, str) and length != "max" or isinstance(length, int) and length < 1:
            raise ConfigError(f"{prefix}.sequence_length={length!r} is invalid: expected an int >= 1 or 'max'")


WANDB_MODES = ("online", "offline", "disabled")


@dataclass
class WandbConfig(Settings):
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

    def check(self, prefix: str) -> None:
        if self.mode is not None:  # null: W&B's own setting (WANDB_MODE)
            check_choice(f"{prefix}.mode", self.mode, WANDB_MODES)


@dataclass
class RunConfig(Settings):
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

    def check(self, prefix: str) -> None:
        check_choice(f"{prefix}.precision", self.precision, ("fp32", "bf16"))
        if not is_device_name(self.device):
            raise ConfigError(f"{prefix}.device={self.device!r} is invalid; valid choices: 'cpu', 'cuda', 'cuda:N'")


@dataclass
class EvalConfig(Settings):
    """Evaluation on novel seeds during training (the paper: 30 seeds x 5 repetitions, actions sampled)."""

    interval: int = param(0, "updates between evaluations (0: none during training)", low=0)
    seeds: list[int] = param([], "inclusive range [low, high] of novel seeds (empty: the 30 after env.train_seeds)")
    repetitions: int = param(5, "episodes per seed", low=1)
    greedy: bool = param(False, "act by argmax instead of sampling (the paper samples)")
    seed: int = param(0, "seed of the evaluation's action sampling", low=0)

    def check(self, prefix: str) -> None:
        _seed_range(f"{prefix}.seeds", self.seeds, allow_empty=True)


@dataclass
class SlurmConfig(Settings):
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

    def check(self, prefix: str) -> None:
        if isinstance(self.time, int):  # YAML 1.1 reads an unquoted 24:00:00 as the integer 86400
            raise ConfigError(
                f"{prefix}.time={self.time!r} is invalid: write the time limit as a quoted string, e.g. '24:00:00' "
                "or '90' (minutes); unquoted, YAML reads 24:00:00 as the number 86400"
            )
        if self.time != "":
            slurm_minutes(self.time, f"{prefix}.time")


@dataclass
class Config(Settings):
    """A whole training run. ``grid`` (its format: :mod:`agents.config.grids`) is expanded by
    :func:`~agents.config.grids.expand_grid` for ``scripts/sweep.py``; a config that has one is not a single run."""

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
        spec = memory_spec(model.memory)
        parts = [] if spec is not None and spec.stateless else [memory]
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


def check_cross_fields(config: Config) -> None:
    """The checks of a whole run's config that span blocks (a grid's base is not a run: its points are checked)."""
    if config.run.total_steps < config.batch_size:
        raise ConfigError(
            f"run.total_steps={config.run.total_steps} is smaller than one batch "
            f"(run.workers x run.worker_steps = {config.batch_size}): expected at least {config.batch_size}"
        )
    spec = memory_spec(config.model.memory)
    if spec is not None and spec.stateless and config.ppo.sequence_length not in ("max", 1):
        raise ConfigError(
            f"ppo.sequence_length={config.ppo.sequence_length!r} needs a memory module; "
            f"with model.memory={config.model.memory} use 'max' or 1 (every step is its own sequence)"
        )
    check_disjoint_seeds(config.env.train_seeds, config.eval_seeds)


def check_disjoint_seeds(train: list[int], evaluation: list[int]) -> None:
    """Evaluation seeds must be novel: refuse a range that overlaps the training range, naming both."""
    if evaluation[0] <= train[1] and train[0] <= evaluation[1]:
        raise ConfigError(
            f"evaluation seeds [{evaluation[0]}, {evaluation[1]}] overlap the training seeds (env.train_seeds) "
            f"[{train[0]}, {train[1]}]: evaluate on novel seeds, e.g. [{train[1] + 1}, {train[1] + DEFAULT_EVAL_SEEDS}]"
        )


def is_device_name(name: str) -> bool:
    """Whether ``name`` is a device this project runs on: ``cpu``, ``cuda`` or ``cuda:N``."""
    return name == "cpu" or name == "cuda" or name.startswith("cuda:") and name[5:].isdigit()


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
