"""The Linear Recurrent Unit (``model.memory: lru``; Orvieto et al., ICML 2023), on the shared scan.

Per block and state channel, a complex diagonal recurrence h_t = lambda * h_{t-1} + gamma * (B u_t), with
lambda = exp(-exp(nu) + i exp(theta)): the exponential parametrisation keeps |lambda| < 1 for any nu, and nu, theta
start on a ring r_min <= |lambda| <= r_max with phases in [0, max_phase] (the stable initialisation).
gamma = sqrt(1 - |lambda|^2) normalises the input so that every channel's state has the input's scale whatever its
memory. The output is real: y_t = Re(C h_t) + D * u_t, then GELU and a linear layer back to the block's width, added
to the block's input (u_t is the layer-normed input). The state is the complex h, stored as (real, imaginary).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor, nn
from torch.nn import functional as F

from agents.layers import orthogonal
from agents.memory.base import MemorySpec, ModelSettings
from agents.memory.scan import Layout, ScanMemory, complex_dtype, full_precision, widen
from agents.settings import ConfigError, Settings, param

__all__ = ["LRU", "LruConfig"]  # agents.memory exports them too


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


class LRUBlock(nn.Module):
    """One residual LRU block of width ``dim`` with ``states`` complex state channels."""

    def __init__(self, dim: int, states: int, config: LruConfig) -> None:
        super().__init__()
        self.states = states
        self.state_size = 2 * states
        u1, u2 = torch.rand(states), torch.rand(states)
        radius_sq = u1 * (config.r_max**2 - config.r_min**2) + config.r_min**2  # uniform on the ring's area
        self.nu_log = nn.Parameter(torch.log(-0.5 * torch.log(radius_sq)))
        self.theta_log = nn.Parameter(torch.log(config.max_phase * u2 + 1e-8))
        # B and C with their real and imaginary parts interleaved (B's rows, C's columns: re, im, re, im, ...), so
        # that B u and Re(C h) are one contiguous product each on the (..., states, 2) layout of a complex tensor
        self.input_weight = nn.Parameter(torch.randn(2 * states, dim) / math.sqrt(2 * dim))
        output = torch.randn(dim, states, 2) / math.sqrt(states)
        output[..., 1] *= -1  # Re(C h) = C_re h_re - C_im h_im: the column of h_im holds -C_im
        self.output_weight = nn.Parameter(output.reshape(dim, 2 * states))
        self.skip = nn.Parameter(torch.randn(dim))
        self.norm = nn.LayerNorm(dim)
        self.out = orthogonal(nn.Linear(dim, dim), 1.0)

    def _load_from_state_dict(self, state_dict: dict, prefix: str, *args: object, **kwargs: object) -> None:
        """Checkpoints written before B and C were interleaved (6b9ff9a..10bf6ec) hold them as four matrices
        (input_re/_im, output_re/_im): converted here, so those runs still load, evaluate and resume."""
        old = [f"{prefix}{name}" for name in ("input_re", "input_im", "output_re", "output_im")]
        if all(key in state_dict for key in old):
            input_re, input_im, output_re, output_im = (state_dict.pop(key) for key in old)
            state_dict[f"{prefix}input_weight"] = torch.stack((input_re, input_im), dim=1).reshape(
                -1, input_re.shape[1]
            )
            state_dict[f"{prefix}output_weight"] = torch.stack((output_re, -output_im), dim=2).reshape(
                output_re.shape[0], -1
            )
        super()._load_from_state_dict(state_dict, prefix, *args, **kwargs)

    def decay(self) -> Tensor:
        """lambda (states,), complex, |lambda| < 1; complex64 also from the bfloat16 weights of a bf16 acting copy
        (torch has no complex bfloat16)."""
        return torch.exp(torch.complex(-torch.exp(widen(self.nu_log)), torch.exp(widen(self.theta_log))))

    def forward(self, x: Tensor, state: Tensor, layout: Layout) -> tuple[Tensor, Tensor]:
        u = widen(self.norm(x))  # (N, dim)
        with full_precision(u.device):  # lambda, gamma and the recurrence in fp32 (complex64) under bf16 too
            decay = self.decay().to(complex_dtype(u.dtype))
            gamma = torch.sqrt(1 - decay.abs() ** 2)
            # gamma scales B's rows (re and im of a state alike), not the (N, 2 states) product: a pass over the
            # weights instead of two over the steps (forward and backward)
            scaled_input = self.input_weight * gamma.repeat_interleave(2).unsqueeze(1)
        # B u is a projection as any other: bfloat16 under autocast, widened before it enters the recurrence
        projected = widen(u @ scaled_input.T.to(u.dtype))
        with full_precision(u.device):
            inputs = torch.view_as_complex(projected.unflatten(-1, (self.states, 2)))  # gamma B u
            start = torch.view_as_complex(widen(state).reshape(-1, self.states, 2).contiguous())
            h = torch.view_as_real(layout.scan(decay, inputs, start)).flatten(1)  # (N, 2 states)
        y = h @ self.output_weight.T.to(u.dtype) + self.skip * u  # Re(C h) + D u
        y = self.out(F.gelu(y).to(x.dtype))
        return x + y, layout.last(h)


class LRU(ScanMemory):
    """``layers`` LRU blocks of width ``dim`` (the model's ``memory_size``)."""

    def __init__(self, config: LruConfig, input_size: int, dim: int, layers: int) -> None:
        states = config.state_size or dim
        super().__init__(input_size, dim, [LRUBlock(dim, states, config) for _ in range(layers)])


def build(config: ModelSettings, input_size: int) -> LRU:
    """``model.memory_layers`` LRU blocks of width ``model.memory_size``, with the block ``model.lru``."""
    return LRU(config.lru, input_size, config.memory_size, config.memory_layers)


MEMORIES = (  # Paul Tol's muted indigo
    MemorySpec("lru", "LRU-PPO", "#332288", build, settings=LruConfig, order=40),
)
