"""A state-space memory with one decay per head (``model.memory: mamba2``; Dao and Gu 2024's Mamba-2 block), in
pure PyTorch through matrix products (the state-space duality, SSD).

Per block: the layer-normed input is projected at once to the gate z (E = expand * dim), the SSM input x (E), B and C
(``state_size`` each, shared by all heads) and one raw step size per head (E / ``head_dim`` heads). x, B and C pass
a causal depthwise convolution over the last ``conv_size`` steps and SiLU. Head h of P = ``head_dim`` channels keeps
a (P, N) state: h_t = exp(Delta_t A_h) h_{t-1} + Delta_t x_t B_t^T, read out as y_t = h_t C_t + D_h x_t, with
Delta_t = softplus(raw_t + b_h) and A_h = -exp(A_log_h). The output y * SiLU(z) is RMS-normalised, projected back to
the block's width and added to its input. Initialisation as Mamba-2: A_h uniform in [-16, -1], b_h so that Delta
starts log-uniform in [dt_min, dt_max].

Why this and :mod:`agents.memory.mamba` both: Mamba's decays are per (channel, state), so its scan moves (T, E, N)
tensors through memory several times per pass. Here a head's decay is one scalar per step, so a chunk of Q steps is
three matrix products (Q x Q scores C B^T masked by the decays between steps, the chunk's state, the carried-in
state read by C) and only the n = T / Q chunk boundaries run through the shared scan (:func:`linear_scan`). Every
decay product is exp of a non-positive sum (cumulative sums of log-decays inside a chunk, differences taken only for
j <= i), so nothing overflows on long sequences.

State per block: the convolution's last ``conv_size - 1`` inputs (conv_size - 1, E + 2N) and the heads' states
(E / P, P, N), flattened into one vector, zeros at an episode start.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor, nn
from torch.nn import functional as F

from agents.layers import orthogonal
from agents.memory.base import MemorySpec, ModelSettings
from agents.memory.scan import Layout, ScanMemory, full_precision, linear_scan, widen
from agents.memory.ssm import causal_conv, check_step_sizes
from agents.settings import ConfigError, Settings, param

__all__ = ["Mamba2", "Mamba2Config"]  # agents.memory exports them too


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


def state_space_dual(
    x: Tensor, step: Tensor, log_decay_rate: Tensor, b: Tensor, c: Tensor, start: Tensor, chunk: int
) -> tuple[Tensor, Tensor]:
    """h_t = exp(step_t a) h_{t-1} + step_t x_t b_t^T, y_t = h_t c_t for S sequences of T steps and H heads: ``x``
    (S, T, H, P), ``step`` (S, T, H) >= 0, ``log_decay_rate`` a (H,) <= 0, ``b``, ``c`` (S, T, N), ``start`` (S, H,
    P, N) the state before each sequence. Returns y (S, T, H, P) and the state after the last step (S, H, P, N),
    computed in chunks of ``chunk`` steps (steps past T are padded with step 0: decay 1, no input); one step (a
    decision of the rollout) is the recurrence itself."""
    s, t, heads, p = x.shape
    if t == 1:
        decay = (step[:, 0] * log_decay_rate)[..., None, None].exp()
        h = decay * start + (x[:, 0] * step[:, 0, :, None]).unsqueeze(-1) * b[:, 0, None, None, :]
        return (h @ c[:, 0, None, :, None]).view(s, 1, heads, p), h
    q = min(chunk, t)
    n = -(-t // q)
    pad = n * q - t
    if pad:
        x, step, b, c = (F.pad(v, (0, 0) * (v.dim() - 2) + (0, pad)) for v in (x, step, b, c))
    log_decay = (step * log_decay_rate).reshape(s, n, q, heads).cumsum(2).transpose(2, 3)  # (S, n, H, Q): sum to i
    inputs = (x * step.unsqueeze(-1)).reshape(s, n, q, heads, p).transpose(2, 3)  # (S, n, H, Q, P)
    b, c = b.reshape(s, n, 1, q, -1), c.reshape(s, n, 1, q, -1)  # (S, n, 1, Q, N)
    # inside each chunk: y_i = sum_{j <= i} exp(L_i - L_j) (c_i . b_j) inputs_j
    causal = torch.ones(q, q, dtype=torch.bool, device=x.device).tril()
    between = (log_decay.unsqueeze(-1) - log_decay.unsqueeze(-2)).masked_fill(~causal, -math.inf).exp()
    y = (between * (c @ b.transpose(-1, -2))) @ inputs  # (S, n, H, Q, P)
    # each chunk's own state from zero, and the chains of chunk states from the start state
    to_end = (log_decay[..., -1:] - log_decay).exp()  # (S, n, H, Q)
    own = (inputs * to_end.unsqueeze(-1)).transpose(-1, -2) @ b  # (S, n, H, P, N)
    chunk_decay = log_decay[..., -1].exp()[..., None, None]  # (S, n, H, 1, 1)
    ends = linear_scan(chunk_decay, own, start)  # the state after each chunk
    carried = torch.cat((start.unsqueeze(1), ends[:, :-1]), dim=1)  # the state entering each chunk
    y = y + (carried @ c.transpose(-1, -2)).transpose(-1, -2) * log_decay.exp().unsqueeze(-1)
    return y.transpose(2, 3).reshape(s, n * q, heads, p)[:, :t], ends[:, -1]


class Mamba2Block(nn.Module):
    """One residual Mamba-2 block of width ``dim``."""

    def __init__(self, dim: int, config: Mamba2Config) -> None:
        super().__init__()
        inner, states, kernel = config.expand * dim, config.state_size, config.conv_size
        if inner % config.head_dim:
            raise ValueError(
                f"model.mamba2.head_dim={config.head_dim} must divide the inner width expand x memory_size = {inner}"
            )
        heads = inner // config.head_dim
        self.inner, self.states, self.kernel, self.heads, self.head_dim = inner, states, kernel, heads, config.head_dim
        self.chunk = config.chunk_size
        self.conv_width = inner + 2 * states  # x, B and C pass the convolution
        self.conv_size = (kernel - 1) * self.conv_width
        self.state_size = self.conv_size + inner * states
        self.norm = nn.LayerNorm(dim)
        self.project_in = orthogonal(nn.Linear(dim, inner + self.conv_width + heads, bias=False), 1.0)
        self.conv = nn.Conv1d(self.conv_width, self.conv_width, kernel, groups=self.conv_width)
        step = torch.exp(
            torch.rand(heads) * (math.log(config.dt_max) - math.log(config.dt_min)) + math.log(config.dt_min)
        )
        self.step_bias = nn.Parameter(step + torch.log(-torch.expm1(-step)))  # softplus^-1(step)
        self.a_log = nn.Parameter(torch.log(torch.empty(heads).uniform_(1.0, 16.0)))
        self.skip = nn.Parameter(torch.ones(heads))
        self.out_norm = nn.RMSNorm(inner, eps=1e-5)
        self.project_out = orthogonal(nn.Linear(inner, dim, bias=False), 1.0)

    def forward(self, x: Tensor, state: Tensor, layout: Layout) -> tuple[Tensor, Tensor]:
        gate, mixed, raw_step = self.project_in(self.norm(x)).split((self.inner, self.conv_width, self.heads), dim=-1)
        mixed, tail = causal_conv(self.conv, layout.pad(mixed), state[:, : self.conv_size])  # (S, P, E + 2N)
        main, b, c = widen(mixed).split((self.inner, self.states, self.states), dim=-1)
        step = F.softplus(layout.pad(widen(raw_step)) + self.step_bias)  # (S, P, H)
        rate = -torch.exp(self.a_log.to(step.dtype))
        s, t = step.shape[:2]
        heads = main.reshape(s, t, self.heads, self.head_dim)
        h = widen(state[:, self.conv_size :]).reshape(s, self.heads, self.head_dim, self.states)
        with full_precision(x.device):  # the chunks' products and the chain of their states in fp32 under bf16 too
            y, h = state_space_dual(heads, step, rate, b, c, h, self.chunk)
        y = layout.unpad(y + self.skip[:, None] * heads).flatten(1)  # (N, E)
        norm = self.out_norm  # in the scan's precision, with the weight of a bf16 model widened to it
        y = F.rms_norm(y * F.silu(widen(gate)), norm.normalized_shape, norm.weight.to(y.dtype), norm.eps)
        y = self.project_out(y.to(x.dtype))
        return x + y, torch.cat((tail.to(state.dtype), h.reshape(s, -1).to(state.dtype)), dim=1)


class Mamba2(ScanMemory):
    """``layers`` Mamba-2 blocks of width ``dim`` (the model's ``memory_size``)."""

    def __init__(self, config: Mamba2Config, input_size: int, dim: int, layers: int) -> None:
        super().__init__(input_size, dim, [Mamba2Block(dim, config) for _ in range(layers)])


def build(config: ModelSettings, input_size: int) -> Mamba2:
    """``model.memory_layers`` Mamba-2 blocks of width ``model.memory_size``, with the block ``model.mamba2``."""
    return Mamba2(config.mamba2, input_size, config.memory_size, config.memory_layers)


def check_heads(config: ModelSettings, prefix: str) -> None:
    """The heads split the inner width: ``head_dim`` must divide ``expand x memory_size`` (a check of the model block
    and this memory's together, run when ``model.memory`` is mamba2)."""
    inner = config.mamba2.expand * config.memory_size
    if inner % config.mamba2.head_dim:
        raise ConfigError(
            f"{prefix}.mamba2.head_dim={config.mamba2.head_dim} is invalid: expected a divisor of the inner width "
            f"{prefix}.mamba2.expand x {prefix}.memory_size = {inner}"
        )


MEMORIES = (  # Paul Tol's muted purple
    MemorySpec("mamba2", "Mamba2-PPO", "#aa4499", build, settings=Mamba2Config, check=check_heads, order=70),
)
