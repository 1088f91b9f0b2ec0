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

Cost. Acting keeps, per block, what its key and value projections take of the window's entries (the cached inputs,
layer-normed with ``pre``; :class:`WindowCache`, built once from the state when the actor starts acting with new
weights or a new state, then extended in place by one entry per step), and attends without projecting them: the
key projection moves to the query and the value projection after the weighted sum (:meth:`Block.attend_window`), so
a decision reads the window's inputs (8.8 MB at 16 slots x 119 x 3 x 384, fp32) where keys and values would be
twice that, and projects nothing per entry. The state, the records and a checkpoint stay the layer inputs, so a
resume rebuilds the same cache; the window moves on without being copied (:func:`shift_window`), and a slot that
starts an episode is cleared in place. What is left of a decision is reading the weights (17.6 MB at 3 x 384 with
the MM Grid CNN's 3,136 inputs, fp32) and the window at every step, in products of 16 rows too small to reach the
memory's bandwidth (docs/baselines.md, "Speed"). The training pass runs the
single-step layers on the real steps only (the padded (S, P) layout exists for the attention alone) and projects
keys and values only for the records some query reads (a sequence that starts its episode reads none of the window
before it): there, P queries share every projected key, so projecting is the cheaper side.

Scaling is 1/sqrt(dim / heads), the scaled dot product's own: it keeps each head's logits at unit variance whatever
the number of heads (the authors' 1/sqrt(dim) shrinks them by sqrt(heads), a leftover of the shared-projection
variant). Positional encodings: ``relative`` adds a content-to-position term q . W_r sin(d) to the logits, d the
distance (1..memory_length) to the current step, as Transformer-XL does (valid for any episode length); ``absolute``
(sinusoidal) and ``learned`` add an embedding of the key's episode step to the cached inputs (keys and values), as
CleanRL does, and refuse an episode longer than ``positional_size``; ``none`` adds nothing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor, nn
from torch.nn import functional as F

from agents.layers import HIDDEN_GAIN, compute_dtype, orthogonal
from agents.memory.base import Memory, MemorySpec, ModelSettings
from agents.settings import ConfigError, Settings, check_choice, param

__all__ = ["TransformerXL", "TrxlConfig"]  # agents.memory exports them too

CACHE_DTYPES = {"fp32": torch.float32, "bf16": torch.bfloat16}


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
        check_choice(f"{prefix}.cache_dtype", self.cache_dtype, tuple(CACHE_DTYPES))
        if self.dim % self.heads:
            raise ConfigError(f"{prefix}.dim={self.dim} is invalid: expected a multiple of {prefix}.heads={self.heads}")


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


def shift_window(window: Tensor, entry: Tensor) -> Tensor:
    """``window`` (B, M, ...) one step on: its oldest entry dropped, ``entry`` (B, ...) appended, oldest first.

    A copy of the window would move M entries to add one (8.8 MB a step at 16 slots x 119 x 3 x 384, fp32), so
    without autograd the window is a view of a buffer twice its length (memory stays bounded by the window): a step
    writes the entry just after the view and returns the view one entry later, and only a full buffer is copied (the
    newest M - 1 entries into a new one, once every M steps). Each window is moved on in place at most once (the
    buffer remembers where its newest view ends): a second step from the same window copies, so every window
    returned keeps its entries. (Views made in inference mode keep no ``_base``: the view names its buffer.)"""
    entry = entry.to(window.dtype)
    length = window.shape[1]
    if torch.is_grad_enabled() and (window.requires_grad or entry.requires_grad):
        return torch.cat((window[:, 1:], entry.unsqueeze(1)), dim=1)
    buffer, start = getattr(window, "window_buffer", None), getattr(window, "window_start", 0)
    if buffer is not None and buffer.window_end == start + length < buffer.shape[1] and _is_view(window, buffer, start):
        buffer[:, start + length] = entry
        buffer.window_end, start = start + length + 1, start + 1
    else:
        buffer = window.new_empty((window.shape[0], 2 * length, *window.shape[2:]))
        buffer[:, : length - 1] = window[:, 1:]
        buffer[:, length - 1] = entry
        buffer.window_end, start = length, 0
    shifted = buffer[:, start : start + length]
    shifted.window_buffer, shifted.window_start = buffer, start
    return shifted


def _is_view(window: Tensor, buffer: Tensor, start: int) -> bool:
    """Whether ``window`` is ``buffer[:, start : start + M]`` (not a copy that kept the attributes)."""
    return (
        window.untyped_storage().data_ptr() == buffer.untyped_storage().data_ptr()
        and window.storage_offset() == buffer.storage_offset() + start * buffer.stride(1)
        and window.stride() == buffer.stride()
        and window.shape[0] == buffer.shape[0]
        and window.shape[2:] == buffer.shape[2:]
    )


@dataclass
class WindowCache:
    """What acting reads of the slots' windows, built from their states by :meth:`TransformerXL.acting_cache` and
    advanced in place by every :meth:`TransformerXL.step`: per block, the inputs of its key and value projections
    (:meth:`Block.window_inputs`) at the window's entries, (B, G, memory_length, c) (G = 1, c = dim; with shared head
    projections G = heads, c = head_dim), in a ring whose oldest entry sits at ``oldest`` (the step writes its own
    over it), and the relative encoding's projected distances (heads, head_dim, 2 memory_length: the table twice, so
    that the columns in ring order are a slice of it, see :meth:`relative`). Valid while the
    parameters are the ones it was built with; a slot cleared to an episode start needs no rebuild (it reads no
    entry)."""

    inputs: list[Tensor]
    tables: list[Tensor | None]
    oldest: int = 0

    def relative(self, layer: int) -> Tensor | None:
        """Block ``layer``'s projected distances (heads, head_dim, memory_length) with their columns in ring order
        (the oldest entry's, at ``oldest``, is the farthest distance's): a view, where a roll would copy."""
        table = self.tables[layer]
        if table is None:
            return None
        length = table.shape[-1] // 2
        return table[..., length - self.oldest : 2 * length - self.oldest]


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

    def _project(self, x: Tensor, layers: tuple[nn.Linear, ...]) -> tuple[Tensor, ...]:
        """(..., dim) through each of ``layers`` -> one (..., heads, head_dim) per layer. One product per layer, not
        one over their weights side by side: joining the weights would copy them at every call, which costs more
        than the product itself when acting (16 rows)."""
        if self.shared:  # every head's slice through the same small projections
            x = x.unflatten(-1, (self.heads, self.head_dim))
            return tuple(layer(x) for layer in layers)
        return tuple(layer(x).unflatten(-1, (self.heads, self.head_dim)) for layer in layers)

    def window_inputs(self, memory: Tensor) -> Tensor:
        """What the key and value projections take of cached inputs (..., dim): the inputs, layer-normed with
        ``pre``."""
        return self.norms[1](memory) if self.norm == "pre" else memory

    def keys_values(self, memory: Tensor) -> tuple[Tensor, Tensor]:
        """Keys and values (..., heads, head_dim) of cached inputs (..., dim)."""
        keys, values = self._project(self.window_inputs(memory), (self.key, self.value))
        return keys, values

    def queries(self, h: Tensor) -> Tensor:
        """The queries (N, heads, head_dim) of the blocks' inputs ``h`` (N, dim)."""
        (q,) = self._project(self.norms[0](h) if self.norm == "pre" else h, (self.query,))
        return q

    def relative_table(self, distances: Tensor | None) -> Tensor | None:
        """The relative encoding's projected distances (heads, head_dim, M) from their sinusoids (M, dim) of the
        distances 1..M, farthest first: column c is the term of a key M - c steps back."""
        if self.position is None or distances is None:
            return None
        table = self.position(distances.to(self.position.weight.dtype)).flip(0)
        return table.view(-1, self.heads, self.head_dim).permute(1, 2, 0)

    @staticmethod
    def relative_logits(q: Tensor, table: Tensor, keys: int) -> Tensor:
        """The relative term (heads, S, P, K) of queries (heads, S, P, head_dim) for K keys of which key kk lies
        (K - P) + p - kk steps before query p, from the ``table``'s columns (see :meth:`relative_table`). Query p's
        terms are query 0's shifted by p keys, so one product per query and distance (heads, S, P, M) and a skew
        (pad each row to K + 1, read the rows K apart) place them, where a gather would need an index per logit;
        the keys out of reach get other terms, which the mask drops."""
        h, s, p, _ = q.shape
        m = table.shape[-1]
        # (H, S P, hd) @ (H, hd, M): the table is read once per head, not broadcast to a copy per sequence
        by_distance = (q.reshape(h, s * p, -1) @ table).view(h, s, p, m)
        return F.pad(by_distance, (0, keys + 1 - m)).flatten(-2)[..., : p * keys].view(h, s, p, keys)

    def attend(self, q: Tensor, k: Tensor, v: Tensor, valid: Tensor, table: Tensor | None) -> Tensor:
        """Attention of the queries (heads, S, P, head_dim) over keys and values (heads, S, K, head_dim) where
        ``valid`` (S, P, K); a query with no valid key gets exactly zero. ``table``: the relative encoding's
        (:meth:`relative_logits`). Heads lead, so that (heads, S) is one batch dimension of contiguous matrices:
        with sequences first, the products would copy every operand to that layout (forward and backward)."""
        logits = q @ k.transpose(-1, -2)  # (H, S, P, K)
        if table is not None:
            logits = logits + self.relative_logits(q, table, k.shape[-2])
        return self._weights(logits, valid).to(v.dtype) @ v

    def _weights(self, logits: Tensor, mask: Tensor) -> Tensor:
        """Attention weights of raw ``logits`` over the keys (last dim) where ``mask`` (broadcast to them): scaled,
        softmaxed in float32, zero outside the mask; a query with no valid key gets all zeros (an empty window is
        not a uniform softmax over padding)."""
        logits = logits.float() * (1.0 / math.sqrt(self.head_dim))
        return torch.softmax(logits.masked_fill(~mask, torch.finfo(logits.dtype).min), dim=-1) * mask

    def attend_window(self, q: Tensor, window: Tensor, valid: Tensor, table: Tensor | None) -> Tensor:
        """:meth:`attend` of single queries (B, heads, head_dim) over a window of key and value inputs (B, G, M, c)
        (:class:`WindowCache`) where ``valid`` (B, M); returns (B, dim). The key projection moves to the query side
        (q . (W_k u + b_k) = (W_k^T q) . u + q . b_k, whose last term is the same for every key, so the softmax
        drops it) and the value projection after the weighted sum (sum_j a_j (W_v u_j + b_v) = W_v sum_j a_j u_j +
        b_v sum_j a_j), so acting reads the window's inputs twice instead of its keys and its values, and keeps half
        the bytes per step (8.8 MB against 17.5 at 16 slots x 119 x 3 x 384, fp32: with the weights, under the CPU's
        last-level cache)."""
        b, heads, head_dim = q.shape
        groups = window.shape[1]
        if self.shared:  # every head's slice through the same (head_dim, head_dim) projections
            folded = q @ self.key.weight  # (B, H, hd)
        else:  # head h through its rows of W_k: (H, B, hd) @ (H, hd, dim)
            folded = (q.transpose(0, 1) @ self.key.weight.view(heads, head_dim, -1)).transpose(0, 1)
        # window @ folded^T, not folded @ window^T: a product over the window as stored reads it twice as fast
        logits = (window @ folded.reshape(b, groups, heads // groups, -1).mT).mT.reshape(b, heads, -1)
        if table is not None:  # (H, B, hd) @ (H, hd, M)
            logits = logits + (q.transpose(0, 1) @ table).transpose(0, 1)
        weights = self._weights(logits, valid.unsqueeze(1))  # (B, H, M)
        mixed = weights.to(window.dtype).view(b, groups, heads // groups, -1) @ window  # (B, G, H / G, c)
        if self.shared:
            values = mixed.view(b, heads, head_dim) @ self.value.weight.t()
        else:  # (H, B, dim) @ (H, dim, hd)
            values = mixed.view(b, heads, -1).transpose(0, 1) @ self.value.weight.view(heads, head_dim, -1).mT
            values = values.transpose(0, 1)
        bias = self.value.bias.view(-1, head_dim)  # (H, hd), or (1, hd) shared
        return (values + weights.sum(-1, keepdim=True).to(values.dtype) * bias).reshape(b, -1)

    def update(self, h: Tensor, attended: Tensor) -> Tensor:
        """The rest of the block on its inputs ``h`` (N, dim) given their attention outputs (N, dim), heads side by
        side: the output projection, the residual (or gate), the feed-forward layer and its residual (or gate)."""
        pre, post = self.norm == "pre", self.norm == "post"
        attended = self.out(attended)
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

    def _positions(self, key_step: Tensor, dtype: torch.dtype) -> Tensor | None:
        """The absolute/learned encoding of keys at episode steps ``key_step`` (None for the other encodings)."""
        if self.encoding not in ("absolute", "learned"):
            return None
        return self.positions[key_step.clamp(0, self.config.positional_size - 1)].to(dtype)

    def acting_cache(self, state: Tensor, episode_step: Tensor | None = None) -> WindowCache:
        """The key and value inputs of the windows ``state`` (B, memory_length, layers, dim) at ``episode_step`` (B,)
        (see :class:`WindowCache`): built once per state and weights, then advanced one entry per step."""
        if episode_step is None:
            raise ValueError("the trxl memory needs each slot's episode_step (decisions since its episode start)")
        dtype = compute_dtype(self.embed[0].weight)
        length = state.shape[1]
        key_step = episode_step.unsqueeze(1) - length + torch.arange(length, device=state.device)
        position = self._positions(key_step, dtype)
        inputs = []
        for layer, block in enumerate(self.blocks):
            memory = state[:, :, layer].to(dtype)
            window = block.window_inputs(memory if position is None else memory + position)  # (B, M, dim)
            groups = block.heads if block.shared else 1
            inputs.append(window.unflatten(-1, (groups, -1)).transpose(1, 2).contiguous())  # (B, G, M, c)
        tables = (block.relative_table(self.distances) for block in self.blocks)
        return WindowCache(inputs, [None if table is None else torch.cat((table, table), dim=-1) for table in tables])

    def step(
        self, features: Tensor, state: Tensor, episode_step: Tensor | None = None, cache: WindowCache | None = None
    ) -> tuple[Tensor, Tensor]:
        """One step; ``cache`` (advanced in place) is :meth:`acting_cache` of an earlier state advanced by every
        step since, None: built from ``state`` here."""
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
        if cache is None:
            cache = self.acting_cache(state, episode_step)
        length = state.shape[1]
        h = self.embed(features)
        age = (torch.arange(length, device=h.device) - cache.oldest) % length  # ring entry -> 0 for the oldest
        distance = length - age  # steps back from this one: 1..M
        valid = distance <= episode_step.clamp(max=length).unsqueeze(1)  # (B, M)
        position = self._positions(episode_step, h.dtype)  # of the step's own entry
        inputs = []
        for layer, block in enumerate(self.blocks):
            inputs.append(h)
            entry = h.to(self.state_dtype).to(h.dtype)  # as the state keeps it, so the training pass reads the same
            window = cache.inputs[layer]
            new_entry = block.window_inputs(entry if position is None else entry + position)
            attended = block.attend_window(block.queries(h), window, valid, cache.relative(layer))
            h = block.update(h, attended)
            window[:, :, cache.oldest] = new_entry.view(window.shape[0], window.shape[1], -1)  # after the attention
        cache.oldest = (cache.oldest + 1) % length
        return h, shift_window(state, torch.stack(inputs, dim=1))

    def record(self, state: Tensor, next_state: Tensor) -> Tensor:
        return next_state[:, -1]  # the step's own layer inputs, the newest entry of its window

    def history_records(self, state: Tensor) -> Tensor:
        return state

    def sequences(self, features: Tensor, records: Tensor, mask: Tensor, episode_step: Tensor | None = None) -> Tensor:
        """Queries of the real steps only; keys and values projected only for the records some query reads (a
        sequence starting an episode reads none of the window before it, and the padding reads nothing)."""
        if episode_step is None:
            raise ValueError("the trxl memory needs each step's episode_step (decisions since its episode start)")
        s, p = mask.shape
        length, k_len, device = self.config.memory_length, records.shape[1], features.device
        rows = mask.flatten().nonzero().squeeze(1)  # flat positions of the real steps in (S, P)
        steps = episode_step.new_zeros(s * p).index_copy(0, rows, episode_step).view(s, p)
        distance = (k_len - p) + torch.arange(p, device=device)[:, None] - torch.arange(k_len, device=device)
        reach = steps.clamp(max=length).unsqueeze(-1)  # the window holds this many steps of the episode (padding: 0)
        valid = (distance >= 1) & (distance <= reach)  # (S, P, K): earlier steps of the episode, within the window
        needed = valid.any(dim=1).flatten().nonzero().squeeze(1)  # flat (S * K) keys some query reads
        h = self.embed(features)
        dtype = h.dtype
        read = records.flatten(0, 1).index_select(0, needed)  # (keys, layers, dim)
        key_step = steps[:, :1] - (k_len - p) + torch.arange(k_len, device=device)  # from the first query's step
        position = self._positions(key_step.flatten().index_select(0, needed), dtype)
        for layer, block in enumerate(self.blocks):
            memory = read[:, layer].to(dtype)
            keys_values = []  # (H, S, K, hd) each, heads first (see Block.attend)
            for projected in block.keys_values(memory if position is None else memory + position):
                heads, head_dim = projected.shape[1:]
                padded = projected.new_zeros((heads, s * k_len, head_dim))
                keys_values.append(padded.index_copy(1, needed, projected.transpose(0, 1)).view(heads, s, k_len, -1))
            q = block.queries(h).transpose(0, 1)  # the real steps' (H, N, hd), padded to the sequences' layout
            q = q.new_zeros((q.shape[0], s * p, q.shape[2])).index_copy(1, rows, q).view(q.shape[0], s, p, -1)
            attended = block.attend(q, *keys_values, valid, block.relative_table(self.distances))  # (H, S, P, hd)
            attended = attended.flatten(1, 2).index_select(1, rows)  # (H, N, hd): the real steps
            h = block.update(h, attended.transpose(0, 1).reshape(rows.shape[0], -1))
        return h


def build(config: ModelSettings, input_size: int) -> TransformerXL:
    """The Transformer-XL of the block ``model.trxl`` (its own width and depth; ``memory_size`` is not read)."""
    return TransformerXL(config.trxl, input_size)


MEMORIES = (  # black; the gated variant (model.trxl.gating) is the method gtrxl of configs/
    MemorySpec("trxl", "TrXL-PPO", "#000000", build, settings=TrxlConfig, variants={"gtrxl": "GTrXL-PPO"}, order=30),
)
