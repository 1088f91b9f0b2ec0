"""The Transformer-XL memory (``trxl``), sequence-to-one as in the authors' code (baselines.md section 1.7).

A step's features go through ``Linear(dim) + ReLU`` and ``layers`` blocks. In every block the query is the current
step only, and the keys and values are that block's *inputs* at the previous ``memory_length`` steps of the same
episode, as cached when those steps were taken: a step never attends to itself, to the future or to another episode,
and at an episode's first step the window is empty, so the attention output is exactly zero (no softmax over
padding). A block is attention, a residual (or GTrXL's GRU gate), ``Linear(dim) + ReLU``, a residual (or gate), with
layer norms before (``pre``), after (``post``) or nowhere (``none``).

State and records. A slot's state is its window, the last ``memory_length`` steps' layer inputs (memory_length,
layers, dim), oldest first; how much of it belongs to the episode is ``episode_step`` (the actor's count of decisions
since the episode start), so memory is bounded by ``memory_length`` whatever the episode's length. The buffer keeps
one record per step, that step's layer inputs (layers, dim), plus the ``memory_length`` records the slots carried
into the rollout (:meth:`history_records`), so windows reach back into the previous rollout. The training pass gets,
per sequence, the records of the ``memory_length`` steps before its start and of its own steps (S, M + P, layers,
dim), and attends with a banded causal mask: every query recomputed, every key and value the cached record (the
authors' "one new hidden state per step", in training as well). No per-step copy of a window is ever made.

Scaling is 1/sqrt(dim / heads), the scaled dot product's own: it keeps each head's logits at unit variance whatever
the number of heads (the authors' 1/sqrt(dim) shrinks them by sqrt(heads), a leftover of the shared-projection
variant). Positional encodings: ``relative`` adds a content-to-position term q . W_r sin(d) to the logits, d the
distance (1..memory_length) to the current step, as Transformer-XL does (valid for any episode length); ``absolute``
(sinusoidal) and ``learned`` add an embedding of the key's episode step to the cached inputs (keys and values), as
CleanRL does, and refuse an episode longer than ``positional_size``; ``none`` adds nothing.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor, nn
from torch.nn import functional as F

from agents.config import TrxlConfig
from agents.layers import HIDDEN_GAIN, orthogonal
from agents.memory.base import Memory

CACHE_DTYPES = {"fp32": torch.float32, "bf16": torch.bfloat16}


def sinusoid(positions: Tensor, dim: int) -> Tensor:
    """The sinusoidal encoding (len(positions), dim) of Vaswani et al.: sin on even, cos on odd features."""
    frequencies = torch.exp(torch.arange(0, dim, 2, dtype=torch.float32) * (-math.log(10000.0) / dim))
    angles = positions.float().unsqueeze(1) * frequencies
    table = torch.zeros(positions.shape[0], dim)
    table[:, 0::2] = torch.sin(angles)
    table[:, 1::2] = torch.cos(angles[:, : dim // 2])
    return table


class GRUGate(nn.Module):
    """GTrXL's gate g(x, y) = (1 - z) x + z tanh(W_g y + U_g (r x)), r and z sigmoids of W y + U x (z's shifted by
    -bias, so that a positive bias starts the block near the identity)."""

    def __init__(self, dim: int, bias: float) -> None:
        super().__init__()
        self.from_y = orthogonal(nn.Linear(dim, 3 * dim, bias=False), 1.0)
        self.from_x = orthogonal(nn.Linear(dim, 2 * dim, bias=False), 1.0)
        self.candidate = orthogonal(nn.Linear(dim, dim, bias=False), 1.0)
        self.bias = bias

    def forward(self, x: Tensor, y: Tensor) -> Tensor:
        y_r, y_z, y_g = self.from_y(y).chunk(3, dim=-1)
        x_r, x_z = self.from_x(x).chunk(2, dim=-1)
        r = torch.sigmoid(y_r + x_r)
        z = torch.sigmoid(y_z + x_z - self.bias)
        return (1 - z) * x + z * torch.tanh(y_g + self.candidate(r * x))


class Block(nn.Module):
    """One sequence-to-one block (see the module docstring)."""

    def __init__(self, config: TrxlConfig) -> None:
        super().__init__()
        dim, heads = config.dim, config.heads
        self.heads, self.head_dim = heads, dim // heads
        self.shared = config.shared_head_projections
        width = self.head_dim if self.shared else dim  # shared: one projection applied to every head's slice
        self.query, self.key, self.value = (orthogonal(nn.Linear(width, width), 1.0) for _ in range(3))
        self.out = orthogonal(nn.Linear(dim, dim), 1.0)
        self.position = (
            orthogonal(nn.Linear(dim, dim, bias=False), 1.0) if config.positional_encoding == "relative" else None
        )
        self.norm = config.layer_norm
        norms = 3 if self.norm == "pre" else 2 if self.norm == "post" else 0
        self.norms = nn.ModuleList(nn.LayerNorm(dim) for _ in range(norms))  # pre: query, keys/values, feed-forward
        self.feed_forward = nn.Sequential(orthogonal(nn.Linear(dim, dim), HIDDEN_GAIN), nn.ReLU())
        self.gates = nn.ModuleList(GRUGate(dim, config.gating_bias) for _ in range(2)) if config.gating else None

    def _project(self, layer: nn.Linear, x: Tensor) -> Tensor:
        """(S, T, dim) -> (S, heads, T, head_dim)."""
        s, t, _ = x.shape
        if self.shared:
            return layer(x.view(s, t, self.heads, self.head_dim)).transpose(1, 2)
        return layer(x).view(s, t, self.heads, self.head_dim).transpose(1, 2)

    def attend(self, query: Tensor, memory: Tensor, valid: Tensor, distances: Tensor | None) -> Tensor:
        """Attention of the queries (S, P, dim) over the cached inputs (S, K, dim) where ``valid`` (S, P, K); a query
        with no valid key gets exactly zero. ``distances``: (M, dim) sinusoids of the distances 1..M (relative)."""
        s, p, _ = query.shape
        q, k, v = self._project(self.query, query), self._project(self.key, memory), self._project(self.value, memory)
        logits = q @ k.transpose(-1, -2)  # (S, H, P, K)
        if self.position is not None and distances is not None:
            m = distances.shape[0]
            r = self.position(distances.to(q.dtype)).view(m, self.heads, self.head_dim)
            by_distance = torch.einsum("shpd,mhd->shpm", q, r)  # (S, H, P, M): the term of distance m + 1
            k_len = memory.shape[1]
            # key kk of query p sits at distance (k_len - p_len) + p - kk, i.e. index that - 1 in by_distance
            offset = k_len - p
            index = offset + torch.arange(p, device=q.device)[:, None] - torch.arange(k_len, device=q.device) - 1
            index = index.clamp(0, m - 1).expand(s, self.heads, p, k_len)
            logits = logits + by_distance.gather(-1, index)
        logits = logits.float() * (1.0 / math.sqrt(self.head_dim))
        mask = valid.unsqueeze(1)
        logits = logits.masked_fill(~mask, torch.finfo(logits.dtype).min)
        weights = torch.softmax(logits, dim=-1) * mask  # an empty window: all zeros, not uniform over padding
        attended = (weights.to(v.dtype) @ v).transpose(1, 2).reshape(s, p, -1)
        return self.out(attended)

    def forward(self, h: Tensor, memory: Tensor, valid: Tensor, distances: Tensor | None) -> Tensor:
        pre, post = self.norm == "pre", self.norm == "post"
        query = self.norms[0](h) if pre else h
        keys = self.norms[1](memory) if pre else memory
        attended = self.attend(query, keys, valid, distances)
        h = self.gates[0](h, F.relu(attended)) if self.gates is not None else h + attended
        if post:
            h = self.norms[0](h)
        update = self.feed_forward(self.norms[2](h) if pre else h)
        h = self.gates[1](h, update) if self.gates is not None else h + update
        return self.norms[1](h) if post else h


class TransformerXL(Memory):
    """The ``trxl`` memory (see the module docstring)."""

    def __init__(self, config: TrxlConfig, input_size: int) -> None:
        super().__init__()
        self.config = config
        dim, layers, length = config.dim, config.layers, config.memory_length
        self.embed = nn.Sequential(orthogonal(nn.Linear(input_size, dim), HIDDEN_GAIN), nn.ReLU())
        self.blocks = nn.ModuleList(Block(config) for _ in range(layers))
        self.output_size = dim
        self.history = length
        self.state_shape = (length, layers, dim)
        self.record_shape = (layers, dim)
        self.state_dtype = CACHE_DTYPES[config.cache_dtype]
        self.encoding = config.positional_encoding
        self.distances: Tensor | None
        self.register_buffer("distances", None)
        if self.encoding == "relative":
            self.distances = sinusoid(torch.arange(1, length + 1), dim)
        elif self.encoding == "absolute":
            self.register_buffer("positions", sinusoid(torch.arange(config.positional_size), dim))
        elif self.encoding == "learned":
            self.positions = nn.Parameter(torch.randn(config.positional_size, dim) * 0.02)

    def step(self, features: Tensor, state: Tensor, episode_step: Tensor | None = None) -> tuple[Tensor, Tensor]:
        if episode_step is None:
            raise ValueError("the trxl memory needs each slot's episode_step (decisions since its episode start)")
        if self.encoding in ("absolute", "learned"):
            longest = int(episode_step.max())
            if longest > self.config.positional_size:
                raise ValueError(
                    f"model.trxl.positional_encoding={self.encoding!r} covers model.trxl.positional_size="
                    f"{self.config.positional_size} episode steps, and an episode reached step {longest}: use "
                    "'relative' (valid for any episode length) or a larger positional_size"
                )
        placeholder = state.new_zeros((state.shape[0], 1, *self.record_shape))  # the step itself: never attended
        records = torch.cat((state, placeholder), dim=1)
        output, inputs = self._run(features.unsqueeze(1), records, episode_step.unsqueeze(1))
        next_state = torch.cat((state[:, 1:], inputs.to(state.dtype)), dim=1)
        return output.squeeze(1), next_state

    def record(self, state: Tensor, next_state: Tensor) -> Tensor:
        return next_state[:, -1]  # the step's own layer inputs, the newest entry of its window

    def history_records(self, state: Tensor) -> Tensor:
        return state

    def sequences(self, features: Tensor, records: Tensor, mask: Tensor, episode_step: Tensor | None = None) -> Tensor:
        if episode_step is None:
            raise ValueError("the trxl memory needs each step's episode_step (decisions since its episode start)")
        s, p = mask.shape
        padded = features.new_zeros((s, p, features.shape[-1])).index_put((mask,), features)
        steps = episode_step.new_zeros((s, p)).index_put((mask,), episode_step)
        output, _ = self._run(padded, records, steps)
        return output[mask]

    def _run(self, features: Tensor, records: Tensor, episode_step: Tensor) -> tuple[Tensor, Tensor]:
        """Queries (S, P, F) at positions M..M+P-1 of the cached inputs ``records`` (S, M + P, layers, dim), their
        episode steps (S, P). Returns the outputs (S, P, dim) and the layer inputs the queries computed
        (S, P, layers, dim)."""
        p, k_len = features.shape[1], records.shape[1]
        length = self.config.memory_length
        distance = (
            (k_len - p) + torch.arange(p, device=features.device)[:, None] - torch.arange(k_len, device=features.device)
        )  # (P, K): how many steps key kk lies before query p
        reach = episode_step.clamp(max=length).unsqueeze(-1)  # the window holds this many steps of the episode
        valid = (distance >= 1) & (distance <= reach)  # (S, P, K): earlier steps of the episode, within the window
        h = self.embed(features)
        position = None
        if self.encoding in ("absolute", "learned"):  # the episode step of every key, from the first query's
            key_step = episode_step[:, :1] - (k_len - p) + torch.arange(k_len, device=features.device)
            position = self.positions[key_step.clamp(0, self.config.positional_size - 1)]  # (S, K, dim)
        inputs = []
        for layer, block in enumerate(self.blocks):
            inputs.append(h)
            memory = records[:, :, layer].to(h.dtype)
            if position is not None:
                memory = memory + position.to(h.dtype)
            h = block(h, memory, valid, self.distances)
        return h, torch.stack(inputs, dim=2)
