"""The settings blocks of the built-in memories that have settings of their own (``model.trxl``, ``model.lru``,
``model.ffm``, ``model.mamba``, ``model.mamba2``), each checking itself.

The memories (:mod:`agents.memory`) receive their block as an argument and never import this module (the config is
the floor above them); a memory of the user's own takes its settings from ``model.memory_options`` instead.
"""

from __future__ import annotations

from dataclasses import dataclass

from agents.settings import ConfigError, Settings, check_choice, param


@dataclass
class TrxlConfig(Settings):
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

    def check(self, prefix: str) -> None:
        check_choice(
            f"{prefix}.positional_encoding", self.positional_encoding, ("relative", "absolute", "learned", "none")
        )
        check_choice(f"{prefix}.layer_norm", self.layer_norm, ("pre", "post", "none"))
        check_choice(f"{prefix}.cache_dtype", self.cache_dtype, ("fp32", "bf16"))
        if self.dim % self.heads:
            raise ConfigError(f"{prefix}.dim={self.dim} is invalid: expected a multiple of {prefix}.heads={self.heads}")


@dataclass
class LruConfig(Settings):
    """The Linear Recurrent Unit (``model.memory: lru``, agents/memory/lru.py): ``model.memory_layers`` residual blocks
    of width ``model.memory_size``, each a complex diagonal linear recurrence."""

    state_size: int = param(0, "complex state channels per block (0: model.memory_size)", low=0)
    r_min: float = param(0.4, "smallest initial |lambda| (the stable-init ring's inner radius)", low=0.0, high=1.0)
    r_max: float = param(0.99, "largest initial |lambda| (the ring's outer radius, < 1)", low=0.0, high=0.999999)
    max_phase: float = param(6.283185307179586, "largest initial phase of lambda (radians)", low=0.0)

    def check(self, prefix: str) -> None:
        if self.r_min > self.r_max:
            raise ConfigError(f"{prefix}.r_min={self.r_min} is invalid: expected <= {prefix}.r_max={self.r_max}")


@dataclass
class FfmConfig(Settings):
    """Fast and Forgetful Memory (``model.memory: ffm``, agents/memory/ffm.py): ``model.memory_layers`` residual
    blocks of width ``model.memory_size``, each trace_size x context_size decaying, oscillating complex traces."""

    trace_size: int = param(32, "gated input channels per block, each with context_size traces", low=1)
    context_size: int = param(4, "traces per channel (decay and frequency learned per channel x context)", low=1)
    max_horizon: float = param(1024.0, "longest initial time constant of a trace (steps)", low=1.0)


@dataclass
class MambaConfig(Settings):
    """A selective state-space memory (``model.memory: mamba``, agents/memory/mamba.py): ``model.memory_layers``
    residual Mamba blocks of width ``model.memory_size``, in pure PyTorch on the shared scan."""

    state_size: int = param(16, "SSM states per inner channel (N)", low=1)
    expand: int = param(2, "inner width = expand x memory_size", low=1)
    conv_size: int = param(4, "steps of the causal depthwise convolution before the SSM (1: none)", low=1)
    dt_rank: int = param(0, "rank of the step-size projection (0: ceil(memory_size / 16))", low=0)
    dt_min: float = param(0.001, "smallest initial step size", low=1e-6)
    dt_max: float = param(0.1, "largest initial step size", low=1e-6)

    def check(self, prefix: str) -> None:
        check_step_sizes(self, prefix)


@dataclass
class Mamba2Config(Settings):
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

    def check(self, prefix: str) -> None:
        check_step_sizes(self, prefix)


def check_step_sizes(block: MambaConfig | Mamba2Config, prefix: str) -> None:
    """The smallest initial step size of a state-space block may not exceed its largest."""
    if block.dt_min > block.dt_max:
        raise ConfigError(f"{prefix}.dt_min={block.dt_min} is invalid: expected <= {prefix}.dt_max={block.dt_max}")
