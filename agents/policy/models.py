"""The actor-critic, assembled from parts.

::

    image (uint8 HWC) -> Nature CNN --------------------------+
    vector obs, previous action (one-hot), previous reward ---+-> concat -> memory -> body FC -> policy FC -> heads
                                -> Linear(128) + ReLU --------+                               -> value FC  -> value

The encoder and the memory module come from one registry each (:data:`IMAGE_ENCODERS` for the image encoders among
the config's choices, :data:`agents.config.ENCODERS`, and :data:`agents.memory.MEMORY_MODULES` with the memory
interface, which the config validation reads too). With frame
stacking the image (and vector) input holds the last k observations along the channels; with the HELM branch, its
cached output (:mod:`agents.policy.helm`) joins the CNN features. Non-memory layers always see a flat batch of real
steps; only the memory module sees the (sequences, length) layout, which it takes from the padding mask of the
minibatch. This module does not know which memory it holds: the model passes the memory's state, records and each step's
``episode_step`` through. Two optional heads read the memory output and are trained only through their own losses
(:meth:`ActorCritic.evaluate`): the observation decoder (``ppo.reconstruction_coef``) and the ground-truth estimator
(``ppo.ground_truth_coef``); acting never runs them.

Initialisation, as in the authors' code: orthogonal weights with gain sqrt(2) for hidden and recurrent layers, 0.1
for the policy heads, 1 for the value head; convolution and linear biases keep PyTorch's default (uniform) init, and
only the recurrent biases are zeroed.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from torch import Tensor, nn
from torch.nn import functional as F

from agents.config import ModelConfig
from agents.layers import HIDDEN_GAIN, POLICY_GAIN, VALUE_GAIN, compute_dtype, orthogonal
from agents.memory import MEMORY_MODULES, NoMemory, RecurrentMemory, build_memory  # noqa: F401 (re-exported)


@dataclass(frozen=True)
class InputField:
    """One model input per environment step: its per-step shape and dtype (what the buffer stores)."""

    shape: tuple[int, ...]
    dtype: torch.dtype


def action_branches(action_space: gym.Space) -> list[int]:
    """Number of choices of every action dimension: ``[n]`` for Discrete(n), ``nvec`` for MultiDiscrete."""
    if isinstance(action_space, gym.spaces.Discrete):
        return [int(action_space.n)]
    if isinstance(action_space, gym.spaces.MultiDiscrete) and action_space.nvec.ndim == 1:
        return [int(n) for n in action_space.nvec]
    raise ValueError(f"unsupported action space {action_space}: expected Discrete or 1-d MultiDiscrete")


OBSERVATION_KEYS = {"visual_observation": "image", "vector_observation": "vector"}  # core key -> model input


def observation_fields(observation_space: gym.Space, grayscale: bool = False) -> dict[str, InputField]:
    """One step's observation as model inputs, before stacking: ``image`` uint8 (H, W, C), one luma channel with
    ``grayscale``, when the observation has an image, and ``vector`` float32 (D,) when it has a vector part (a
    gymnasium environment's observation arrives in this form: envs.gymnasium_core)."""
    if isinstance(observation_space, gym.spaces.Dict):
        unknown = set(observation_space.spaces) - set(OBSERVATION_KEYS)
        if unknown or not observation_space.spaces:
            raise ValueError(
                f"unsupported Dict observation keys {sorted(observation_space.spaces)}: expected "
                "'visual_observation' and/or 'vector_observation'"
            )
        image_space = observation_space.spaces.get("visual_observation")
        vector_space = observation_space.spaces.get("vector_observation")
    else:
        image_space, vector_space = observation_space, None
    fields = {}
    if image_space is not None:
        if not (
            isinstance(image_space, gym.spaces.Box) and image_space.dtype == np.uint8 and len(image_space.shape) == 3
        ):
            raise ValueError(f"unsupported image space {image_space}: expected a uint8 Box of shape (H, W, C)")
        height, width, channels = image_space.shape
        fields["image"] = InputField((height, width, 1 if grayscale else channels), torch.uint8)
    elif grayscale:
        raise ValueError(f"model.grayscale needs an image observation; {observation_space} has none")
    if vector_space is not None:
        fields["vector"] = InputField((int(np.prod(vector_space.shape)),), torch.float32)
    return fields


def model_inputs(
    observation_space: gym.Space, action_space: gym.Space, config: ModelConfig, helm_size: int = 0
) -> dict[str, InputField]:
    """The inputs the model takes at every step.

    ``image``: uint8 (H, W, k C) for k stacked frames; ``vector``: float32 (k D,) when the observation has a vector
    part; ``previous_action``: int64 (branches,), -1 where there is none (an episode's first step), and
    ``previous_reward``: float32 () when the config feeds them; ``helm``: float32 (helm_size,), the HELM branch's
    output, when it is on.
    """
    k = config.frame_stack
    fields = {
        name: InputField((*field.shape[:-1], k * field.shape[-1]), field.dtype)
        for name, field in observation_fields(observation_space, config.grayscale).items()
    }
    if config.previous_action:
        fields["previous_action"] = InputField((len(action_branches(action_space)),), torch.int64)
    if config.previous_reward:
        fields["previous_reward"] = InputField((), torch.float32)
    if helm_size:
        fields["helm"] = InputField((helm_size,), torch.float32)
    return fields


def join_frames(frames: Tensor) -> Tensor:
    """(N, k, ..., C) frames, the oldest first -> (N, ..., k C): the stacked input of :func:`model_inputs`.

    A concatenation along the channel axis: for multi-channel frames ~3x faster than moving the k axis and reshaping
    (torch's strided copy handles a 3-byte innermost run badly); single-channel frames need no copy at all."""
    if frames.shape[-1] == 1:
        moved = frames.movedim(1, -2)
        return moved.reshape(*moved.shape[:-2], -1)
    return torch.cat(frames.unbind(1), dim=-1)


class NatureCNN(nn.Module):
    """Three convolutions (32 8x8/4, 64 4x4/2, 64 3x3/1) with ReLU on uint8 HWC images, flattened."""

    def __init__(self, image_shape: tuple[int, int, int]) -> None:
        super().__init__()
        height, width, channels = image_shape
        self.convs = nn.Sequential(
            orthogonal(nn.Conv2d(channels, 32, 8, stride=4), HIDDEN_GAIN),
            nn.ReLU(),
            orthogonal(nn.Conv2d(32, 64, 4, stride=2), HIDDEN_GAIN),
            nn.ReLU(),
            orthogonal(nn.Conv2d(64, 64, 3, stride=1), HIDDEN_GAIN),
            nn.ReLU(),
            nn.Flatten(),
        )
        side = [height, width]
        for kernel, stride in ((8, 4), (4, 2), (3, 1)):
            side = [(s - kernel) // stride + 1 for s in side]
        if min(side) < 1:
            raise ValueError(f"image {height}x{width} is too small for the Nature CNN (at least 36x36)")
        self.output_size = 64 * side[0] * side[1]

    def forward(self, images: Tensor) -> Tensor:
        if images.dtype != torch.uint8:
            raise TypeError(f"the CNN takes uint8 images (0..255), got {images.dtype}")
        # The only place where pixels become [0, 1] floats. HWC -> CHW is a view (channels-last strides, which
        # oneDNN convolutions prefer); under autocast or with bfloat16 weights the pixels go straight to bfloat16.
        pixels = images.permute(0, 3, 1, 2).to(compute_dtype(self.convs[0].weight)).mul_(1.0 / 255.0)
        return self.convs(pixels)


class ObservationDecoder(nn.Module):
    """The observation-reconstruction head of the JMLR TrXL runs (CleanRL's ``ppo_trxl``): the memory output ->
    Linear(64 x h x w) + ReLU -> transposed convolutions mirroring the Nature CNN -> per-pixel logits of the newest
    frame, (N, H, W, C); :meth:`loss` is the binary cross-entropy against the observation / 255."""

    def __init__(self, input_size: int, image_shape: tuple[int, int, int]) -> None:
        super().__init__()
        height, width, channels = image_shape
        sides = [(height, width)]
        for kernel, stride in ((8, 4), (4, 2), (3, 1)):
            sides.append(tuple((s - kernel) // stride + 1 for s in sides[-1]))
        self.side = sides[-1]

        def up(cin: int, cout: int, kernel: int, stride: int, into: tuple[int, ...], out: tuple[int, ...]) -> nn.Module:
            extra = tuple(o - ((i - 1) * stride + kernel) for i, o in zip(into, out, strict=True))  # floor remainders
            return orthogonal(nn.ConvTranspose2d(cin, cout, kernel, stride, output_padding=extra), HIDDEN_GAIN)

        self.linear = nn.Sequential(orthogonal(nn.Linear(input_size, 64 * self.side[0] * self.side[1]), HIDDEN_GAIN))
        self.deconvs = nn.Sequential(
            nn.ReLU(),
            up(64, 64, 3, 1, sides[3], sides[2]),
            nn.ReLU(),
            up(64, 32, 4, 2, sides[2], sides[1]),
            nn.ReLU(),
            up(32, channels, 8, 4, sides[1], sides[0]),
        )

    def forward(self, memory_output: Tensor) -> Tensor:
        hidden = self.linear(memory_output).view(-1, 64, *self.side)
        return self.deconvs(hidden).permute(0, 2, 3, 1)  # back to (N, H, W, C)

    def loss(self, memory_output: Tensor, images: Tensor) -> Tensor:
        """Mean BCE of the reconstruction of ``images`` (N, H, W, k C) uint8, whose newest frame is the target."""
        logits = self(memory_output).float()
        target = images[..., -logits.shape[-1] :].float() / 255.0
        return F.binary_cross_entropy_with_logits(logits, target)


# The one registry of image encoders: name -> class taking the (H, W, C) image shape, with ``output_size``.
IMAGE_ENCODERS: dict[str, Callable[[tuple[int, int, int]], nn.Module]] = {"nature_cnn": NatureCNN}


def mlp(input_size: int, sizes: Sequence[int]) -> nn.Sequential:
    """Linear + ReLU layers of ``sizes`` (orthogonal init, gain sqrt(2))."""
    layers: list[nn.Module] = []
    for size in sizes:
        layers += [orthogonal(nn.Linear(input_size, size), HIDDEN_GAIN), nn.ReLU()]
        input_size = size
    return nn.Sequential(*layers)


class ActorCritic(nn.Module):
    """Shared trunk (encoders, memory, body) with separate policy and value streams."""

    def __init__(
        self,
        observation_space: gym.Space,
        action_space: gym.Space,
        config: ModelConfig,
        helm_size: int = 0,
        reconstruction: bool = False,
        ground_truth_size: int = 0,
        observations_named: str = "",
    ) -> None:
        """``helm_size``: width of the HELM branch's output (0: no branch); the branch itself is frozen and lives
        with the actor, which caches its outputs as the ``helm`` input. ``reconstruction``: add the observation
        decoder (``ppo.reconstruction_coef`` > 0), trained only through its loss. ``ground_truth_size``: add the
        ground-truth estimator (``ppo.ground_truth_coef`` > 0) for targets of that size, trained only through its
        loss (0: none). ``observations_named``: how an error names the observations (the environment's own space,
        which a gymnasium environment translates into ``observation_space``); default: ``observation_space``."""
        super().__init__()
        self.action_dims = action_branches(action_space)
        self.inputs = model_inputs(observation_space, action_space, config, helm_size)
        image = self.inputs.get("image")
        named = observations_named or str(observation_space)
        if config.encoder == "mlp":
            if image is not None:
                raise ValueError(
                    f"model.encoder=mlp takes observations without an image, but {named} has one: "
                    f"use an image encoder ({', '.join(IMAGE_ENCODERS)})"
                )
            self.image_encoder = None
            vector_sizes = list(config.mlp_sizes)
        else:
            if image is None:
                raise ValueError(
                    f"model.encoder={config.encoder} needs an image observation, but {named} has none: "
                    "set model.encoder: mlp (its layers: model.mlp_sizes)"
                )
            self.image_encoder = IMAGE_ENCODERS[config.encoder](image.shape)  # type: ignore[arg-type]
            vector_sizes = [config.vector_encoder_size]
        if (helm_size or reconstruction) and image is None:
            raise ValueError(f"the HELM branch and the reconstruction loss need an image; {named} has none")
        vector_size = self.inputs["vector"].shape[0] if "vector" in self.inputs else 0
        vector_size += sum(self.action_dims) if config.previous_action else 0
        vector_size += 1 if config.previous_reward else 0
        self.vector_encoder = None
        feature_size = helm_size + (0 if self.image_encoder is None else self.image_encoder.output_size)
        if vector_size:
            self.vector_encoder = mlp(vector_size, vector_sizes)
            feature_size += vector_sizes[-1]
        self.memory = build_memory(config, feature_size)
        hidden = config.hidden_size
        self.body = nn.Sequential(orthogonal(nn.Linear(self.memory.output_size, hidden), HIDDEN_GAIN), nn.ReLU())
        self.policy_stream = nn.Sequential(orthogonal(nn.Linear(hidden, hidden), HIDDEN_GAIN), nn.ReLU())
        self.value_stream = nn.Sequential(orthogonal(nn.Linear(hidden, hidden), HIDDEN_GAIN), nn.ReLU())
        self.policy_heads = nn.ModuleList(orthogonal(nn.Linear(hidden, n), POLICY_GAIN) for n in self.action_dims)
        self.value_head = orthogonal(nn.Linear(hidden, 1), VALUE_GAIN)
        self.decoder = None
        if reconstruction:
            frame_shape = observation_fields(observation_space, config.grayscale)["image"].shape
            self.decoder = ObservationDecoder(self.memory.output_size, frame_shape)  # type: ignore[arg-type]
        self.ground_truth_size = ground_truth_size
        self.ground_truth_head = None
        if ground_truth_size:  # the JMLR endless TrXL's auxiliary head: memory output -> hidden -> the targets
            self.ground_truth_head = nn.Sequential(
                orthogonal(nn.Linear(self.memory.output_size, hidden), HIDDEN_GAIN),
                nn.ReLU(),
                orthogonal(nn.Linear(hidden, ground_truth_size), 1.0),
            )
        # changes of the weights (agents.policy.actor.refresh_copy): older acting caches are stale
        self.weights_generation = 0

    @property
    def state_shape(self) -> tuple[int, ...]:
        return self.memory.state_shape

    @property
    def record_shape(self) -> tuple[int, ...]:
        return self.memory.record_shape

    def initial_state(self, batch: int, device: torch.device | str) -> Tensor:
        """The memory state at the start of an episode (zeros), for ``batch`` environments."""
        return self.memory.initial_state(batch, device)

    def encode(self, inputs: dict[str, Tensor]) -> Tensor:
        """Features (N, F) of a flat batch of steps."""
        features = [] if self.image_encoder is None else [self.image_encoder(inputs["image"])]
        if "helm" in inputs:
            features.append(inputs["helm"].to(features[0].dtype))
        if self.vector_encoder is not None:
            dtype = compute_dtype(self.vector_encoder[0].weight)
            vector = []
            if "vector" in inputs:
                vector.append(inputs["vector"].to(dtype))
            if "previous_action" in inputs:
                vector.append(one_hot_actions(inputs["previous_action"], self.action_dims).to(dtype))
            if "previous_reward" in inputs:
                vector.append(inputs["previous_reward"].unsqueeze(-1).to(dtype))
            features.append(self.vector_encoder(torch.cat(vector, dim=-1)))
        return torch.cat(features, dim=-1) if len(features) > 1 else features[0]

    def heads(self, memory_output: Tensor) -> tuple[list[Tensor], Tensor]:
        """Logits of every action branch (float32) and the value (N,) of a flat batch."""
        hidden = self.body(memory_output)
        policy, value = self.policy_stream(hidden), self.value_stream(hidden)
        logits = [head(policy).float() for head in self.policy_heads]
        return logits, self.value_head(value).squeeze(-1).float()

    def step(
        self, inputs: dict[str, Tensor], state: Tensor, episode_step: Tensor | None = None, cache: Any = None
    ) -> tuple[list[Tensor], Tensor, Tensor]:
        """Rollout: one step of B environments (``episode_step`` (B,): decisions since each one's episode start;
        ``cache``: the memory's acting cache of ``state``, :meth:`agents.memory.base.Memory.acting_cache`, which the
        step advances). Returns logits, values (B,) and the next memory state."""
        features = self.encode(inputs)
        if cache is None:  # memories without an acting cache take no such argument
            output, next_state = self.memory.step(features, state, episode_step)
        else:
            output, next_state = self.memory.step(features, state, episode_step, cache)
        logits, values = self.heads(output)
        return logits, values, next_state

    def evaluate(
        self,
        inputs: dict[str, Tensor],
        records: Tensor,
        mask: Tensor,
        episode_step: Tensor | None = None,
        reconstruct: bool = False,
        ground_truth: Tensor | None = None,
    ) -> tuple[list[Tensor], Tensor, dict[str, Tensor]]:
        """Training: the N real steps of S sequences (flat, in sequence order), the memory records the buffer
        gathered for them (:meth:`agents.training.buffer.RolloutBuffer.memory_records`: a recurrent memory's start
        states (S, ...)), their padding mask (S, P) and each step's ``episode_step`` (N,). Returns logits and values of
        the N steps and the auxiliary losses asked for, by their logged names: with ``reconstruct`` the
        observation-reconstruction loss of those steps (``reconstruction_loss``), with ``ground_truth`` (N, G), the
        targets of those steps, the ground-truth estimator's mean squared error (``ground_truth_loss``).

        ``inputs`` may hold filler rows after the N real ones (see :func:`agents.training.ppo.filled_index`): they pass
        through the layers that act on single steps, so those keep a few fixed shapes, but they never enter the
        memory and are dropped from the outputs, so they change no output and no gradient."""
        features = self.encode(inputs)
        real_steps = int(mask.sum())
        output = self.memory.sequences(features[:real_steps], records, mask, episode_step)
        if features.shape[0] > real_steps:
            output = torch.cat((output, output.new_zeros(features.shape[0] - real_steps, *output.shape[1:])))
        logits, values = self.heads(output)
        logits, values = [branch[:real_steps] for branch in logits], values[:real_steps]
        auxiliary: dict[str, Tensor] = {}
        if reconstruct:  # the observation-reconstruction loss of the real steps (a model with a decoder)
            assert self.decoder is not None, "reconstruct needs a model built with reconstruction=True"
            auxiliary["reconstruction_loss"] = self.decoder.loss(output[:real_steps], inputs["image"][:real_steps])
        if ground_truth is not None:  # the ground-truth estimator's error on the real steps
            assert self.ground_truth_head is not None, "ground_truth needs a model built with ground_truth_size > 0"
            estimate = self.ground_truth_head(output[:real_steps]).float()
            auxiliary["ground_truth_loss"] = F.mse_loss(estimate, ground_truth.to(estimate.dtype))
        return logits, values, auxiliary


# --------------------------------------------------------------------------------------- action distribution
def one_hot_actions(actions: Tensor, action_dims: Sequence[int]) -> Tensor:
    """Actions (N, branches) as concatenated one-hots (N, sum(action_dims)); an action of -1 (none: the first step
    of an episode) is all zeros, as in the authors' code."""
    return torch.cat(
        [actions[:, i : i + 1] == torch.arange(n, device=actions.device) for i, n in enumerate(action_dims)], dim=-1
    )


def choose_actions(
    logits: Sequence[Tensor], generator: torch.Generator | None = None, greedy: bool = False
) -> tuple[Tensor, Tensor]:
    """One action per branch, sampled (or the most likely one with ``greedy``); returns actions (B, branches) int64
    and their log-probs (B, branches)."""
    actions, log_probs = [], []
    for branch_logits in logits:
        log_p = F.log_softmax(branch_logits, dim=-1)
        if greedy:
            action = log_p.argmax(dim=-1, keepdim=True)
        else:
            action = torch.multinomial(log_p.exp(), 1, generator=generator)
        actions.append(action)
        log_probs.append(log_p.gather(-1, action))
    return torch.cat(actions, dim=-1), torch.cat(log_probs, dim=-1)


def log_probs_and_entropy(logits: Sequence[Tensor], actions: Tensor) -> tuple[Tensor, Tensor]:
    """Log-probs (N, branches) of ``actions`` and the entropy (N,) summed over branches."""
    log_probs, entropy = [], 0.0
    for i, branch_logits in enumerate(logits):
        log_p = F.log_softmax(branch_logits, dim=-1)
        log_probs.append(log_p.gather(-1, actions[:, i : i + 1]))
        entropy = entropy - (log_p.exp() * log_p).sum(-1)
    return torch.cat(log_probs, dim=-1), entropy  # type: ignore[return-value]
