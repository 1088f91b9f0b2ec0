"""Task names: the reset options an environment resolves, and the short name of a task in records and plots.

A task is named after its environment id and the reset options that differ from the environment's defaults
(:func:`task_name`), from the options as the environment resolves them (:func:`resolved_options`: validated,
canonical, cached per option set).
"""

from __future__ import annotations

import hashlib
import json
import re
from collections.abc import Mapping
from typing import Any

import envs
from agents.settings import deep_copy

MAX_TASK_NAME = 96  # longer default task names end in a digest of the options instead (file names stay short)
_RESOLVED: dict[tuple[str, str], tuple[dict[str, Any], dict[str, Any]]] = {}  # (id, options) -> (resolved, defaults)


def resolved_options(env_id: str, options: Mapping[str, Any] | None = None, changed_only: bool = False) -> dict:
    """The reset options of ``env_id`` with ``options`` applied, validated and canonical (a float option as a float,
    so that ``1`` and ``1.0`` agree); ``changed_only``: only those that differ from the environment's defaults."""
    if env_id not in envs.ENV_IDS:  # a gymnasium environment: its reset options are its own, without known defaults
        return deep_copy(dict(options or {}))
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
