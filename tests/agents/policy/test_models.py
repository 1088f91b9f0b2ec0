"""The actor-critic: input layout, initialisation, the memory modules and padding invariance."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
import torch

from agents.config import ModelConfig
from agents.policy.models import (
    ActorCritic,
    NatureCNN,
    RecurrentMemory,
    choose_actions,
    log_probs_and_entropy,
    model_inputs,
)
from agents.training.ppo import filled_index
from agents.training.sequences import Sequences, pad_sequences, split_sequences

IMAGE = gym.spaces.Box(0, 255, (36, 36, 3), np.uint8)
DICT = gym.spaces.Dict({"visual_observation": IMAGE, "vector_observation": gym.spaces.Box(-1.0, 1.0, (5,), np.float32)})
MULTI = gym.spaces.MultiDiscrete([3, 3])


def _model(memory: str, observation_space: gym.Space = DICT, action_space: gym.Space = MULTI, **kw) -> ActorCritic:
    torch.manual_seed(0)
    config = ModelConfig(memory=memory, memory_size=16, hidden_size=24, vector_encoder_size=8, **kw)
    return ActorCritic(observation_space, action_space, config)


def _inputs(model: ActorCritic, n: int, seed: int = 0) -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    out = {}
    for name, field in model.inputs.items():
        if field.dtype == torch.uint8:
            out[name] = torch.randint(0, 256, (n, *field.shape), generator=g, dtype=torch.uint8)
        elif field.dtype == torch.int64:
            out[name] = torch.randint(0, 3, (n, *field.shape), generator=g)
        else:
            out[name] = torch.randn((n, *field.shape), generator=g)
    return out


def test_inputs_follow_the_spaces_and_the_config() -> None:
    config = ModelConfig(previous_action=True, previous_reward=True)
    fields = model_inputs(DICT, MULTI, config)
    assert {k: (v.shape, v.dtype) for k, v in fields.items()} == {
        "image": ((36, 36, 3), torch.uint8),
        "vector": ((5,), torch.float32),
        "previous_action": ((2,), torch.int64),
        "previous_reward": ((), torch.float32),
    }
    assert list(model_inputs(IMAGE, gym.spaces.Discrete(2), ModelConfig())) == ["image"]
    with pytest.raises(ValueError, match="uint8 Box"):
        model_inputs(gym.spaces.Box(0.0, 1.0, (36, 36, 3), np.float32), MULTI, config)
    with pytest.raises(ValueError, match="Dict observation keys"):
        model_inputs(gym.spaces.Dict({"image": IMAGE}), MULTI, config)
    with pytest.raises(ValueError, match="action space"):
        ActorCritic(IMAGE, gym.spaces.Box(-1, 1, (2,)), config)


@pytest.mark.parametrize("memory", ["none", "gru", "lstm"])
def test_output_shapes(memory: str) -> None:
    model = _model(memory, previous_action=True, previous_reward=True)
    state = model.initial_state(5, "cpu")
    assert state.shape == {"none": (5, 0), "gru": (5, 1, 16), "lstm": (5, 2, 1, 16)}[memory]
    logits, values, next_state = model.step(_inputs(model, 5), state)
    assert [tuple(x.shape) for x in logits] == [(5, 3), (5, 3)] and values.shape == (5,)
    assert next_state.shape == state.shape
    actions, log_probs = choose_actions(logits, torch.Generator().manual_seed(0))
    assert actions.shape == (5, 2) and actions.dtype == torch.int64 and log_probs.shape == (5, 2)
    again, entropy = log_probs_and_entropy(logits, actions)
    torch.testing.assert_close(again, log_probs)
    assert entropy.shape == (5,) and (entropy <= 2 * math.log(3) + 1e-6).all()


def test_initialisation_gains() -> None:
    model = _model("gru", IMAGE, gym.spaces.Discrete(4))

    def gram(w: torch.Tensor) -> torch.Tensor:  # W W^T for wide matrices, W^T W for tall ones
        w = w.detach().reshape(w.shape[0], -1)
        return w @ w.T if w.shape[0] <= w.shape[1] else w.T @ w

    def assert_orthogonal(w: torch.Tensor, gain: float) -> None:
        g = gram(w)
        torch.testing.assert_close(g, gain**2 * torch.eye(g.shape[0]), atol=1e-5, rtol=1e-5)

    assert_orthogonal(model.policy_heads[0].weight, 0.1)
    assert_orthogonal(model.value_head.weight, 1.0)
    for layer in (model.body[0], model.policy_stream[0], model.value_stream[0], model.image_encoder.convs[0]):
        assert_orthogonal(layer.weight, math.sqrt(2))
    assert_orthogonal(model.memory.rnn.weight_hh_l0, math.sqrt(2))
    assert_orthogonal(model.memory.rnn.weight_ih_l0, math.sqrt(2))
    # as in the authors' code: recurrent biases start at zero, the others keep PyTorch's uniform(+-1/sqrt(fan_in))
    for name in ("bias_ih_l0", "bias_hh_l0"):
        assert not getattr(model.memory.rnn, name).any(), name
    for name, module in model.named_modules():
        if isinstance(module, torch.nn.Conv2d | torch.nn.Linear):
            fan_in = module.weight[0].numel()
            assert module.bias.any() and module.bias.abs().max() <= 1 / math.sqrt(fan_in), name


def test_pixels_are_scaled_once_and_must_be_uint8() -> None:
    cnn = NatureCNN((36, 36, 3))
    white = torch.full((2, 36, 36, 3), 255, dtype=torch.uint8)
    expected = cnn.convs(torch.ones(2, 3, 36, 36))
    torch.testing.assert_close(cnn(white), expected)
    with pytest.raises(TypeError, match="uint8"):
        cnn(white.float())
    with pytest.raises(ValueError, match="too small"):
        NatureCNN((32, 32, 3))
    assert NatureCNN((84, 84, 3)).output_size == 64 * 7 * 7


def _episode_layout() -> tuple[np.ndarray, int, int]:
    # 3 workers x 7 steps; episodes of several lengths, some crossing the rollout's start and end
    terminated = np.zeros((3, 7), dtype=bool)
    terminated[0, [1, 5]] = True
    terminated[2, 3] = True
    return terminated, 3, 7


@pytest.mark.parametrize("memory", ["gru", "lstm"])
@pytest.mark.parametrize("max_length", [None, 2])
def test_sequences_reproduce_step_by_step_outputs(memory: str, max_length: int | None) -> None:
    """Training on padded sequences from stored start states gives what the rollout computed one step at a time."""
    model = _model(memory, previous_action=True)
    terminated, workers, steps = _episode_layout()
    inputs = _inputs(model, workers * steps, seed=1)
    step_inputs = {k: v.reshape(workers, steps, *v.shape[1:]) for k, v in inputs.items()}
    state = torch.randn(model.initial_state(workers, "cpu").shape, generator=torch.Generator().manual_seed(2))
    states, values, logits0 = [], [], []
    with torch.no_grad():
        for t in range(steps):
            states.append(state)
            logits, value, state = model.step({k: v[:, t] for k, v in step_inputs.items()}, state)
            values.append(value)
            logits0.append(logits[0])
            state = state * torch.from_numpy(~terminated[:, t]).view(-1, *[1] * (state.dim() - 1))
    flat_states = torch.stack(states, dim=1).reshape(workers * steps, *state.shape[1:])
    flat_values = torch.stack(values, dim=1).reshape(-1)
    flat_logits = torch.stack(logits0, dim=1).reshape(workers * steps, -1)

    sequences = split_sequences(terminated, max_length)
    batch = pad_sequences(sequences, np.random.default_rng(0).permutation(len(sequences)))
    with torch.no_grad():
        logits, values, _ = model.evaluate(
            {k: v[batch.step_index] for k, v in inputs.items()}, flat_states[batch.start_index], batch.mask
        )
    torch.testing.assert_close(values, flat_values[batch.step_index], atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(logits[0], flat_logits[batch.step_index], atol=1e-5, rtol=1e-5)


def _training_case(memory: str, seed: int) -> tuple[ActorCritic, Sequences, dict[str, torch.Tensor], torch.Tensor]:
    """A model, the sequences of the hand-made episode layout, random inputs and start states for every step."""
    model = _model(memory, previous_action=True, previous_reward=True)
    terminated, workers, steps = _episode_layout()
    sequences = split_sequences(terminated, None if memory != "none" else 1)
    inputs = _inputs(model, workers * steps, seed=seed)
    states = torch.randn(workers * steps, *model.state_shape, generator=torch.Generator().manual_seed(seed + 1))
    return model, sequences, inputs, states


@pytest.mark.parametrize("memory", ["none", "gru", "lstm"])
def test_padding_changes_no_output_and_no_gradient(memory: str) -> None:
    model, sequences, inputs, states = _training_case(memory, seed=3)
    ids = np.arange(len(sequences))

    def loss_and_grads(pad_to: int | None) -> tuple[torch.Tensor, list[torch.Tensor]]:
        batch = pad_sequences(sequences, ids, pad_to=pad_to)
        model.zero_grad()
        logits, values, _ = model.evaluate(
            {k: v[batch.step_index] for k, v in inputs.items()}, states[batch.start_index], batch.mask
        )
        loss = values.square().mean() + sum(x.logsumexp(-1).mean() for x in logits)
        loss.backward()
        return loss.detach(), [p.grad.clone() for p in model.parameters()]

    loss, grads = loss_and_grads(None)
    longest = int(sequences.lengths.max())
    for extra in (1, 9):
        padded_loss, padded_grads = loss_and_grads(longest + extra)
        torch.testing.assert_close(padded_loss, loss, atol=1e-6, rtol=1e-6)
        for a, b in zip(padded_grads, grads, strict=True):
            torch.testing.assert_close(a, b, atol=1e-6, rtol=1e-6)


@pytest.mark.parametrize("memory", ["none", "gru"])
def test_filler_rows_change_no_output_and_no_gradient(memory: str) -> None:
    """The PPO update rounds a minibatch's rows up with filler (filled_index): same outputs, loss and gradients."""
    model, sequences, inputs, states = _training_case(memory, seed=5)
    batch = pad_sequences(sequences, np.arange(len(sequences)))
    assert batch.num_steps % 8 != 0, "the layout must need filler for this test to mean anything"

    def run(index: torch.Tensor) -> tuple[list[torch.Tensor], torch.Tensor, list[torch.Tensor]]:
        model.zero_grad()
        selected = {k: v[index] for k, v in inputs.items()}
        logits, values, _ = model.evaluate(selected, states[batch.start_index], batch.mask)
        (values.square().mean() + sum(x.logsumexp(-1).mean() for x in logits)).backward()
        return logits, values, [p.grad.clone() for p in model.parameters()]

    filled = filled_index(batch.step_index)
    assert filled.shape[0] % 8 == 0 and filled.shape[0] > batch.num_steps
    assert torch.equal(filled[: batch.num_steps], batch.step_index)
    logits, values, grads = run(batch.step_index)
    filled_logits, filled_values, filled_grads = run(filled)
    assert values.shape == filled_values.shape and len(filled_logits) == len(logits)
    torch.testing.assert_close(filled_values, values, atol=1e-6, rtol=1e-6)
    for a, b in zip(filled_logits, logits, strict=True):
        torch.testing.assert_close(a, b, atol=1e-6, rtol=1e-6)
    for a, b in zip(filled_grads, grads, strict=True):
        torch.testing.assert_close(a, b, atol=1e-6, rtol=1e-6)


@pytest.mark.parametrize("layers", [1, 2])
def test_packed_gru_equals_torch_gru_in_outputs_and_every_gradient(layers: int) -> None:
    """RecurrentMemory('gru') runs its own packed recurrence: same outputs, final states and gradients (inputs,
    start states, all weights and biases) as nn.GRU on the padded batch, in float32."""
    from torch.nn.utils.rnn import pack_padded_sequence, pad_packed_sequence

    torch.manual_seed(3)
    lengths = [5, 9, 1, 9, 3]
    memory = RecurrentMemory("gru", 6, 8, layers)
    mask = torch.arange(9)[None] < torch.tensor(lengths)[:, None]
    features = torch.randn(int(mask.sum()), 6, requires_grad=True)
    start = torch.randn(len(lengths), layers, 8, requires_grad=True)
    ours = memory.sequences(features, start, mask)
    weights = torch.randn_like(ours)
    (ours * weights).sum().backward()
    got = [features.grad, start.grad] + [p.grad for p in memory.parameters()]
    features.grad, start.grad = None, None
    memory.zero_grad()

    padded = torch.zeros(len(lengths), 9, 6)
    padded[mask] = features
    packed = pack_padded_sequence(padded, torch.tensor(lengths), batch_first=True, enforce_sorted=False)
    output, _ = memory.rnn(packed, start.transpose(0, 1).contiguous())
    theirs = pad_packed_sequence(output, batch_first=True)[0][mask]
    (theirs * weights).sum().backward()
    expected = [features.grad, start.grad] + [p.grad for p in memory.parameters()]
    torch.testing.assert_close(ours, theirs, rtol=1e-5, atol=1e-6)
    for mine, reference in zip(got, expected, strict=True):
        torch.testing.assert_close(mine, reference, rtol=1e-4, atol=1e-6)

    step_out, step_state = memory.step(features[:5].detach(), start[:, :, :].detach())
    _, final = memory.rnn(features[:5, None].detach(), start.transpose(0, 1).contiguous().detach())
    torch.testing.assert_close(step_state, final.transpose(0, 1), rtol=1e-5, atol=1e-6)
    torch.testing.assert_close(step_out, final[-1], rtol=1e-5, atol=1e-6)


def test_packed_gru_under_bfloat16_autocast_stays_close_to_float32() -> None:
    torch.manual_seed(4)
    memory = RecurrentMemory("gru", 32, 16, 1)
    mask = torch.arange(20)[None] < torch.tensor([20, 13, 7])[:, None]
    features = torch.randn(int(mask.sum()), 32)
    start = torch.randn(3, 1, 16)
    exact = memory.sequences(features, start, mask)
    with torch.autocast("cpu", dtype=torch.bfloat16):
        mixed = memory.sequences(features, start, mask)
    assert mixed.dtype == torch.float32
    assert (mixed - exact).abs().max() < 0.05


def test_the_nn_gru_path_used_off_the_cpu_agrees_with_the_packed_path(monkeypatch: pytest.MonkeyPatch) -> None:
    """Off the CPU (CUDA) RecurrentMemory runs nn.GRU itself; run that path here and compare step and sequences."""
    torch.manual_seed(5)
    memory = RecurrentMemory("gru", 6, 8, 2)
    mask = torch.arange(7)[None] < torch.tensor([7, 2, 5])[:, None]
    features, start = torch.randn(int(mask.sum()), 6), torch.randn(3, 2, 8)
    packed = memory.sequences(features, start, mask), memory.step(features[:3], start)
    monkeypatch.setattr(RecurrentMemory, "_packed_gru", lambda self, features: False)
    nn_path = memory.sequences(features, start, mask), memory.step(features[:3], start)
    torch.testing.assert_close(packed[0], nn_path[0], rtol=1e-5, atol=1e-6)
    for ours, theirs in zip(packed[1], nn_path[1], strict=True):
        torch.testing.assert_close(ours, theirs, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("side", [36, 84])
def test_the_observation_decoder_mirrors_the_encoder_and_its_loss_reaches_the_memory(side: int) -> None:
    """The decoder redraws the newest frame at the observation's size; its BCE (against obs / 255) is what the
    model returns with reconstruct=True, and its gradient reaches the memory and the encoder."""
    space = gym.spaces.Box(0, 255, (side, side, 3), np.uint8)
    config = ModelConfig(memory="gru", memory_size=16, hidden_size=16, frame_stack=2)
    torch.manual_seed(0)
    model = ActorCritic(space, gym.spaces.Discrete(3), config, reconstruction=True)
    assert ActorCritic(space, gym.spaces.Discrete(3), config).decoder is None
    inputs = {"image": torch.randint(0, 256, (6, side, side, 6), dtype=torch.uint8)}
    mask = torch.tensor([[True, True, True, True], [True, True, False, False]])
    logits, values, auxiliary = model.evaluate(inputs, torch.zeros(2, 1, 16), mask, None, reconstruct=True)
    assert list(auxiliary) == ["reconstruction_loss"]
    loss = auxiliary["reconstruction_loss"]
    output = model.memory.sequences(model.encode(inputs), torch.zeros(2, 1, 16), mask)
    assert model.decoder(output).shape == (6, side, side, 3)
    expected = torch.nn.functional.binary_cross_entropy_with_logits(
        model.decoder(output), inputs["image"][..., 3:].float() / 255
    )
    torch.testing.assert_close(loss, expected)
    loss.backward()
    assert (
        model.memory.rnn.weight_ih_l0.grad.abs().sum() > 0 and model.image_encoder.convs[0].weight.grad.abs().sum() > 0
    )
    assert model.policy_heads[0].weight.grad is None  # only the reconstruction loss was taken


def test_the_configs_encoder_choices_are_the_image_encoders_and_the_mlp() -> None:
    """model.encoder's choices live in the config (agents.config.ENCODERS, which validation reads without importing
    the policy); the image encoders the model builds must be exactly those choices but the MLP."""
    from agents.config import ENCODERS
    from agents.policy.models import IMAGE_ENCODERS

    assert set(ENCODERS) == {*IMAGE_ENCODERS, "mlp"}
