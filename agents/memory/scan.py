"""The one scan of the linear-recurrent and state-space memories: h_t = a_t * h_{t-1} + b_t, in parallel over time.

``linear_scan(a, b, start, reset)`` runs S sequences of T steps of D channels (real or complex) from a start state
per sequence; ``reset`` (S, T) restarts a sequence at a step (h_{t-1} counts as zero there: an episode start inside
a sequence). Every memory of this family (``lru``, ``ffm``, ``mamba``) computes its decays and inputs in parallel
and hands them to this function.

How it is computed: a **chunked scan**. Time is cut into n chunks of C ~ sqrt(T) steps; (1) the recurrence runs
from a zero state inside every chunk at once (C steps, each over all chunks), (2) the n chunk ends are chained from
the start state (n steps over (S, D)), (3) each chunk's carried-in state is added, scaled by the cumulative product
of the chunk's decays (one product, one multiply-add). That is 2 sqrt(T) small sequential steps instead of T, and
about three times the elementwise work of a plain loop. Measured on this project's 2-core CPU (one thread, S=16,
D=128, forward only): at T=1,024 the chunked scan took 8 ms, a step-by-step loop 12 ms and a log-depth associative
(Hillis-Steele) scan about ten times the chunked one, which does log2(T) passes over the whole (S, T, D) tensor: on a
CPU, memory traffic, not depth, is the cost. The larger gain is the backward pass: the loop's autograd graph has T
nodes per tensor, the reverse scan below is one more chunked scan.
Closed forms through cumulative sums (``b / prod(a)``) are not used: with strong decays the products underflow and
the division overflows; the chunked scan only ever multiplies by |a| <= 1 products, so it neither overflows nor loses
precision on long sequences (tested at 4,096 steps and beyond).

Gradients come from an explicit reverse scan (:class:`LinearScan`): dL/db_t = g_t with g_t = dy_t + conj(a_{t+1})
g_{t+1}, dL/da_t = g_t conj(h_{t-1}), dL/dh_start = conj(a_0) g_0 (PyTorch's convention for complex gradients), so
the backward pass is the same chunked scan run backwards and keeps only a, the start state and the outputs.
"""

from __future__ import annotations

import contextlib
import functools
import math
from collections.abc import Callable

import torch
from torch import Tensor, nn
from torch.utils.checkpoint import checkpoint

from agents.layers import HIDDEN_GAIN, orthogonal
from agents.memory.base import Memory


def widen(x: Tensor) -> Tensor:
    """``x`` in at least single precision: the scan runs in fp32 (or fp64) even under bf16 autocast, where a long
    product of decays would lose its precision. An fp32 or fp64 ``x`` is returned as it is."""
    return x.float() if x.dtype in (torch.float16, torch.bfloat16) else x


def scan_dtype(dtype: torch.dtype) -> torch.dtype:
    """The dtype a recurrence computes in for inputs of ``dtype``: at least float32 (``dtype`` itself when wider)."""
    return torch.promote_types(dtype, torch.float32)


def full_precision(device: torch.device) -> contextlib.AbstractContextManager:
    """Autocast off on ``device``: inside, every operation computes in its inputs' own dtype. A recurrence runs in
    it, on inputs widened by :func:`widen`, so that a bfloat16 autocast (``run.precision: bf16``) never casts its
    products to bfloat16 (Mamba-2's chunk products, whose states chain over the chunks), and torch's complex types,
    which have no bfloat16, are only ever made from fp32 parts. Where autocast is off already (fp32) it changes
    nothing."""
    return torch.autocast(device.type, enabled=False)


def complex_dtype(real: torch.dtype) -> torch.dtype:
    """The complex dtype whose parts are ``real``."""
    return {torch.float32: torch.complex64, torch.float64: torch.complex128}[real]


def _chunk_size(t: int) -> int:
    """Steps per chunk for T steps: a divisor of T near sqrt(T) when there is one (no padding), else ceil(sqrt(T))."""
    root = math.isqrt(t)
    for size in range(root, max(1, root // 2) - 1, -1):  # the largest divisor in [sqrt(T) / 2, sqrt(T)]
        if t % size == 0 and size > 1:
            return size
    return max(1, math.isqrt(t - 1) + 1)


def _chunks(a: Tensor, b: Tensor) -> tuple[Tensor, Tensor, int]:
    """``a``, ``b`` (S, T, *D) as (S, n, C, *D) chunks, padded at the end with steps (a = 1, b = 0) that change
    nothing before them; and T."""
    s, t = b.shape[:2]
    chunk = _chunk_size(t)
    n = -(-t // chunk)
    pad = n * chunk - t
    if pad:
        a = torch.cat((a, a.new_ones((s, pad, *b.shape[2:]))), dim=1)
        b = torch.cat((b, b.new_zeros((s, pad, *b.shape[2:]))), dim=1)
    return a.reshape(s, n, chunk, *b.shape[2:]), b.reshape(s, n, chunk, *b.shape[2:]), t


def _chunked_scan(a: Tensor, b: Tensor, start: Tensor) -> Tensor:
    """h_t = a_t h_{t-1} + b_t over dim 1 of (S, T, *D) tensors from ``start`` (S, *D), without autograd."""
    if b.shape[1] == 1:
        return (a[:, 0] * start + b[:, 0]).unsqueeze(1)
    a, b, t = _chunks(a, b)
    s, n, chunk = b.shape[:3]
    local = torch.empty_like(b)  # (1) every chunk from a zero state, all chunks at once
    decay = torch.empty_like(b)  # decay[:, j, i] = a_{j,0} ... a_{j,i}
    local[:, :, 0] = b[:, :, 0]
    decay[:, :, 0] = a[:, :, 0]
    for i in range(1, chunk):
        torch.addcmul(b[:, :, i], a[:, :, i], local[:, :, i - 1], out=local[:, :, i])
        torch.mul(a[:, :, i], decay[:, :, i - 1], out=decay[:, :, i])
    carried = torch.empty_like(b[:, :, 0])  # (2) the state entering each chunk
    carried[:, 0] = start
    for j in range(1, n):
        torch.addcmul(local[:, j - 1, -1], decay[:, j - 1, -1], carried[:, j - 1], out=carried[:, j])
    h = local.addcmul_(decay, carried.unsqueeze(2))  # (3) each chunk's carried-in state, decayed
    return h.reshape(s, n * chunk, *b.shape[3:])[:, :t]


def _chunked_reverse_scan(a: Tensor, d: Tensor) -> Tensor:
    """g_t = d_t + a_{t+1} g_{t+1} over dim 1 of (S, T, *D) tensors, g_{T-1} = d_{T-1}: the backward pass's scan,
    run backwards in place of flipping and shifting copies (the same three phases as :func:`_chunked_scan`)."""
    if d.shape[1] == 1:
        return d.clone()
    a, d, t = _chunks(a, d)
    s, n, chunk = d.shape[:3]
    local = torch.empty_like(d)  # (1) every chunk from a zero state after its end
    decay = torch.empty_like(d)  # decay[:, j, i] = a_{j,i+1} ... a_{j,C-1} a_{j+1,0}: from step (j, i) to chunk j + 1
    local[:, :, -1] = d[:, :, -1]
    decay[:, :-1, -1] = a[:, 1:, 0]
    decay[:, -1, -1] = 0  # nothing comes after the last chunk
    for i in range(chunk - 2, -1, -1):
        torch.addcmul(d[:, :, i], a[:, :, i + 1], local[:, :, i + 1], out=local[:, :, i])
        torch.mul(a[:, :, i + 1], decay[:, :, i + 1], out=decay[:, :, i])
    carried = torch.zeros_like(d[:, :, 0])  # (2) g at the first step of the next chunk
    for j in range(n - 2, -1, -1):
        torch.addcmul(local[:, j + 1, 0], decay[:, j + 1, 0], carried[:, j + 1], out=carried[:, j])
    g = local.addcmul_(decay, carried.unsqueeze(2))  # (3)
    return g.reshape(s, n * chunk, *d.shape[3:])[:, :t]


class LinearScan(torch.autograd.Function):
    """h = scan(a, b, start) with the reverse-scan backward of the module docstring."""

    @staticmethod
    def forward(ctx, a: Tensor, b: Tensor, start: Tensor) -> Tensor:  # type: ignore[override]
        h = _chunked_scan(a, b, start)
        ctx.save_for_backward(a, start, h)
        return h

    @staticmethod
    def backward(ctx, grad: Tensor) -> tuple[Tensor | None, Tensor | None, Tensor | None]:  # type: ignore[override]
        a, start, h = ctx.saved_tensors
        conj_a = a.conj().resolve_conj()  # a no-op for real tensors
        g = _chunked_reverse_scan(conj_a, grad.contiguous())  # g_t = grad_t + conj(a_{t+1}) g_{t+1}
        grad_a = None
        if ctx.needs_input_grad[0]:  # g_t conj(h_{t-1}), h_{-1} the start state
            grad_a = torch.empty_like(g)
            torch.mul(g[:, 1:], h[:, :-1].conj(), out=grad_a[:, 1:])
            torch.mul(g[:, 0], start.conj(), out=grad_a[:, 0])
        grad_start = conj_a[:, 0] * g[:, 0] if ctx.needs_input_grad[2] else None
        return grad_a, g, grad_start


def linear_scan(a: Tensor, b: Tensor, start: Tensor | None = None, reset: Tensor | None = None) -> Tensor:
    """All states h_t = a_t * h_{t-1} + b_t of S sequences: ``a``, ``b`` (S, T, *D) real or complex (``a`` may
    broadcast over the channels: (S, T, *D') with size-1 dims), ``start`` (S, *D) the state before each sequence
    (zeros when None), ``reset`` (S, T) bool: h_{t-1} is zero at these steps (an episode starts there). Returns
    (S, T, *D), differentiable in ``a``, ``b`` and ``start``."""
    if b.dim() < 3:
        raise ValueError(f"linear_scan expects (S, T, channels...) inputs, got b of shape {tuple(b.shape)}")
    a = a.expand_as(b)
    if reset is not None:
        keep = ~reset.view(*reset.shape, *([1] * (b.dim() - 2)))
        a = a * keep
    if start is None:
        start = b.new_zeros((b.shape[0], *b.shape[2:]))
    return LinearScan.apply(a.contiguous(), b.contiguous(), start.to(b.dtype).contiguous())


def reference_scan(a: Tensor, b: Tensor, start: Tensor | None = None, reset: Tensor | None = None) -> Tensor:
    """The same recurrence as :func:`linear_scan`, one step at a time (the tests' and benchmarks' reference)."""
    a = a.expand_as(b)
    h = b.new_zeros((b.shape[0], *b.shape[2:])) if start is None else start.to(b.dtype)
    states = []
    for t in range(b.shape[1]):
        decay = a[:, t]
        if reset is not None:
            decay = decay * ~reset[:, t].view(-1, *([1] * (b.dim() - 2)))
        h = decay * h + b[:, t]
        states.append(h)
    return torch.stack(states, dim=1)


BLOCK_ELEMENTS = 2**21  # states per block of Layout.scan_readout: 8 MB in fp32, measured fastest among 2^19..2^23
WHOLE_ELEMENTS = 6 * 2**20  # up to this many states (24 MB in fp32, 3/4 of the last-level cache) it runs whole


class Layout:
    """Where the N flat steps of a training pass sit in S sequences padded to P steps: ``mask`` (S, P), a prefix of
    real steps per row, or None when every position is real (a decision of the rollout, or dense sequences; a mask
    with no padding is read as None). A scan memory's per-step layers (norms, projections, gates) run on the N real
    steps, and :meth:`scan` runs the recurrence over them too, so padding costs neither anything (the trainer's
    sequences are whole episodes padded to the longest of a minibatch: ~2.6 positions per real step on Mortar
    Mayhem); only convolutions over time use the padded (S, P) layout (:meth:`pad`, :meth:`unpad`)."""

    def __init__(self, sequences: int, length: int, mask: Tensor | None = None) -> None:
        if mask is not None and bool(mask.all()):
            mask = None
        self.sequences, self.length, self.mask = sequences, length, mask
        if mask is not None:  # each sequence's first and last real step in the flat order
            lengths = mask.sum(dim=1)
            ends = lengths.cumsum(0)
            present = lengths > 0
            self.firsts, self.lasts = (ends - lengths)[present], (ends - 1)[present]
            self.present = present

    def pad(self, x: Tensor) -> Tensor:
        """(N, *D) -> (S, P, *D), zeros at the padded positions."""
        if self.mask is None:
            return x.reshape(self.sequences, self.length, *x.shape[1:])
        return x.new_zeros((self.sequences, self.length, *x.shape[1:])).index_put((self.mask,), x)

    def unpad(self, x: Tensor) -> Tensor:
        """(S, P, *D) -> (N, *D), the real positions in sequence order."""
        return x.reshape(-1, *x.shape[2:]) if self.mask is None else x[self.mask]

    def scan(self, a: Tensor, b: Tensor, start: Tensor) -> Tensor:
        """:func:`linear_scan` of each sequence from its ``start`` (S, *D) over the flat steps: ``b`` (N, *D), ``a``
        (N, *D) or broadcast to it. With padding, the N steps run as one stream in which each sequence's first step
        forgets the step before it and takes its start state instead (h = a start + b there), so padded positions
        are never computed."""
        if self.mask is None:
            dense = (self.sequences, self.length, *b.shape[1:])
            a = a.expand_as(b).reshape(dense) if a.dim() == b.dim() else a.view(1, 1, *a.shape)
            return linear_scan(a, b.reshape(dense), start).reshape(b.shape)
        a, b = _restart(a.expand_as(b), b, self.firsts, start[self.present])
        return linear_scan(a.unsqueeze(0), b.unsqueeze(0))[0]

    def scan_readout(
        self,
        build: Callable[..., tuple[Tensor, Tensor]],
        readout: Callable[..., Tensor],
        per_step: tuple[Tensor, ...],
        start: Tensor,
        block_elements: int | None = None,
        whole_elements: int | None = None,
    ) -> tuple[Tensor, Tensor]:
        """:meth:`scan` and a readout of its states for a memory whose state is much wider than what it reads and
        writes per step (Mamba: E x N states from E inputs and E outputs): ``build(*steps)`` makes the decays and
        inputs (n, *D) of n flat steps from their rows of ``per_step`` (tensors (N, ...)), ``readout(h, *steps)``
        their outputs (n, *Y) from their states h (n, *D). Returns the outputs (N, *Y) and :meth:`last` of the
        states (S, *D).

        Runs over time in blocks of about ``block_elements`` states (default :data:`BLOCK_ELEMENTS`), each chained
        from the one before, and keeps no state, decay or input beyond its block: with autograd, each block is
        recomputed in the backward pass (activation checkpointing), which saves only the state entering it. Whole
        (N, *D) tensors would be read and written some 40 times over a forward and backward pass (268 MB each for
        Mamba at width 128 over 16 x 1,024 steps); in blocks that stay in the CPU's cache, that scan and readout
        took 1.0 s instead of 2.6 s (one thread), and the memory they held is gone. A scan of at most
        ``whole_elements`` states (default :data:`WHOLE_ELEMENTS`) runs whole, without recomputation, as it fits
        the cache already: a Mortar Mayhem minibatch at width 512 (~4-6M states) trained 5% slower in blocks."""
        rows = self.sequences if self.mask is None else 1  # streams: the dense sequences, or the one flat stream
        steps = per_step[0].shape[0] // rows
        state_width = start[0].numel()
        block_elements = block_elements or BLOCK_ELEMENTS
        whole_elements = WHOLE_ELEMENTS if whole_elements is None else whole_elements
        whole = rows * steps * state_width <= whole_elements  # fits the cache as it is: nothing to recompute
        block = max(1, steps) if whole else max(1, block_elements // max(1, rows * state_width))
        # split, not sliced: one backward node joins the blocks' gradients, where a slice's would zero a whole-size
        # tensor per block
        blocks = tuple(x.reshape(rows, steps, *x.shape[1:]).split(block, dim=1) for x in per_step)
        if self.mask is None:  # the dense sequences start from their states
            h, firsts, lasts = start, None, None
        else:  # one stream, in which each sequence's first step takes its start state (see scan)
            h, firsts, lasts = start.new_zeros((1, *start.shape[1:])), self.firsts, self.lasts
            start = start[self.present]
        outputs, finals = [], []
        for index, begin in enumerate(range(0, steps, block)):
            end = min(steps, begin + block)
            block_steps = tuple(x[index] for x in blocks)
            restarts = None
            if firsts is not None:
                inside = (firsts >= begin) & (firsts < end)
                restarts = (firsts[inside] - begin, start[inside])
            run = functools.partial(_scan_block, build, readout, restarts)
            if torch.is_grad_enabled() and not whole:
                y, states, h = checkpoint(run, h, *block_steps, use_reentrant=False)
            else:
                y, states, h = run(h, *block_steps)
            outputs.append(y)
            if lasts is not None:
                finals.append(states[lasts[(lasts >= begin) & (lasts < end)] - begin])
        y = torch.cat(outputs, dim=1).flatten(0, 1)
        return y, h if lasts is None else self._per_sequence(torch.cat(finals))

    def last(self, h: Tensor) -> Tensor:
        """The flat steps' values (N, *D) at each sequence's last real step (S, *D); zeros for an empty sequence."""
        if self.mask is None:
            return h.reshape(self.sequences, self.length, *h.shape[1:])[:, -1]
        return self._per_sequence(h[self.lasts])

    def _per_sequence(self, values: Tensor) -> Tensor:
        """One row per present sequence (their order) -> (S, ...), zeros for the empty sequences."""
        return values.new_zeros((self.sequences, *values.shape[1:])).index_copy(
            0, self.present.nonzero().squeeze(1), values
        )


def _restart(a: Tensor, b: Tensor, positions: Tensor, starts: Tensor) -> tuple[Tensor, Tensor]:
    """Flat steps ``positions`` of a stream start a sequence from ``starts`` (one state each): there h = a start + b,
    whatever came before (a zeroed, a start added to b)."""
    return a.index_fill(0, positions, 0), b.index_add(0, positions, a[positions] * starts.to(b.dtype))


def _scan_block(
    build: Callable[..., tuple[Tensor, Tensor]],
    readout: Callable[..., Tensor],
    restarts: tuple[Tensor, Tensor] | None,
    h: Tensor,
    *steps: Tensor,
) -> tuple[Tensor, Tensor, Tensor]:
    """One block of :meth:`Layout.scan_readout`: ``steps`` (R, n, ...) of R streams from their states ``h`` (R, *D);
    ``restarts`` (one stream only): the block's steps that start a sequence, and their start states. Returns the
    outputs (R, n, *Y), the states (R * n, *D) (for the sequences' last steps) and the states after the block."""
    r, n = steps[0].shape[:2]
    flat = tuple(x.reshape(r * n, *x.shape[2:]) for x in steps)
    a, b = build(*flat)
    a = a.expand_as(b)
    if restarts is not None and restarts[0].numel():
        a, b = _restart(a, b, *restarts)
    hs = linear_scan(a.reshape(r, n, *b.shape[1:]), b.reshape(r, n, *b.shape[1:]), h.to(b.dtype))
    flat_states = hs.reshape(r * n, *b.shape[1:])
    y = readout(flat_states, *flat)
    return y.reshape(r, n, *y.shape[1:]), flat_states, hs[:, -1]


class ScanMemory(Memory):
    """A stack of residual blocks on the scan: ``Linear(input, dim)``, ``layers`` blocks x -> x + f(LayerNorm(x)),
    a final LayerNorm. Each block keeps a flat state of ``block.state_size`` floats per slot, so a slot's state is
    (layers, state_size), zeros at an episode start, and the buffer keeps the state fed into every step (truncated
    BPTT starts each training sequence from it, as for the GRU). A block is called as ``block(x, state, layout)``
    with x (N, dim) flat steps, state (S, state_size) and a :class:`Layout`, and returns x + f(x) (N, dim) and the
    state after the last position of each sequence (S, state_size; the rollout's next state, where P = 1).
    ``step`` and ``sequences`` run the same :meth:`forward_steps`, over one step or over the padded sequences
    (padding trails the real steps, so it changes nothing before it)."""

    def __init__(self, input_size: int, dim: int, blocks: list[nn.Module]) -> None:
        super().__init__()
        sizes = {block.state_size for block in blocks}
        if len(sizes) != 1:
            raise ValueError(f"the blocks of a scan memory need one state size, got {sorted(sizes)}")
        self.embed = orthogonal(nn.Linear(input_size, dim), HIDDEN_GAIN)
        self.blocks = nn.ModuleList(blocks)
        self.norm = nn.LayerNorm(dim)
        self.output_size = dim
        self.state_shape = self.record_shape = (len(blocks), sizes.pop())

    def forward_steps(self, features: Tensor, state: Tensor, layout: Layout) -> tuple[Tensor, Tensor]:
        """Features (N, F) of the real steps of S sequences laid out by ``layout``, from their states (S, layers,
        state_size): outputs (N, dim) and the states after each sequence's last position."""
        x = self.embed(features)
        finals = []
        for layer, block in enumerate(self.blocks):
            x, final = block(x, state[:, layer], layout)
            finals.append(final)
        return self.norm(x), torch.stack(finals, dim=1)

    def run(self, features: Tensor, state: Tensor) -> tuple[Tensor, Tensor]:
        """Dense sequences: features (S, T, F) from states (S, layers, state_size); outputs (S, T, dim) and the
        states after the last step."""
        s, t = features.shape[:2]
        output, final = self.forward_steps(features.reshape(s * t, -1), state, Layout(s, t))
        return output.reshape(s, t, -1), final

    # The states reach the blocks in at least fp32, not in the features' dtype: under bf16 the features are bfloat16
    # (a bf16 acting copy's, or autocast's in training), and a state rounded to bfloat16 at every decision would
    # lose what the fp32 recurrence keeps (a block widens what it reads, but cannot restore lost digits)
    def step(self, features: Tensor, state: Tensor, episode_step: Tensor | None = None) -> tuple[Tensor, Tensor]:
        start = state.to(scan_dtype(features.dtype))
        output, final = self.forward_steps(features, start, Layout(features.shape[0], 1))
        return output, final.to(state.dtype)

    def sequences(self, features: Tensor, records: Tensor, mask: Tensor, episode_step: Tensor | None = None) -> Tensor:
        starts = records.to(scan_dtype(features.dtype))
        output, _ = self.forward_steps(features, starts, Layout(*mask.shape, mask))
        return output
