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

import torch
from torch import Tensor, nn
from torch.nn import functional as F

from agents.config import LruConfig
from agents.layers import orthogonal
from agents.memory.scan import ScanMemory, complex_dtype, linear_scan, widen


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
        self.input_re = nn.Parameter(torch.randn(states, dim) / math.sqrt(2 * dim))
        self.input_im = nn.Parameter(torch.randn(states, dim) / math.sqrt(2 * dim))
        self.output_re = nn.Parameter(torch.randn(dim, states) / math.sqrt(states))
        self.output_im = nn.Parameter(torch.randn(dim, states) / math.sqrt(states))
        self.skip = nn.Parameter(torch.randn(dim))
        self.norm = nn.LayerNorm(dim)
        self.out = orthogonal(nn.Linear(dim, dim), 1.0)

    def decay(self) -> Tensor:
        """lambda (states,), complex, |lambda| < 1."""
        return torch.exp(torch.complex(-torch.exp(self.nu_log), torch.exp(self.theta_log)))

    def forward(self, x: Tensor, state: Tensor) -> tuple[Tensor, Tensor]:
        u = widen(self.norm(x))
        decay = self.decay().to(complex_dtype(u.dtype))
        gamma = torch.sqrt(1 - decay.abs() ** 2)
        inputs = (
            torch.complex(u @ self.input_re.T.to(u.dtype), u @ self.input_im.T.to(u.dtype)) * gamma
        )  # (S, T, states)
        start = torch.view_as_complex(widen(state).reshape(-1, self.states, 2).contiguous())
        h = linear_scan(decay.view(1, 1, -1), inputs, start)
        y = (
            h.real @ self.output_re.T.to(u.dtype) - h.imag @ self.output_im.T.to(u.dtype) + self.skip * u
        )  # Re(C h) + D u
        y = self.out(F.gelu(y).to(x.dtype))
        final = torch.view_as_real(h[:, -1]).reshape(-1, self.state_size)
        return x + y, final


class LRU(ScanMemory):
    """``layers`` LRU blocks of width ``dim`` (the model's ``memory_size``)."""

    def __init__(self, config: LruConfig, input_size: int, dim: int, layers: int) -> None:
        states = config.state_size or dim
        super().__init__(input_size, dim, [LRUBlock(dim, states, config) for _ in range(layers)])
