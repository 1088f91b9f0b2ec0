"""The one rule of what a run that goes on may change, and of what the records of a run do not depend on.

:data:`SETTINGS` is the one table: for every config key (a block: every key in it) that is not simply part of the
experiment, what a resume may do with it and why, and why the config digest of the records leaves it out (or that it
does not). Everything else derives from it: :func:`resume_may_change` (``scripts/train.py --resume``, a sweep's
resume, a checkpoint under a newer ``config.yaml``), the command line's notes and refusals, and the digest of
:func:`agents.analysis.digest.experiment_settings` (:data:`NOT_IN_DIGEST`, :func:`in_digest`).

What a resume may do with a key (:attr:`Setting.resume`):

* ``lengthen`` (:data:`LENGTH_KEY`, ``run.total_steps``): raise it, and the run is lengthened
  (:func:`agents.training.logs.extend_run`);
* ``neutral``: no record of the run depends on it, so any resume may change it (:data:`RESULT_NEUTRAL`);
* ``rounding``: a resume asked for on the command line may change it although the floating-point rounding of what
  follows changes (not the experiment: it is outside the digest), and says so; a sweep's resume keeps it
  (:data:`ROUNDING_ONLY`);
* ``refused``: like every key that is not in the table, it may not change; where one might take it for a setting
  that no record depends on, :attr:`Setting.resume_why` names the record it changes (:data:`CHANGE_RECORDS`).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from agents.config.building import config_to_dict, differing_keys, parse_override
from agents.config.loading import config_from_dict
from agents.config.schema import Config
from agents.settings import ConfigError

LENGTHEN, NEUTRAL, ROUNDING, REFUSED = "lengthen", "neutral", "rounding", "refused"


@dataclass(frozen=True)
class Setting:
    """What a resume may do with a key (``lengthen``, ``neutral``, ``rounding`` or ``refused``) and why (said by the
    command line where a resume is refused or noted; empty where nothing needs saying), and why the config digest
    leaves the key out (None: the digest covers it, the key is part of the experiment)."""

    resume: str
    resume_why: str
    digest_why: str | None


SETTINGS: dict[str, Setting] = {
    "run.total_steps": Setting(LENGTHEN, "a resume may raise it: the run is lengthened", None),
    "run.progress_bar": Setting(NEUTRAL, "display only", "display"),
    "run.checkpoint_interval": Setting(
        NEUTRAL,
        "when checkpoints are taken: a run continues exactly from any of them",
        "bookkeeping (a resumed run replays the same steps)",
    ),
    "run.keep_checkpoints": Setting(NEUTRAL, "how many checkpoints stay on disk", "bookkeeping"),
    "run.wandb": Setting(
        NEUTRAL,
        "where the scalars also go; TensorBoard, training.csv and the evaluation records are the same",
        "where the logs also go",
    ),
    "env.check_seeding": Setting(
        NEUTRAL,
        "whether an environment that ignores seeds is refused; a run that goes on is the same",
        "whether an environment that ignores seeds is refused (a run that went ahead is the same)",
    ),
    "run.torch_threads": Setting(
        ROUNDING,
        "the thread count changes the rounding of the updates (the weights differ by ~1e-5 after one update), so "
        "from here on the run is not bit for bit the one an uninterrupted run would have been",
        "how fast the run computes",
    ),
    "run.device": Setting(REFUSED, "another device computes other floats", "where the run computes"),
    "run.method": Setting(REFUSED, "its name is in every record", "a name: the cell's own key"),
    "run.task": Setting(REFUSED, "its name is in every record", "a name: the cell's own key"),
    "eval.interval": Setting(
        REFUSED, "it decides the steps of the evaluation records", "how often the curve is sampled"
    ),
    "env.metric.label": Setting(REFUSED, "it is in the records' metric_spec column", "a name"),
    "run.seed": Setting(REFUSED, "", "seed: the runs of a cell are its seeds"),
    "model.helm.seed": Setting(
        REFUSED,
        "",
        "seed of HELM's random projection (and random transformer): another draw, not another agent",
    ),
    "eval.seed": Setting(REFUSED, "", "seed of the evaluation's action sampling"),
    "eval.seeds": Setting(REFUSED, "", "which novel seeds: a sample of the same level distribution"),
    "eval.repetitions": Setting(REFUSED, "", "episodes per novel seed: how precise a score is, not what it measures"),
    "env.vectorization": Setting(REFUSED, "", "how a gymnasium environment's copies run: the same episodes either way"),
    "grid": Setting(REFUSED, "", "a run's config holds no grid"),
}

# The table's views, by what a reader asks of it
(LENGTH_KEY,) = (key for key, setting in SETTINGS.items() if setting.resume == LENGTHEN)
RESULT_NEUTRAL = {key: s.resume_why for key, s in SETTINGS.items() if s.resume == NEUTRAL}
ROUNDING_ONLY = {key: s.resume_why for key, s in SETTINGS.items() if s.resume == ROUNDING}
CHANGE_RECORDS = {key: s.resume_why for key, s in SETTINGS.items() if s.resume == REFUSED and s.resume_why}
NOT_IN_DIGEST = {key: s.digest_why for key, s in SETTINGS.items() if s.digest_why is not None}


def in_digest(key: str) -> bool:
    """Whether the dotted config ``key`` is part of the experiment a run's records stand for (its config digest):
    not when :data:`NOT_IN_DIGEST` names it or a block it is in."""
    return not any(key == left or key.startswith(left + ".") for left in NOT_IN_DIGEST)


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
