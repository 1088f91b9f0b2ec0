"""The parallel scan (agents/memory/scan.py) against a step-by-step loop, the memories built on it (lru, ffm, mamba,
mamba2), Mamba-2's chunked matrix form against its recurrence, and a memory of the user's own by import path."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from agents.config import ConfigError, ModelConfig, config_from_dict
from agents.memory import build_memory, memory_class
from agents.memory.lru import LruConfig
from agents.memory.mamba2 import state_space_dual
from agents.memory.scan import linear_scan, reference_scan
from agents.training.trainer import Trainer
from tests.support.external_memory import LeakyMemory

SCAN_MEMORIES = ("lru", "ffm", "mamba", "mamba2")


def _small_config(name: str, **fields: int) -> ModelConfig:
    """A small model config; mamba2 with heads of 4 channels and chunks of 4 steps, so that the small sequences of
    these tests cross chunk boundaries and the inner width has several heads."""
    config = ModelConfig(memory=name, **fields)
    config.mamba2.head_dim, config.mamba2.chunk_size = 4, 4
    return config


def _scan_inputs(s: int, t: int, d: int, complex_: bool, seed: int = 0) -> tuple[torch.Tensor, ...]:
    generator = torch.Generator().manual_seed(seed)
    a = torch.rand(s, t, d, generator=generator, dtype=torch.float64)
    if complex_:
        a = a * torch.exp(1j * 3 * torch.rand(s, t, d, generator=generator, dtype=torch.float64))
    dtype = a.dtype
    b = torch.randn(s, t, d, generator=generator, dtype=torch.float64).to(dtype)
    start = torch.randn(s, d, generator=generator, dtype=torch.float64).to(dtype)
    reset = torch.rand(s, t, generator=generator) < 0.1
    return a, b, start, reset


@pytest.mark.parametrize("complex_", [False, True], ids=["real", "complex"])
@pytest.mark.parametrize("length", [1, 2, 5, 16, 17, 63, 200])
def test_scan_equals_the_step_by_step_loop_in_values_and_gradients(length: int, complex_: bool) -> None:
    """Every length (chunk boundaries, padding of the last chunk), start states and resets inside the sequences."""
    a, b, start, reset = (
        x.requires_grad_(x.is_floating_point() or x.is_complex()) for x in _scan_inputs(3, length, 4, complex_)
    )
    weights = torch.randn(3, length, 4, dtype=torch.float64)
    fast, slow = linear_scan(a, b, start, reset), reference_scan(a, b, start, reset)
    torch.testing.assert_close(fast, slow, rtol=1e-12, atol=1e-12)
    grads = [
        torch.autograd.grad(
            (y.real * weights).sum() + (y.imag * weights).sum() if complex_ else (y * weights).sum(), (a, b, start)
        )
        for y in (fast, slow)
    ]
    for fast_grad, slow_grad in zip(*grads, strict=True):
        torch.testing.assert_close(fast_grad, slow_grad, rtol=1e-10, atol=1e-12)


def test_scan_gradients_pass_gradcheck() -> None:
    a, b, start, reset = _scan_inputs(2, 11, 3, complex_=True, seed=1)
    inputs = tuple(x.requires_grad_() for x in (a, b, start))
    assert torch.autograd.gradcheck(lambda a, b, h: linear_scan(a, b, h, reset), inputs)


def test_a_reset_makes_the_sequence_independent_of_everything_before() -> None:
    a, b, start, _ = _scan_inputs(2, 30, 4, complex_=False)
    reset = torch.zeros(2, 30, dtype=torch.bool)
    reset[:, 12] = True
    h = linear_scan(a, b, start, reset)
    other = b.clone()
    other[:, :12] += 5.0
    h_other = linear_scan(a, other, -start, reset)
    assert not torch.allclose(h[:, :12], h_other[:, :12])
    torch.testing.assert_close(h[:, 12:], h_other[:, 12:], rtol=0, atol=0)


@pytest.mark.parametrize("length", [4096, 20_000])
def test_long_fp32_scans_neither_overflow_nor_drift(length: int) -> None:
    """fp32 over thousands of steps, decays from vanishing (1e-30) to nearly one (|a| = 1 - 1e-6), complex and real:
    finite, and within 1e-4 of the float64 loop (a closed form through b / prod(a) would overflow here)."""
    generator = torch.Generator().manual_seed(0)
    magnitude = torch.tensor([1e-30, 0.5, 0.99, 0.9999, 1 - 1e-6], dtype=torch.float64)
    phase = torch.exp(1j * torch.rand(1, length, 5, generator=generator, dtype=torch.float64))
    a = (magnitude * phase).expand(2, length, 5)
    b = torch.randn(2, length, 5, generator=generator, dtype=torch.float64).to(a.dtype)
    expected = reference_scan(a, b)
    for decays, inputs, truth in ((a, b, expected), (a.abs(), b.real, reference_scan(a.abs(), b.real))):
        got = linear_scan(
            decays.to(torch.complex64 if decays.is_complex() else torch.float32),
            inputs.to(torch.complex64 if inputs.is_complex() else torch.float32),
        )
        assert torch.isfinite(torch.view_as_real(got) if got.is_complex() else got).all()
        scale = truth.abs().amax(dim=1, keepdim=True)
        assert ((got.to(truth.dtype) - truth).abs() / scale).max() < 1e-4


@pytest.mark.parametrize("per_step", [True, False], ids=["decay-per-step", "constant-decay"])
def test_the_layout_scans_the_real_steps_as_each_sequence_alone(per_step: bool) -> None:
    """A minibatch's flat real steps scanned as one stream (each sequence's first step takes its start state) equal
    each sequence scanned alone, in values and gradients; ``last`` is the state after its last real step (zeros for
    a sequence with no step), and a mask with no padding takes the dense path."""
    from agents.memory.scan import Layout

    generator = torch.Generator().manual_seed(3)
    lengths = [5, 1, 0, 7]
    mask = torch.arange(7)[None, :] < torch.tensor(lengths)[:, None]
    n, d = int(mask.sum()), 3
    a = torch.rand(n, d, generator=generator, dtype=torch.float64) if per_step else torch.rand(d, dtype=torch.float64)
    b = torch.randn(n, d, generator=generator, dtype=torch.float64)
    start = torch.randn(len(lengths), d, generator=generator, dtype=torch.float64)
    inputs = tuple(x.requires_grad_() for x in (a, b, start))
    layout = Layout(*mask.shape, mask)
    h = layout.scan(*inputs)
    expected, finals, offset = [], [], 0
    for row, length in enumerate(lengths):
        if not length:
            finals.append(torch.zeros(d, dtype=torch.float64))
            continue
        steps = slice(offset, offset + length)
        decay = (a[steps] if per_step else a.expand(length, d)).unsqueeze(0)
        alone = reference_scan(decay, b[steps].unsqueeze(0), start[row : row + 1])[0]
        expected.append(alone)
        finals.append(alone[-1])
        offset += length
    expected = torch.cat(expected)
    torch.testing.assert_close(h, expected, rtol=1e-12, atol=1e-12)
    torch.testing.assert_close(layout.last(h), torch.stack(finals), rtol=1e-12, atol=1e-12)
    weights = torch.randn(n, d, dtype=torch.float64)
    grads = [torch.autograd.grad((y * weights).sum(), inputs) for y in (h, expected)]
    for got, want in zip(*grads, strict=True):
        torch.testing.assert_close(got, want, rtol=1e-10, atol=1e-12)
    assert Layout(2, 3, torch.ones(2, 3, dtype=torch.bool)).mask is None


@pytest.mark.parametrize(
    ("block_elements", "whole_elements"), [(1, 0), (3 * 4 * 2, 0), (1, 10**6)], ids=["1-step", "2-step", "whole"]
)
@pytest.mark.parametrize("padded", [True, False], ids=["padded", "dense"])
def test_the_scan_in_blocks_with_a_readout_equals_the_whole_scan(
    padded: bool, block_elements: int, whole_elements: int
) -> None:
    """Layout.scan_readout (Mamba's path: decays, inputs and states built and read block by block, recomputed in the
    backward pass) gives the outputs, last states and gradients of building everything, scanning it whole
    (Layout.scan) and reading it out, with sequences starting inside blocks, an empty sequence and start states."""
    from agents.memory.scan import Layout

    generator = torch.Generator().manual_seed(5)
    lengths = [5, 1, 0, 7] if padded else [6, 6, 6]
    mask = torch.arange(max(lengths))[None, :] < torch.tensor(lengths)[:, None]
    n, width, states = int(mask.sum()), 3, 4
    rate = -torch.rand(width, states, generator=generator, dtype=torch.float64)
    step, x = torch.rand(n, width, generator=generator, dtype=torch.float64), torch.randn(n, width, dtype=torch.float64)
    b, c = torch.randn(n, states, dtype=torch.float64), torch.randn(n, states, dtype=torch.float64)
    start = torch.randn(len(lengths), width, states, generator=generator, dtype=torch.float64)
    leaves = tuple(v.requires_grad_() for v in (rate, step, x, b, c, start))

    def build(step, x, b, c):
        return torch.exp(step.unsqueeze(-1) * rate), (step * x).unsqueeze(-1) * b.unsqueeze(1)

    def readout(h, step, x, b, c):
        return (h * c.unsqueeze(1)).sum(-1)

    layout = Layout(*mask.shape, mask)
    y, last = layout.scan_readout(build, readout, (step, x, b, c), start, block_elements, whole_elements)
    h = layout.scan(*build(step, x, b, c), start)
    y_whole, last_whole = readout(h, step, x, b, c), layout.last(h)
    torch.testing.assert_close(y, y_whole, rtol=1e-12, atol=1e-12)
    torch.testing.assert_close(last, last_whole, rtol=1e-12, atol=1e-12)
    weights = torch.randn(y.shape, dtype=torch.float64), torch.randn(last.shape, dtype=torch.float64)
    grads = [
        torch.autograd.grad((out * weights[0]).sum() + (fin * weights[1]).sum(), leaves)
        for out, fin in ((y, last), (y_whole, last_whole))
    ]
    for got, want in zip(*grads, strict=True):
        torch.testing.assert_close(got, want, rtol=1e-10, atol=1e-12)
    with torch.no_grad():  # acting and evaluation: the same blocks, no checkpointing
        blocked = layout.scan_readout(build, readout, (step, x, b, c), start, block_elements, whole_elements)[0]
        torch.testing.assert_close(blocked, y)


def test_mamba_in_blocks_trains_as_in_one_block(monkeypatch: pytest.MonkeyPatch) -> None:
    """The Mamba block through blocks of a few steps (a minibatch larger than one block) gives the outputs and
    gradients of one block."""
    import agents.memory.scan as scan

    torch.manual_seed(0)
    memory = build_memory(_small_config("mamba", memory_size=8, memory_layers=2), 10).double()
    steps, start, mask = _sequence_batch(memory, 10, [9, 6, 1, 4], seed=2)

    def outputs_and_grads() -> tuple[torch.Tensor, list[torch.Tensor]]:
        memory.zero_grad()
        output = memory.sequences(steps, start, mask)
        output.square().sum().backward()
        return output.detach(), [p.grad.clone() for p in memory.parameters()]

    whole, whole_grads = outputs_and_grads()
    inner = memory.blocks[0].inner * memory.blocks[0].states
    monkeypatch.setattr(scan, "BLOCK_ELEMENTS", 3 * inner)  # blocks of 3 steps
    monkeypatch.setattr(scan, "WHOLE_ELEMENTS", 0)
    blocked, blocked_grads = outputs_and_grads()
    torch.testing.assert_close(blocked, whole, rtol=1e-10, atol=1e-12)
    for got, want in zip(blocked_grads, whole_grads, strict=True):
        torch.testing.assert_close(got, want, rtol=1e-9, atol=1e-12)


def test_the_shifted_convolution_has_the_gradients_of_autograd() -> None:
    """Mamba's depthwise convolution (its own backward) against the same shifted multiply-adds under autograd."""
    from torch.nn import functional as F

    from agents.memory.ssm import ShiftedConv

    generator = torch.Generator().manual_seed(6)
    window, weight, bias = (
        torch.randn(shape, generator=generator, dtype=torch.float64).requires_grad_()
        for shape in ((3, 7 + 3, 5), (4, 5), (5,))
    )
    out = bias + sum(window[:, shift : shift + 7] * weight[shift] for shift in range(4))
    expected = F.silu(out)
    got = ShiftedConv.apply(window, weight, bias)
    torch.testing.assert_close(got, expected, rtol=1e-12, atol=1e-12)
    assert torch.autograd.gradcheck(ShiftedConv.apply, (window, weight, bias))


def _ssd_loop(x, step, rate, b, c, start):
    """Mamba-2's recurrence one step at a time: h_t = exp(step_t a) h_{t-1} + step_t x_t b_t^T, y_t = h_t c_t."""
    h, outputs = start, []
    for t in range(x.shape[1]):
        decay = torch.exp(step[:, t] * rate)[..., None, None]
        h = decay * h + (x[:, t] * step[:, t, :, None]).unsqueeze(-1) * b[:, t, None, None, :]
        outputs.append((h @ c[:, t, None, :, None]).squeeze(-1))
    return torch.stack(outputs, dim=1), h


def _ssd_inputs(s: int, t: int, heads: int, p: int, n: int, seed: int, dtype=torch.float64):
    generator = torch.Generator().manual_seed(seed)
    x = torch.randn(s, t, heads, p, generator=generator, dtype=dtype)
    step = 2 * torch.rand(s, t, heads, generator=generator, dtype=dtype)
    rate = -8 * torch.rand(heads, generator=generator, dtype=dtype)
    b, c = (torch.randn(s, t, n, generator=generator, dtype=dtype) for _ in range(2))
    start = torch.randn(s, heads, p, n, generator=generator, dtype=dtype)
    return x, step, rate, b, c, start


@pytest.mark.parametrize(("length", "chunk"), [(1, 4), (7, 4), (8, 4), (13, 5), (13, 64), (40, 1)])
def test_mamba2_chunks_equal_the_recurrence_in_values_and_gradients(length: int, chunk: int) -> None:
    """The state-space-dual form (Q x Q products per chunk, chunk states chained by the scan) gives the recurrence's
    outputs, final state and gradients: partial last chunks, one chunk longer than the sequence, chunks of 1."""
    inputs = tuple(v.requires_grad_() for v in _ssd_inputs(3, length, 2, 3, 4, seed=length))
    fast, slow = state_space_dual(*inputs, chunk=chunk), _ssd_loop(*inputs)
    weights = [torch.randn_like(v) for v in slow]
    for got, expected in zip(fast, slow, strict=True):
        torch.testing.assert_close(got, expected, rtol=1e-10, atol=1e-10)
    grads = [
        torch.autograd.grad(sum((v * w).sum() for v, w in zip(out, weights, strict=True)), inputs)
        for out in (fast, slow)
    ]
    for got, expected in zip(*grads, strict=True):
        torch.testing.assert_close(got, expected, rtol=1e-9, atol=1e-10)


def test_mamba2_chunks_stay_finite_and_exact_over_long_fp32_sequences() -> None:
    """4,096 steps in fp32 with decays from vanishing (step x a = -80 per step) to nearly none: finite, and within
    1e-4 of the float64 loop (every decay product is exp of a non-positive sum)."""
    x, step, rate, b, c, start = _ssd_inputs(2, 4096, 3, 2, 3, seed=0)
    rate = torch.tensor([-40.0, -1e-3, -1e-6], dtype=torch.float64)
    expected, _ = _ssd_loop(x, step, rate, b, c, start)
    got, final = state_space_dual(*(v.float() for v in (x, step, rate, b, c, start)), chunk=64)
    assert torch.isfinite(got).all() and torch.isfinite(final).all()
    scale = expected.abs().amax(dim=1, keepdim=True)
    assert ((got.double() - expected).abs() / scale).max() < 1e-4


def test_mamba2_refuses_a_head_size_that_does_not_divide_its_width() -> None:
    with pytest.raises(ConfigError, match=r"model\.mamba2\.head_dim=48 is invalid.*= 64"):
        config_from_dict({"model": {"memory": "mamba2", "memory_size": 32, "mamba2": {"head_dim": 48}}})


def _sequence_batch(memory: torch.nn.Module, features: int, lengths: list[int], seed: int):
    generator = torch.Generator().manual_seed(seed)
    mask = torch.zeros(len(lengths), max(lengths), dtype=torch.bool)
    for row, length in enumerate(lengths):
        mask[row, :length] = True
    steps = torch.randn(int(mask.sum()), features, generator=generator, dtype=torch.float64)
    start = 0.5 * torch.randn(len(lengths), *memory.state_shape, generator=generator, dtype=torch.float64)
    start[1] = 0  # one sequence at an episode start
    return steps, start, mask


@pytest.mark.parametrize("name", [*SCAN_MEMORIES, "tests.support.external_memory:LeakyMemory"])
def test_step_by_step_equals_the_sequence_path(name: str) -> None:
    """Random sequences of random lengths (trailing padding), random start states: the rollout's one-step path and
    the training pass give the same outputs, and gradients reach every parameter."""
    torch.manual_seed(0)
    memory = build_memory(_small_config(name, memory_size=24, memory_layers=2), 10).double()
    steps, start, mask = _sequence_batch(memory, 10, [9, 6, 1, 4], seed=1)
    sequence_output = memory.sequences(steps, start, mask)
    padded = torch.zeros(*mask.shape, 10, dtype=torch.float64).index_put((mask,), steps)
    state, outputs = start, []
    for t in range(mask.shape[1]):
        output, state = memory.step(padded[:, t], state)
        outputs.append(output)
    torch.testing.assert_close(sequence_output, torch.stack(outputs, dim=1)[mask], rtol=1e-10, atol=1e-10)
    sequence_output.square().sum().backward()
    assert all(p.grad is not None and torch.isfinite(p.grad).all() for p in memory.parameters())
    assert all(p.grad.abs().sum() > 0 for p in memory.parameters())


@pytest.mark.parametrize("name", SCAN_MEMORIES)
def test_the_state_carries_across_truncated_sequences(name: str) -> None:
    """A sequence cut in two, the second half started from the state the first half ended with (what the buffer
    stores), gives the outputs of the uncut sequence; and a zero state is an episode start (the padding before it is
    never seen)."""
    torch.manual_seed(0)
    memory = build_memory(_small_config(name, memory_size=16), 6).double()
    steps = torch.randn(1, 12, 6, dtype=torch.float64)
    full, _ = memory.run(steps, memory.initial_state(1, "cpu").double())
    first, state = memory.run(steps[:, :5], memory.initial_state(1, "cpu").double())
    second, _ = memory.run(steps[:, 5:], state)
    torch.testing.assert_close(torch.cat((first, second), dim=1), full, rtol=1e-10, atol=1e-10)


def test_lru_decays_stay_inside_the_unit_circle_on_the_init_ring() -> None:
    config = ModelConfig(memory="lru", memory_size=32)
    config.lru.r_min, config.lru.r_max = 0.5, 0.9
    decay = build_memory(config, 4).blocks[0].decay()
    assert decay.abs().min() >= 0.5 - 1e-6 and decay.abs().max() <= 0.9 + 1e-6


def test_mamba_keeps_its_convolution_window_in_the_state() -> None:
    """The state holds the convolution's last conv_size - 1 inputs: with the SSM's part of the state zeroed, the next
    output still depends on the input 3 steps back (conv 4), and no longer once the window is zeroed too."""
    torch.manual_seed(0)
    memory = build_memory(ModelConfig(memory="mamba", memory_size=8), 4).double()
    block = memory.blocks[0]
    assert block.state_size == 3 * 16 + 16 * 16 and memory.state_shape == (1, block.state_size)
    steps = torch.randn(1, 5, 4, dtype=torch.float64)
    changed = steps.clone()
    changed[:, 1] += 1.0

    def last_output(sequence: torch.Tensor, keep_window: bool) -> torch.Tensor:
        _, state = memory.run(sequence[:, :4], memory.initial_state(1, "cpu").double())
        state[:, :, block.conv_size :] = 0  # the SSM's states
        if not keep_window:
            state[:, :, : block.conv_size] = 0
        return memory.run(sequence[:, 4:], state)[0]

    assert not torch.allclose(last_output(steps, True), last_output(changed, True))
    torch.testing.assert_close(last_output(steps, False), last_output(changed, False), rtol=0, atol=0)


def test_an_import_path_memory_is_built_with_its_options() -> None:
    config = ModelConfig(
        memory="tests.support.external_memory:LeakyMemory", memory_size=8, memory_options={"leak": 0.25}
    )
    memory = build_memory(config, 5)
    assert isinstance(memory, LeakyMemory) and memory.leak == 0.25 and memory.output_size == 8
    assert memory_class("tests.support.external_memory:LeakyMemory") is LeakyMemory


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ("tests.support.no_such_module:Memory", "cannot import module 'tests.support.no_such_module'"),
        ("tests.support.external_memory:Missing", "has no attribute 'Missing'"),
        ("tests.support.external_memory:ModelConfig", "not a subclass of agents.memory.Memory"),
        ("tests.support.external_memory:", "expected an import path"),
    ],
)
def test_a_bad_import_path_names_the_key(value: str, message: str) -> None:
    with pytest.raises(ConfigError, match="model.memory=") as error:
        config_from_dict({"model": {"memory": value}})
    assert message in str(error.value)


def test_memory_options_without_an_import_path_are_refused() -> None:
    with pytest.raises(ConfigError, match=r"model.memory_options=.*only for a memory given by import path"):
        config_from_dict({"model": {"memory": "gru", "memory_options": {"leak": 0.5}}})


def test_an_external_memory_trains_evaluates_and_names_its_runs(tmp_path: Path) -> None:
    """The memory outside agents/ trains end to end through the one trainer (and evaluates through its actor); its
    method name is the class's."""
    raw = {
        "env": {"id": "ProofOfMemory-v0", "options": {"delay": 2}},
        "model": {
            "memory": "tests.support.external_memory:LeakyMemory",
            "memory_size": 16,
            "hidden_size": 16,
            "memory_options": {"leak": 0.8},
        },
        "ppo": {"epochs": 1, "minibatches": 2},
        "run": {"total_steps": 2 * 4 * 16, "workers": 4, "worker_steps": 16, "progress_bar": False, "torch_threads": 1},
        "eval": {"interval": 2, "seeds": [100000, 100002], "repetitions": 1},
    }
    config = config_from_dict(raw)
    assert config.method == "LeakyMemory"
    trainer = Trainer(config, tmp_path)
    history = trainer.train()
    assert len(history) == 2 and np.isfinite(history[-1]["losses/policy_loss"])
    assert isinstance(trainer.model.memory, LeakyMemory) and trainer.model.memory.leak == 0.8
    with open(tmp_path / "eval" / "episodes.csv") as records:
        assert len(records.readlines()) == 1 + 3 * 1  # the header and 3 seeds x 1 repetition at update 2


def test_lru_checkpoints_with_separate_real_and_imaginary_matrices_still_load() -> None:
    """The earlier layout of B and C (input_re/_im, output_re/_im) loads into the interleaved one and computes the
    same outputs: y = Re(C h) + D u with h driven by (B_re u, B_im u)."""
    torch.manual_seed(0)
    memory = build_memory(ModelConfig(memory="lru", memory_size=6, lru=LruConfig(state_size=4)), 5).double()
    block = memory.blocks[0]
    old = {k: v for k, v in memory.state_dict().items() if "input_weight" not in k and "output_weight" not in k}
    input_re, input_im = torch.randn(4, 6).double(), torch.randn(4, 6).double()
    output_re, output_im = torch.randn(6, 4).double(), torch.randn(6, 4).double()
    old |= {"blocks.0.input_re": input_re, "blocks.0.input_im": input_im}
    old |= {"blocks.0.output_re": output_re, "blocks.0.output_im": output_im}
    memory.load_state_dict(old)
    u = torch.randn(2, 3, 6, dtype=torch.float64)
    projected = torch.view_as_complex((u @ block.input_weight.T).unflatten(-1, (4, 2)))
    torch.testing.assert_close(projected, torch.complex(u @ input_re.T, u @ input_im.T))
    h = torch.randn(2, 3, 4, dtype=torch.complex128)
    readout = torch.view_as_real(h).reshape(2, 3, 8) @ block.output_weight.T
    torch.testing.assert_close(readout, h.real @ output_re.T - h.imag @ output_im.T)
