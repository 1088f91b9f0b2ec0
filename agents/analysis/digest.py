"""What defines the experiment a run belongs to: the settings its records stand for, their digest (the records'
``config_digest`` column), the environment's options (``env_options``), and the words for how two runs differ.

Runs that differ only in seeds, names, device, threads or bookkeeping share a digest: what a run's records do not
depend on is the config's one table (:data:`agents.config.NOT_IN_DIGEST`, read through
:func:`agents.config.in_digest`). The config is imported where it is used, so that reading records needs numpy and
the standard library only.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from agents.config import Config


def experiment_settings(config: Config, greedy: bool | None = None, changed_only: bool = True) -> dict[str, Any]:
    """What defines the experiment of a run, as ``{dotted key: value}``: every config key but those the config's one
    table leaves out (:data:`agents.config.NOT_IN_DIGEST`),
    the env's reset options resolved (``env.options.<name>``), and ``eval.greedy`` as the evaluation used it
    (``greedy``; default: the config's). ``changed_only``: only the values that differ from the defaults (of
    :class:`agents.config.Config` and of the env's options), so that a field added to the config later leaves the
    settings of existing configs unchanged."""
    from agents.config import Config, config_to_dict, in_digest, resolved_options

    def flat(config: Config, changed: bool, greedy: bool | None = None) -> dict[str, Any]:
        tree = config_to_dict(config)
        tree["env"]["options"] = resolved_options(config.env.id, config.env.options, changed_only=changed)
        if greedy is not None:
            tree["eval"]["greedy"] = bool(greedy)
        return {key: value for key, value in _flatten(tree).items() if in_digest(key)}

    found = flat(config, changed_only, greedy)
    if not changed_only:
        return found
    defaults = flat(Config(), False)
    return {key: value for key, value in found.items() if key not in defaults or defaults[key] != value}


def config_digest(config: Config, greedy: bool | None = None) -> str:
    """The ``config_digest`` column: ``c`` and the first 12 hex digits of the SHA-256 of :func:`experiment_settings`
    (changed values only) as sorted, compact JSON; the letter keeps CSV readers from taking it for a number. Runs
    that differ only in seeds, names, device, threads or bookkeeping (:data:`agents.config.NOT_IN_DIGEST`) share it; the
    same config gives the same digest in any process and on any machine."""
    text = json.dumps(experiment_settings(config, greedy), sort_keys=True, separators=(",", ":"))
    return "c" + hashlib.sha256(text.encode()).hexdigest()[:12]


def env_options_text(config: Config) -> str:
    """The ``env_options`` column: the env's non-default reset options as sorted, compact JSON (``{}``: defaults)."""
    from agents.config import resolved_options

    changed = resolved_options(config.env.id, config.env.options, changed_only=True)
    return json.dumps(changed, sort_keys=True, separators=(",", ":"))


def _flatten(tree: Any, prefix: str = "") -> dict[str, Any]:
    if not isinstance(tree, Mapping):
        return {prefix: tree}
    found: dict[str, Any] = {}
    for key, value in tree.items():
        found.update(_flatten(value, f"{prefix}.{key}" if prefix else str(key)))
    return found


def describe_differences(settings: Mapping[str, Mapping[str, Any]]) -> str:
    """The keys whose values differ between the :func:`experiment_settings` of several runs (``{where: settings}``,
    ``where`` naming each in the sentence), as a sentence."""
    keys = sorted(set().union(*settings.values()))
    differing = [key for key in keys if len({json.dumps(s.get(key), sort_keys=True) for s in settings.values()}) > 1]
    if not differing:
        return (
            "Their saved configs agree on every key the digest covers: the records were evaluated differently "
            "(eval.greedy) or written by another version."
        )
    shown = [
        f"{key} ({', '.join(f'{json.dumps(s.get(key))} in {d}' for d, s in settings.items())})" for key in differing
    ]
    more = f" and {len(shown) - 8} more" if len(shown) > 8 else ""
    return f"Differing keys: {'; '.join(shown[:8])}{more}."
