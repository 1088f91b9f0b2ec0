"""The memory modules, one file per memory family, and their one registry (:data:`MEMORY_SPECS`).

A memory sits between the encoders and the body of :class:`agents.policy.models.ActorCritic`. The actor, the rollout
buffer, the sequence batching and the PPO update only speak this interface (:class:`agents.memory.base.Memory`), so a
new memory is one new file here (see "The registry" below):

* ``output_size``: width of its output.
* **State** (``state_shape``, ``state_dtype``): what a slot carries from one decision to the next, one tensor per
  slot; zeros are an episode start (the actor clears a slot by zeroing its row), and a checkpoint stores it as is,
  so a resume restores it bit for bit.
* ``step(features, state, episode_step)``: one decision of B slots; ``episode_step`` (B,) counts the decisions
  since each slot's episode start (a window memory reads how much of its window is the episode's from it).
* ``acting_cache(state, episode_step)`` (optional, None by default): what acting may keep from step to step instead
  of recomputing it from the state (a transformer's window, as its attention reads it); ``step`` then takes it as
  ``cache`` and advances it in place. The actor rebuilds it when the weights change or the state is replaced.
* **Records** (``record_shape``, :meth:`~agents.memory.base.Memory.record`): what the buffer keeps of every step.
  A recurrent memory keeps the state fed into the step; a transformer the step's layer inputs.
* ``history``: ``None`` when the training pass needs the record at each sequence start only (truncated BPTT from
  stored start states); an int h when it needs the h records before each sequence start and the sequence's own
  records. The buffer then also keeps h records from before the rollout (``history_records`` of the state the slots
  carried in, as frame stacks carry their k - 1 frames) and gathers (S, h + P, ...) per minibatch, never a window per
  step.
* ``sequences(features, records, mask, episode_step)``: the training pass over the real steps of S padded sequences.
* ``stateless``: no memory at all (every step is a sequence of its own).

The registry. Every module of this package is imported when the package is (:func:`pkgutil.iter_modules` over its
directory, file names starting with ``_`` left out), and each memory file exports its specs as ``MEMORIES = (
MemorySpec(...), ...)`` (:class:`agents.memory.base.MemorySpec`): its name (``model.memory``), its label and colour
in figures, its builder, its settings dataclass (the block ``model.<name>``, with defaults, ranges and its own
checks), a check spanning the model block and its own, the method names of its variants. :data:`MEMORY_SPECS` holds
them in a fixed order, by each spec's ``order`` (the built-ins: none 0, gru 10, lstm 20, trxl 30, lru 40, ffm 50,
mamba 60, mamba2 70; a spec that sets none comes after them), then file name, then place in its file. The config
(``model.memory``'s choices, the ``model.<name>`` blocks), the figures (labels, colours, legend order) and the
benchmark scripts (their method lists) read it and name no memory. So adding a built-in memory is one new file here,
and removing a memory's file leaves the package and every other memory working (its name is then refused with the
list of valid ones). Shared machinery exports no spec: :mod:`agents.memory.base` (the interface, the spec),
:mod:`agents.memory.scan` (the parallel scan), :mod:`agents.memory.ssm` (the state-space memories' convolution),
:mod:`agents.memory.packed_gru` (the GRU's CPU recurrence). The memory files' public names (their ``__all__``: the
memory classes and settings dataclasses) are this package's too (``agents.memory.RecurrentMemory``).

Families: :mod:`agents.memory.recurrent` (``none``, ``gru``, ``lstm``), :mod:`agents.memory.transformer` (``trxl``),
and the linear recurrences on the shared parallel scan (:mod:`agents.memory.scan`): :mod:`agents.memory.lru`
(``lru``), :mod:`agents.memory.ffm` (``ffm``), :mod:`agents.memory.mamba` (``mamba``), :mod:`agents.memory.mamba2`
(``mamba2``: one decay per head, so its training pass is matrix products over chunks and the shared scan runs over
the chunk boundaries only).

A memory of the user's own needs no file here: ``model.memory: "package.module:ClassName"`` imports a
:class:`Memory` subclass, built as ``ClassName(input_size, model_config, **model.memory_options)``
(:func:`build_memory`; both ways are walked through in docs/memory.md).
"""

from __future__ import annotations

import importlib
import pkgutil
from collections.abc import Callable
from types import ModuleType
from typing import Any

from agents.memory.base import Memory, MemorySpec, ModelSettings


def _memory_files() -> list[ModuleType]:
    """Every module of this package, imported, in file-name order (a broken memory file fails loudly here)."""
    names = sorted(info.name for info in pkgutil.iter_modules(__path__) if not info.name.startswith("_"))
    return [importlib.import_module(f"{__name__}.{name}") for name in names]


def _collect(modules: list[ModuleType]) -> dict[str, MemorySpec]:
    """The specs the modules export (``MEMORIES``), by order, file name and place in the file; a name (or a variant's
    method name) given twice is an error naming both files."""
    found: list[tuple[int, str, int, MemorySpec]] = []
    for module in modules:
        exported = getattr(module, "MEMORIES", ())
        for place, spec in enumerate(exported):
            if not isinstance(spec, MemorySpec):
                raise TypeError(f"{module.__name__}.MEMORIES[{place}] is {spec!r}, not an agents.memory.MemorySpec")
            found.append((spec.order, module.__name__, place, spec))
    specs: dict[str, MemorySpec] = {}
    owners: dict[str, str] = {}  # memory and variant names -> the module that exports them
    for _, module_name, _, spec in sorted(found, key=lambda entry: entry[:3]):
        for name in (spec.name, *spec.variants):
            if name in owners:
                raise ValueError(f"memory name {name!r} is exported twice: by {owners[name]} and by {module_name}")
            owners[name] = module_name
        specs[spec.name] = spec
    return specs


_MODULES = _memory_files()

# The one registry: name -> spec, in the registry's order (the config validation reads its keys).
MEMORY_SPECS: dict[str, MemorySpec] = _collect(_MODULES)

# name -> builder(model config, input size), as the model builds its memory.
MEMORY_MODULES: dict[str, Callable[[ModelSettings, int], Memory]] = {
    name: spec.builder for name, spec in MEMORY_SPECS.items()
}


def memory_spec(name: str) -> MemorySpec | None:
    """The spec of a registered memory, None for any other name (an import path, a name no file exports)."""
    return MEMORY_SPECS.get(name)


def memory_class(path: str) -> type[Memory]:
    """The :class:`Memory` subclass named by an import path ``"package.module:ClassName"`` (the module is imported;
    it must be importable from the working directory or ``PYTHONPATH``, in every process that trains, evaluates or
    resumes the run)."""
    module_name, _, attribute = path.partition(":")
    if not module_name or not attribute:
        raise ValueError(f"expected an import path 'package.module:ClassName', got {path!r}")
    try:
        module = importlib.import_module(module_name)
    except ImportError as err:
        raise ImportError(f"cannot import module {module_name!r} ({err}); is it on PYTHONPATH?") from err
    target: object = module
    for part in attribute.split("."):
        if not hasattr(target, part):
            raise AttributeError(f"module {module_name!r} has no attribute {attribute!r}")
        target = getattr(target, part)
    if not (isinstance(target, type) and issubclass(target, Memory)):
        raise TypeError(f"{path!r} is {target!r}, not a subclass of agents.memory.Memory")
    return target


def build_memory(config: ModelSettings, input_size: int) -> Memory:
    """The memory of a model config: a registered name, or a class by import path."""
    if ":" in config.memory:
        return memory_class(config.memory)(input_size, config, **config.memory_options)
    if config.memory not in MEMORY_MODULES:  # a config validated elsewhere (the config refuses it when it loads)
        raise ValueError(f"model.memory={config.memory!r} is not a memory; valid memories: {', '.join(MEMORY_MODULES)}")
    return MEMORY_MODULES[config.memory](config, input_size)


# The memory files' public names (their __all__), so that ``from agents.memory import RecurrentMemory`` works
# whichever files there are.
_EXPORTED: dict[str, Any] = {
    name: getattr(module, name) for module in _MODULES for name in getattr(module, "__all__", ())
}


def __getattr__(name: str) -> Any:
    if name in _EXPORTED:
        return _EXPORTED[name]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "MEMORY_MODULES",
    "MEMORY_SPECS",
    "Memory",
    "MemorySpec",
    "ModelSettings",
    "build_memory",
    "memory_class",
    "memory_spec",
    *_EXPORTED,
]
