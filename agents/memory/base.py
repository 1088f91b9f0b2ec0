"""The interface every memory module implements (see the package docstring, :mod:`agents.memory`), and the spec
that a memory's file exports so that the registry finds it (:class:`MemorySpec`)."""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

import torch
from torch import Tensor, nn

from agents.settings import Settings


class ModelSettings(Protocol):
    """What a memory's builder reads of the model config (``agents.config.ModelConfig``, on the floor above, which the
    memory floor never imports): the shared sizes and, as the attribute named after it (``config.lru``), a memory's
    own settings block."""

    memory: str
    memory_size: int
    memory_layers: int
    memory_options: dict[str, Any]

    def __getattr__(self, name: str) -> Any: ...


DEFAULT_ORDER = 1000  # the built-in memories take the places 0..70; a memory that names none comes after them
NAME_PATTERN = re.compile(r"[a-z][a-z0-9_]*")  # a YAML key and a method name: model.memory: <name>, model.<name>
COLOUR_PATTERN = re.compile(r"#[0-9a-f]{6}")


class Memory(nn.Module):
    """Base class of the memory modules: features of one step in, the memory's output out.

    Subclasses set ``output_size``, ``state_shape`` (the per-slot state), ``record_shape`` (what the rollout buffer
    keeps per step) and ``history`` (None: the training pass reads the record at each sequence start; an int h: it
    reads the h records before each sequence start and the sequence's own), and implement :meth:`step` and
    :meth:`sequences`; the defaults below suit a state that is one tensor whose zeros are an episode start."""

    output_size: int
    state_shape: tuple[int, ...]
    record_shape: tuple[int, ...]
    history: int | None = None
    state_dtype: torch.dtype = torch.float32
    stateless: bool = False  # True: no memory at all, every step is a sequence of its own

    def initial_state(self, batch: int, device: torch.device | str) -> Tensor:
        """The state of ``batch`` slots at an episode start: zeros (the actor clears a slot by zeroing its row)."""
        return torch.zeros((batch, *self.state_shape), dtype=self.state_dtype, device=device)

    def step(self, features: Tensor, state: Tensor, episode_step: Tensor | None = None) -> tuple[Tensor, Tensor]:
        """One step of B slots: features (B, F), state (B, *state_shape), decisions since each slot's episode start
        (B,). Returns the output (B, output_size) and the next state."""
        raise NotImplementedError

    def acting_cache(self, state: Tensor, episode_step: Tensor | None = None) -> Any:
        """What acting may keep from one step to the next instead of recomputing it from the state at every step
        (a transformer's window, as its attention reads it), built from ``state`` (B, ...) at ``episode_step`` (B,), or
        None (the default): nothing. A memory that returns one takes it as :meth:`step`'s ``cache`` and advances it
        in place, with the outputs and next state of a step without it. The actor keeps it while the memory's
        parameters are unchanged and every slot steps, or is cleared to an episode start (which must read nothing
        of it), and builds a new one otherwise."""
        return None

    def record(self, state: Tensor, next_state: Tensor) -> Tensor:
        """What the buffer keeps of one step (B, *record_shape), from the state fed in and the state it gave: by
        default the state fed in (a recurrent memory's start state of any sequence that begins there)."""
        return state

    def history_records(self, state: Tensor) -> Tensor:
        """The ``history`` records before a rollout (B, history, *record_shape), oldest first, from the state the
        slots carry into it (only called when ``history`` is an int)."""
        raise NotImplementedError

    def sequences(self, features: Tensor, records: Tensor, mask: Tensor, episode_step: Tensor | None = None) -> Tensor:
        """Training: ``features`` (N, F) of the real steps of S sequences in sequence order, ``mask`` (S, P) their
        padding mask (a prefix of real steps per row), ``records`` what the buffer gathered for them (``history``
        None: (S, *record_shape), the record at each sequence start; an int h: (S, h + P, *record_shape), the h
        records before each sequence start and the P records of its positions), ``episode_step`` (N,) each step's
        decisions since its episode start. Returns the outputs (N, output_size) of the N steps, in the same order."""
        raise NotImplementedError


@dataclass(frozen=True)
class MemorySpec:
    """Everything about one memory, exported by its file as ``MEMORIES = (MemorySpec(...), ...)`` (a file may export
    several: ``recurrent.py`` exports ``none``, ``gru`` and ``lstm``). The registry (:mod:`agents.memory`) imports
    every module of the package and collects these; the config, the figures and the benchmark scripts read them and
    name no memory themselves.

    * ``name``: the value of ``model.memory`` (a lower-case identifier); also the method name of a run that uses it
      (``Config.method``) and, when it has settings, the key of its block (``model.<name>``).
    * ``label``, ``colour``: the agent in figures (``GRU-PPO``, ``#0072b2``: a hex colour); a derived method name
      (``gru-stack4``) shows the label without its ``-PPO`` (``GRU + 4-Stack``).
    * ``builder(model_config, input_size)``: the :class:`Memory` of a resolved ``model`` block for features of
      ``input_size`` per step (read ``model_config.memory_size``, ``model_config.<name>``...).
    * ``settings``: the dataclass of its block ``model.<name>`` (a :class:`agents.settings.Settings` of
      :func:`agents.settings.param` fields: defaults, documentation, bounds, its own ``check``), or None.
    * ``check(model_config, prefix)``: what spans the model block and its own (e.g. a width of its block that must
      divide ``memory_size``), run when ``model.memory`` names it; raise :class:`agents.settings.ConfigError`.
    * ``variants``: method names that configs give to a variant of it, with their labels (``gtrxl``: the gated
      Transformer-XL, ``model.trxl.gating: true`` under ``run.method: gtrxl``).
    * ``stateless``: no memory at all (a run is named after its other parts, else ``ppo``; every step is a sequence of
      its own, so ``ppo.sequence_length`` must be ``max`` or 1).
    * ``order``: its place in the registry (the built-ins take 0, 10, ..., 70; ties in file-name order), which is
      also the place of its agent in legends.
    """

    name: str
    label: str
    colour: str
    builder: Callable[[ModelSettings, int], Memory]
    settings: type[Settings] | None = None
    check: Callable[[ModelSettings, str], None] | None = None
    variants: Mapping[str, str] = field(default_factory=dict)
    stateless: bool = False
    order: int = DEFAULT_ORDER

    def __post_init__(self) -> None:
        # a spec is written once, by whoever adds a memory: say exactly what is wrong with it
        for name in (self.name, *self.variants):
            if not NAME_PATTERN.fullmatch(name):
                raise ValueError(f"memory name {name!r} is invalid: expected a lower-case identifier, e.g. 'my_rnn'")
        if not COLOUR_PATTERN.fullmatch(self.colour):
            raise ValueError(f"memory {self.name!r}: colour {self.colour!r} is invalid: expected '#rrggbb' (lowercase)")
        settings = self.settings
        if settings is not None and not (dataclasses.is_dataclass(settings) and issubclass(settings, Settings)):
            raise ValueError(f"memory {self.name!r}: settings {settings!r} is not a dataclass deriving from Settings")

    @property
    def module(self) -> str:
        """The module that defines the memory (its builder's): ``agents.memory.lru``."""
        return str(getattr(self.builder, "__module__", ""))
