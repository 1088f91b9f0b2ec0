"""The memory modules, one module per family, and their one registry (:data:`MEMORY_MODULES`).

A memory sits between the encoders and the body of :class:`agents.policy.models.ActorCritic`. The actor, the rollout
buffer, the sequence batching and the PPO update only speak this interface (:class:`agents.memory.base.Memory`), so a
new memory is one new file here and one registry entry:

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

Families: :mod:`agents.memory.recurrent` (``none``, ``gru``, ``lstm``), :mod:`agents.memory.transformer` (``trxl``),
and the linear recurrences on the shared parallel scan (:mod:`agents.memory.scan`): :mod:`agents.memory.lru`
(``lru``), :mod:`agents.memory.ffm` (``ffm``), :mod:`agents.memory.mamba` (``mamba``), :mod:`agents.memory.mamba2`
(``mamba2``: one decay per head, so its training pass is matrix products over chunks and the shared scan runs over
the chunk boundaries only).

A memory of the user's own needs no edit here: ``model.memory: "package.module:ClassName"`` imports a
:class:`Memory` subclass, built as ``ClassName(input_size, model_config, **model.memory_options)``
(:func:`build_memory`; a walk-through is in docs/memory.md).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import TYPE_CHECKING

from agents.memory.base import Memory
from agents.memory.ffm import FFM
from agents.memory.lru import LRU
from agents.memory.mamba import Mamba
from agents.memory.mamba2 import Mamba2
from agents.memory.recurrent import NoMemory, RecurrentMemory
from agents.memory.transformer import TransformerXL

if TYPE_CHECKING:  # a builder receives the model config; the config is the floor above
    from agents.config import ModelConfig

# The one registry of memory modules (the config validation reads its keys): name -> builder(config, input size).
MEMORY_MODULES: dict[str, Callable[[ModelConfig, int], Memory]] = {
    "none": lambda config, input_size: NoMemory(input_size),
    "gru": lambda config, input_size: RecurrentMemory("gru", input_size, config.memory_size, config.memory_layers),
    "lstm": lambda config, input_size: RecurrentMemory("lstm", input_size, config.memory_size, config.memory_layers),
    "trxl": lambda config, input_size: TransformerXL(config.trxl, input_size),
    "lru": lambda config, input_size: LRU(config.lru, input_size, config.memory_size, config.memory_layers),
    "ffm": lambda config, input_size: FFM(config.ffm, input_size, config.memory_size, config.memory_layers),
    "mamba": lambda config, input_size: Mamba(config.mamba, input_size, config.memory_size, config.memory_layers),
    "mamba2": lambda config, input_size: Mamba2(config.mamba2, input_size, config.memory_size, config.memory_layers),
}


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


def build_memory(config: ModelConfig, input_size: int) -> Memory:
    """The memory of a model config: a registered name, or a class by import path."""
    if ":" in config.memory:
        return memory_class(config.memory)(input_size, config, **config.memory_options)
    return MEMORY_MODULES[config.memory](config, input_size)


__all__ = [
    "FFM",
    "LRU",
    "MEMORY_MODULES",
    "Mamba",
    "Mamba2",
    "Memory",
    "NoMemory",
    "RecurrentMemory",
    "TransformerXL",
    "build_memory",
    "memory_class",
]
