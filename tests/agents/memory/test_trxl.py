"""The Transformer-XL memory: episodic windows, cached rollout outputs == the training pass, padding, positional
encodings, bounded memory on endless episodes, GTrXL gating, and the config's checks."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from agents.config import ConfigError, config_from_dict
from agents.memory.transformer import TransformerXL, TrxlConfig, shift_window
from agents.policy.actor import refresh_copy
from agents.training.buffer import RolloutBuffer
from agents.training.sequences import pad_sequences, split_sequences
from agents.training.trainer import Trainer

FEATURES = 5


@pytest.fixture(autouse=True)
def one_thread():
    """Tiny tensors: one torch thread is as fast, and does not stall when the machine's cores are busy."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def _memory(**kw) -> TransformerXL:
    torch.manual_seed(0)
    settings = {"layers": 2, "heads": 2, "dim": 8, "memory_length": 3, **kw}
    return TransformerXL(TrxlConfig(**settings), FEATURES)


def _layout() -> tuple[np.ndarray, torch.Tensor]:
    """3 workers x 11 steps with episode ends inside and across rows, and where every row starts mid-episode."""
    terminated = np.zeros((3, 11), dtype=bool)
    terminated[0, 4] = terminated[1, 1] = terminated[1, 8] = True
    return terminated, torch.tensor([2, 0, 5])  # decisions each slot's episode had taken before the rollout


def _rollout(
    memory: TransformerXL,
    features: torch.Tensor,
    terminated: np.ndarray,
    episode_step: torch.Tensor,
    window_seed: int = 1,
    cached: bool = True,
) -> tuple[torch.Tensor, RolloutBuffer]:
    """Act step by step from a random carried-in window (drawn with ``window_seed``) as the actor does: with
    ``cached``, one acting cache built from that window and carried through every step and episode end, else one
    built afresh from the state at every step. Returns the outputs (W, T, dim) and the buffer holding the records
    and episode steps."""
    workers, steps = terminated.shape
    state = torch.randn((workers, *memory.state_shape), generator=torch.Generator().manual_seed(window_seed))
    state = state.to(memory.state_dtype)
    buffer = RolloutBuffer(workers, steps, {}, 1, memory.record_shape, "cpu", 1, memory.history, memory.state_dtype)
    buffer.begin({}, memory.history_records(state))
    outputs = []
    with torch.no_grad():
        cache = memory.acting_cache(state, episode_step) if cached else None
        for t in range(steps):
            output, next_state = memory.step(features[:, t], state, episode_step, cache)
            buffer.store_record(t, memory.record(state, next_state))
            buffer.episode_step[:, t] = episode_step
            outputs.append(output)
            alive = torch.from_numpy(~terminated[:, t])
            state = next_state * alive.view(-1, 1, 1, 1)
            episode_step = (episode_step + 1) * alive
    return torch.stack(outputs, dim=1), buffer


def _training_pass(memory: TransformerXL, buffer: RolloutBuffer, features: torch.Tensor, batch) -> torch.Tensor:
    flat = features.reshape(-1, FEATURES)
    records = buffer.memory_records(batch.start_index, batch.mask.shape[1])
    episode_step = buffer.flat(buffer.episode_step)[batch.step_index]
    return memory.sequences(flat[batch.step_index], records, batch.mask, episode_step)


VARIANTS = [  # every encoding and norm, gating and both projections; not their whole product (time)
    {"positional_encoding": "relative", "layer_norm": "pre", "gating": False, "shared_head_projections": False},
    {"positional_encoding": "absolute", "layer_norm": "pre", "gating": False, "shared_head_projections": True},
    {"positional_encoding": "learned", "layer_norm": "post", "gating": True, "shared_head_projections": False},
    {"positional_encoding": "none", "layer_norm": "none", "gating": True, "shared_head_projections": True},
    {"positional_encoding": "relative", "layer_norm": "post", "gating": True, "shared_head_projections": True},
]


@pytest.mark.parametrize("variant", VARIANTS, ids=lambda v: "-".join(str(x) for x in v.values()))
def test_cached_rollout_outputs_equal_the_training_pass(variant: dict) -> None:
    """What the rollout computed one step at a time (windows carried into the rollout, episode ends inside it) is
    what the training pass recomputes from the buffer's records, for sequences of any length in any order."""
    memory = _memory(**variant)
    terminated, episode_step = _layout()
    features = torch.randn(3, 11, FEATURES, generator=torch.Generator().manual_seed(2))
    outputs, buffer = _rollout(memory, features, terminated, episode_step)
    for length in (None, 4, 1):
        sequences = split_sequences(terminated, length)
        batch = pad_sequences(sequences, np.random.default_rng(0).permutation(len(sequences)))
        with torch.no_grad():
            trained = _training_pass(memory, buffer, features, batch)
        torch.testing.assert_close(trained, outputs.reshape(33, -1)[batch.step_index], atol=1e-5, rtol=1e-5)


@pytest.mark.parametrize("variant", VARIANTS, ids=lambda v: "-".join(str(x) for x in v.values()))
def test_a_carried_acting_cache_gives_the_outputs_of_one_built_at_every_step(variant: dict) -> None:
    """The window's key and value inputs computed once per entry and carried in a ring through episode ends (where
    the cleared slot reads none of them) give what a cache built from the whole window at every step gives."""
    memory = _memory(**variant)
    terminated, episode_step = _layout()
    features = torch.randn(3, 11, FEATURES, generator=torch.Generator().manual_seed(8))
    carried, carried_buffer = _rollout(memory, features, terminated, episode_step)
    fresh, fresh_buffer = _rollout(memory, features, terminated, episode_step, cached=False)
    torch.testing.assert_close(carried, fresh, atol=1e-6, rtol=1e-6)
    torch.testing.assert_close(carried_buffer.memory_states, fresh_buffer.memory_states, atol=1e-6, rtol=1e-6)


def test_the_actor_rebuilds_its_acting_cache_when_the_weights_or_the_state_change(tmp_path) -> None:
    """Every decision of the trainer's actor (caches carried through rollouts, rebuilt after each update's new
    weights, episode ends inside) is what a step that builds its cache from the state gives."""
    config = config_from_dict(
        {
            "env": {"id": "ProofOfMemory-v0", "options": {"delay": 4}},
            "model": {"memory": "trxl", "hidden_size": 16, "trxl": {"layers": 2, "heads": 2, "dim": 16}},
            "ppo": {"epochs": 1, "minibatches": 2},
            "run": {"total_steps": 4 * 8 * 3, "workers": 4, "worker_steps": 8, "seed": 3, "progress_bar": False},
        },
        ["model.trxl.memory_length=3", "run.torch_threads=1"],
    )
    trainer = Trainer(config, tmp_path)
    model = trainer.rollout_model
    acting_step, checked = model.step, []

    def compared_step(inputs, state, episode_step, cache=None):
        fresh = acting_step(inputs, state, episode_step)  # first: the cached step advances its cache
        result = acting_step(inputs, state, episode_step, cache)
        for a, b in zip((*fresh[0], *fresh[1:]), (*result[0], *result[1:]), strict=True):
            torch.testing.assert_close(a, b, atol=1e-6, rtol=1e-6)
        checked.append(cache is not None)
        return result

    model.step = compared_step  # type: ignore[method-assign]
    for _ in range(3):
        trainer.train_update()
    assert sum(checked) == 3 * 8  # every decision of the rollouts used a cache
    actor = trainer.actor
    for _ in range(2):  # a cache of the current weights advanced to the current state, windows not empty
        actor.advance(actor.decide())
    assert actor.memory.episode_step.min() > 0
    actor.memory.recurrent = torch.randn_like(actor.memory.recurrent)  # a replaced state (as a resume loads one)
    actor.advance(actor.decide())
    with torch.no_grad():
        for weight in model.memory.parameters():
            weight.mul_(0.5)  # new weights (as an update writes them): a stale window cache would show
    refresh_copy(model, trainer.model)
    actor.decide()
    assert sum(checked) == 3 * 8 + 4


def test_a_bf16_cache_gives_the_same_outputs_in_rollout_and_training() -> None:
    memory = _memory(cache_dtype="bf16")
    terminated, episode_step = _layout()
    features = torch.randn(3, 11, FEATURES, generator=torch.Generator().manual_seed(3))
    outputs, buffer = _rollout(memory, features, terminated, episode_step)
    assert buffer.memory_states.dtype == torch.bfloat16
    batch = pad_sequences(split_sequences(terminated, None), np.arange(5))
    with torch.no_grad():
        trained = _training_pass(memory, buffer, features, batch)
    torch.testing.assert_close(trained, outputs.reshape(33, -1)[batch.step_index], atol=1e-5, rtol=1e-5)


def test_no_attention_across_episodes_to_itself_or_the_future() -> None:
    """Perturbing the previous episode (its steps and the window carried in) or the future changes no output of an
    episode; the first step of an episode depends on nothing but its own features."""
    memory = _memory(memory_length=6)
    terminated = np.zeros((1, 12), dtype=bool)
    terminated[0, 4] = True  # episode A: steps 0-4, episode B: 5-11
    features = torch.randn(1, 12, FEATURES, generator=torch.Generator().manual_seed(4))
    outputs, _ = _rollout(memory, features, terminated, torch.tensor([3]))
    changed = features.clone()
    changed[0, :5] += 10.0  # the whole previous episode, and the window it carried into the rollout
    changed_outputs, _ = _rollout(memory, changed, terminated, torch.tensor([3]), window_seed=9)
    assert not torch.allclose(changed_outputs[0, :5], outputs[0, :5])
    torch.testing.assert_close(changed_outputs[0, 5:], outputs[0, 5:], atol=0, rtol=0)
    future = features.clone()
    future[0, 8:] -= 5.0
    future_outputs, _ = _rollout(memory, future, terminated, torch.tensor([3]))
    torch.testing.assert_close(future_outputs[0, :8], outputs[0, :8], atol=0, rtol=0)
    assert not torch.allclose(future_outputs[0, 8:], outputs[0, 8:])  # the perturbation is large enough to show

    # the first step of an episode: any window contents give the output of an all-zero window
    state = torch.randn((4, *memory.state_shape))
    with torch.no_grad():
        first, _ = memory.step(features[0, :4], state, torch.zeros(4, dtype=torch.int64))
        empty, _ = memory.step(features[0, :4], torch.zeros_like(state), torch.zeros(4, dtype=torch.int64))
    torch.testing.assert_close(first, empty, atol=0, rtol=0)


def test_the_empty_window_gives_zero_attention_not_a_softmax_over_padding() -> None:
    block = _memory().blocks[0]
    # 2 heads x 3 sequences, heads first: sequence 0 has no valid key, sequence 1 one, sequence 2 all four
    query, keys, values = torch.randn(2, 3, 1, 4), torch.randn(2, 3, 4, 4), torch.randn(2, 3, 4, 4)
    valid = torch.zeros(3, 1, 4, dtype=torch.bool)
    valid[1, 0, 2] = True
    valid[2] = True
    attended = block.attend(query, keys, values, valid, None)
    torch.testing.assert_close(attended[:, 0], torch.zeros(2, 1, 4), atol=0, rtol=0)  # no value reaches it
    torch.testing.assert_close(attended[:, 1], values[:, 1, 2:3])  # the one valid key gets all the weight
    weights = torch.softmax(query[:, 2] @ keys[:, 2].mT / math.sqrt(block.head_dim), dim=-1)
    torch.testing.assert_close(attended[:, 2], weights @ values[:, 2])  # each head over its own keys


def test_padding_changes_no_output_and_no_gradient() -> None:
    memory = _memory(gating=True)
    terminated, episode_step = _layout()
    features = torch.randn(3, 11, FEATURES, generator=torch.Generator().manual_seed(5))
    _, buffer = _rollout(memory, features, terminated, episode_step)
    sequences = split_sequences(terminated, None)

    def loss_and_grads(pad_to: int | None) -> tuple[torch.Tensor, list[torch.Tensor]]:
        memory.zero_grad()
        batch = pad_sequences(sequences, np.arange(len(sequences)), pad_to=pad_to)
        loss = _training_pass(memory, buffer, features, batch).square().mean()
        loss.backward()
        return loss.detach(), [p.grad.clone() for p in memory.parameters()]

    loss, grads = loss_and_grads(None)
    for pad_to in (int(sequences.lengths.max()) + 1, int(sequences.lengths.max()) + 7):
        padded_loss, padded_grads = loss_and_grads(pad_to)
        torch.testing.assert_close(padded_loss, loss, atol=1e-6, rtol=1e-6)
        for a, b in zip(padded_grads, grads, strict=True):
            torch.testing.assert_close(a, b, atol=1e-6, rtol=1e-6)


@pytest.mark.parametrize("encoding", ["relative", "absolute", "learned", "none"])
def test_positional_encodings_make_the_order_of_the_window_matter(encoding: str) -> None:
    """Without an encoding attention is blind to order (swapping two window entries changes nothing); every
    encoding sees it. The relative one depends on distances only: the same window at episode step 10 or 10,000 gives
    the same output."""
    memory = _memory(positional_encoding=encoding, memory_length=4, positional_size=64)
    state = torch.randn((1, *memory.state_shape), generator=torch.Generator().manual_seed(6))
    swapped = state[:, [1, 0, 2, 3]]
    features = torch.randn(1, FEATURES)
    steps = torch.tensor([10])
    with torch.no_grad():
        output = memory.step(features, state, steps)[0]
        output_swapped = memory.step(features, swapped, steps)[0]
        later = memory.step(features, state, torch.tensor([11]))[0]
    assert torch.allclose(output, output_swapped, atol=1e-6) == (encoding == "none")
    assert torch.allclose(output, later, atol=1e-6) == (encoding in ("relative", "none"))
    if encoding == "relative":
        with torch.no_grad():
            far = memory.step(features, state, torch.tensor([10_000]))[0]
        torch.testing.assert_close(far, output, atol=0, rtol=0)


@pytest.mark.parametrize("encoding", ["absolute", "learned"])
def test_episode_step_encodings_refuse_longer_episodes(encoding: str) -> None:
    memory = _memory(positional_encoding=encoding, positional_size=16)
    state = memory.initial_state(1, "cpu")
    memory.step(torch.randn(1, FEATURES), state, torch.tensor([16]))
    with pytest.raises(ValueError, match=f"positional_encoding='{encoding}'.*positional_size=16.*'relative'"):
        memory.step(torch.randn(1, FEATURES), state, torch.tensor([17]))


@pytest.mark.slow
def test_a_20000_step_endless_episode_keeps_memory_bounded_and_equal_to_its_window() -> None:
    """20,000 steps of one episode: the state stays (memory_length, layers, dim); the last output is exactly what
    the training pass computes from the last memory_length records alone."""
    memory = _memory(memory_length=4)
    steps = 20_000
    features = torch.randn(steps, 1, FEATURES, generator=torch.Generator().manual_seed(7))
    state = memory.initial_state(1, "cpu")
    records = []
    with torch.inference_mode():
        for t in range(steps):
            output, next_state = memory.step(features[t], state, torch.tensor([t]))
            records = [*records[-4:], memory.record(state, next_state)]
            state = next_state
    assert state.shape == (1, 4, 2, 8) and torch.isfinite(output).all()
    with torch.no_grad():
        window = torch.stack(records, dim=1)  # the 4 steps before the last, then the last one itself
        mask = torch.ones(1, 1, dtype=torch.bool)
        recomputed = memory.sequences(features[-1], window, mask, torch.tensor([steps - 1]))
    torch.testing.assert_close(recomputed, output, atol=1e-6, rtol=1e-6)


def test_shifting_the_window_in_place_keeps_every_window_it_returned() -> None:
    """Acting moves the window on without copying it (a view of a buffer twice its length): over several buffers'
    worth of steps every window equals the one a copy gives and stays so; a second step from the same window (a
    branch) gets its own entries and leaves the first branch's alone; with autograd it is a plain copy."""
    length = 3
    with torch.inference_mode():
        window, copied, returned = torch.zeros(2, length, 4), torch.zeros(2, length, 4), []
        for t in range(4 * length + 1):
            entry = torch.full((2, 4), float(t + 1))
            window, copied = shift_window(window, entry), torch.cat((copied[:, 1:], entry[:, None]), dim=1)
            returned.append((window, copied.clone()))
            assert window.window_buffer.shape[1] == 2 * length  # a view of the buffer, not a copy
        for shifted, expected in returned:
            torch.testing.assert_close(shifted, expected, rtol=0, atol=0)
        first = shift_window(window, torch.full((2, 4), -1.0))
        second = shift_window(window, torch.full((2, 4), -2.0))
        assert float(first[0, -1, 0]) == -1.0 and float(second[0, -1, 0]) == -2.0
        torch.testing.assert_close(first[:, :-1], window[:, 1:], rtol=0, atol=0)
    leaf = torch.zeros(2, length, 4, requires_grad=True)
    shifted = shift_window(leaf, torch.ones(2, 4))
    shifted.sum().backward()
    assert not hasattr(shifted, "window_buffer") and leaf.grad is not None


def test_gtrxl_gates_start_near_the_identity_and_change_the_outputs() -> None:
    """With gating each residual is a GRU gate: a large bias keeps a block's output at its input; the default bias
    lets the block act."""
    features = torch.randn(4, FEATURES)
    steps = torch.tensor([0, 1, 2, 3])
    shut = _memory(gating=True, gating_bias=1e4, layer_norm="none")
    state = torch.randn((4, *shut.state_shape))
    with torch.no_grad():
        output, next_state = shut.step(features, state, steps)
        embedded = shut.embed(features)
    torch.testing.assert_close(output, embedded, atol=1e-5, rtol=1e-5)  # every gate passed its input through
    torch.testing.assert_close(next_state[:, -1, 1], embedded, atol=1e-5, rtol=1e-5)
    open_gates = _memory(gating=True, layer_norm="none")
    with torch.no_grad():
        assert not torch.allclose(open_gates.step(features, state, steps)[0], open_gates.embed(features), atol=1e-3)


def test_config_checks_name_the_key_and_the_choices() -> None:
    for key, value, message in (
        ("positional_encoding", "rotary", "valid choices: relative, absolute, learned, none"),
        ("layer_norm", "both", "valid choices: pre, post, none"),
        ("cache_dtype", "fp16", "valid choices: fp32, bf16"),
        ("dim", 10, "expected a multiple of model.trxl.heads=4"),
    ):
        with pytest.raises(ConfigError, match=f"model.trxl.{key}=.*{message}"):
            config_from_dict({"model": {"memory": "trxl", "trxl": {key: value}}})
