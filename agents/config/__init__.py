"""The config room: typed, documented training configuration loaded from YAML.

A config file has the blocks ``env``, ``model``, ``ppo``, ``run`` and ``eval`` (and an optional ``grid`` that
``scripts/sweep.py`` expands into runs); every block is a dataclass and every field documents itself. Loading is
strict: an unknown key fails with the closest valid name, a value of the wrong type or outside its range fails with
what would have been valid. Command-line overrides (``--set ppo.gamma=0.995``) are parsed as YAML scalars and
validated the same way.

Example::

    env:   {id: ProofOfMemory-v0, options: {delay: 4}}
    model: {memory: gru, memory_size: 64, hidden_size: 64}
    ppo:   {learning_rate: {initial: 3.0e-4, final: 1.0e-4}, sequence_length: max}
    run:   {total_steps: 200000, workers: 16, worker_steps: 64, seed: 1}

Where what lives (this face re-exports the public names, so ``from agents.config import X`` is enough):

* :mod:`agents.config.schema`: the blocks (:class:`Config` and its parts), each checking itself;
* :mod:`agents.config.tasks`: an environment's resolved reset options and the task names made of them;
* :mod:`agents.config.building`: strict building of blocks from nested dicts, dotted keys, overrides, and back;
* :mod:`agents.config.grids`: grid expansion (axes, bundles, points; the format is in its docstring);
* :mod:`agents.config.loading`: YAML files and dicts in, a validated config out; ``config.yaml`` text;
* :mod:`agents.config.resume`: the one table of what a resume may change and what the records do not depend on.

The config sits on the memories' floor: it reads the memory registry (:mod:`agents.memory`), for ``model.memory``'s
choices and the memories' settings blocks (``model.trxl``, ``model.lru``, ...: each memory's file defines its own),
and the small shared modules (:mod:`agents.settings`), and nothing above it. Loading it imports the memories (and
torch).
"""

from __future__ import annotations

from agents.config.building import config_to_dict, differing_keys, parse_override
from agents.config.grids import (
    GRID_SETTINGS,
    NAMED_AXES,
    RESERVED_NAMES,
    GridPoint,
    check_name,
    expand_grid,
    grid_panel,
    grid_slurm,
)
from agents.config.loading import config_from_dict, dump_config, load_config, read_config_file
from agents.config.resume import (
    CHANGE_RECORDS,
    LENGTH_KEY,
    NOT_IN_DIGEST,
    RESULT_NEUTRAL,
    ROUNDING_ONLY,
    SETTINGS,
    Setting,
    in_digest,
    resume_changes,
    resume_config,
    resume_may_change,
    sets_length,
    with_neutral_settings,
)
from agents.config.schema import (
    DEFAULT_EVAL_SEEDS,
    ENCODERS,
    NO_LM,
    WANDB_MODES,
    Config,
    EnvConfig,
    EvalConfig,
    HelmConfig,
    MetricConfig,
    ModelConfig,
    PPOConfig,
    RunConfig,
    Schedule,
    SlurmConfig,
    WandbConfig,
    check_cross_fields,
    check_disjoint_seeds,
    is_device_name,
    rounding_notice,
    slurm_minutes,
)
from agents.config.tasks import MAX_TASK_NAME, resolved_options, task_name
from agents.settings import ConfigError

__all__ = [
    "CHANGE_RECORDS",
    "DEFAULT_EVAL_SEEDS",
    "ENCODERS",
    "GRID_SETTINGS",
    "LENGTH_KEY",
    "MAX_TASK_NAME",
    "NAMED_AXES",
    "NOT_IN_DIGEST",
    "NO_LM",
    "RESERVED_NAMES",
    "RESULT_NEUTRAL",
    "ROUNDING_ONLY",
    "SETTINGS",
    "WANDB_MODES",
    "Config",
    "ConfigError",
    "EnvConfig",
    "EvalConfig",
    "GridPoint",
    "HelmConfig",
    "MetricConfig",
    "ModelConfig",
    "PPOConfig",
    "RunConfig",
    "Schedule",
    "Setting",
    "SlurmConfig",
    "WandbConfig",
    "check_cross_fields",
    "check_disjoint_seeds",
    "check_name",
    "config_from_dict",
    "config_to_dict",
    "differing_keys",
    "dump_config",
    "expand_grid",
    "grid_panel",
    "grid_slurm",
    "in_digest",
    "is_device_name",
    "load_config",
    "parse_override",
    "read_config_file",
    "resolved_options",
    "resume_changes",
    "resume_config",
    "resume_may_change",
    "rounding_notice",
    "sets_length",
    "slurm_minutes",
    "task_name",
    "with_neutral_settings",
]
