"""Rollout storage: one tensor per field, shaped (workers, steps, ...), on the training device.

Step t of worker w holds what the policy saw and did there: its inputs (observation, previous action/reward, the
HELM branch's cached output), the memory state fed *into* that step (the start state of any sequence beginning
there), the sampled actions with their log-probs, the value estimate, the reward received and whether the action
ended the episode.

Frame stacks are not stored k times. The observation fields (``image``, ``vector``) keep one observation per step,
after ``k - 1`` observations from before the rollout (what the policy's stack held at its start), and each step
keeps how many decisions its episode had taken (``episode_step``). :meth:`RolloutBuffer.gather` rebuilds the stack
of any step from those: frame j of step t is step ``t - (k - 1 - j)``, but never one from before its episode's first
step (an episode's stack starts filled with its first frame), which is exactly the stack the policy saw.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import torch
from torch import Tensor

from agents.models import InputField, join_frames

STACKED = ("image", "vector")  # the observation fields, stacked along their last (channel) axis


class RolloutBuffer:
    def __init__(
        self,
        workers: int,
        steps: int,
        inputs: Mapping[str, InputField],
        branches: int,
        state_shape: tuple[int, ...],
        device: torch.device | str,
        frame_stack: int = 1,
    ) -> None:
        """``inputs``: the model's inputs (stacked shapes); ``frame_stack``: k, the observations per stack."""
        self.workers, self.steps, self.device = workers, steps, torch.device(device)
        self.frame_stack = k = frame_stack

        def zeros(*shape: int, dtype: torch.dtype = torch.float32, history: int = 0) -> Tensor:
            return torch.zeros((workers, history + steps, *shape), dtype=dtype, device=self.device)

        self.inputs: dict[str, Tensor] = {}
        for name, field in inputs.items():
            if name in STACKED:  # one observation per step (channels / k), plus the k - 1 before the rollout
                shape = (*field.shape[:-1], field.shape[-1] // k)
                self.inputs[name] = zeros(*shape, dtype=field.dtype, history=k - 1)
            else:
                self.inputs[name] = zeros(*field.shape, dtype=field.dtype)
        self.episode_step = zeros(dtype=torch.int64)
        self.memory_states = zeros(*state_shape)
        self.actions = zeros(branches, dtype=torch.int64)
        self.log_probs = zeros(branches)
        self.values = zeros()
        self.rewards = zeros()
        self.terminated = zeros(dtype=torch.bool)
        self.advantages = zeros()
        self.returns = zeros()

    @property
    def size(self) -> int:
        return self.workers * self.steps

    @property
    def bytes_per_step(self) -> int:
        """Bytes of stored inputs per environment step (the observation history before the rollout and the episode
        positions included)."""
        total = sum(t.numel() * t.element_size() for t in (*self.inputs.values(), self.episode_step))
        return total // self.size

    def begin(self, stacks: Mapping[str, Tensor]) -> None:
        """Start a rollout from the policy's current frame stacks (name -> (workers, k, ...), oldest first): their
        k - 1 older observations become the history before step 0."""
        history = self.frame_stack - 1
        if history:
            for name, stack in stacks.items():
                self.inputs[name][:, :history] = stack[:, :history]

    def store(self, t: int, newest: Mapping[str, Tensor], episode_step: Tensor) -> None:
        """Step ``t``'s per-step inputs (the newest observation for stacked fields) and episode position."""
        history = self.frame_stack - 1
        for name, value in newest.items():
            self.inputs[name][:, t + (history if name in STACKED else 0)] = value
        self.episode_step[:, t] = episode_step

    def flat(self, tensor: Tensor) -> Tensor:
        """A (workers * steps, ...) view, indexed by the flat step numbers of :mod:`agents.sequences`."""
        return tensor.reshape(self.size, *tensor.shape[2:])

    def gather(self, index: Tensor) -> dict[str, Tensor]:
        """The model's inputs of the flat steps ``index`` (N,), with every frame stack rebuilt."""
        gathered = {}
        k = self.frame_stack
        if k > 1:
            worker, t = index // self.steps, index % self.steps
            back = torch.arange(k - 1, -1, -1, device=index.device)  # frame j of a stack is `back[j]` steps earlier
            first = (t - self.flat(self.episode_step).index_select(0, index)).unsqueeze(1)  # the episode's first step
            source = torch.maximum(t.unsqueeze(1) - back, first) + (k - 1)  # (N, k) positions in the stored rows
            stacked_index = (worker.unsqueeze(1) * (self.steps + k - 1) + source).reshape(-1)
        for name, tensor in self.inputs.items():
            if name in STACKED and k > 1:
                rows = tensor.reshape(-1, *tensor.shape[2:]).index_select(0, stacked_index)
                gathered[name] = join_frames(rows.reshape(index.shape[0], k, *rows.shape[1:]))
            else:
                gathered[name] = self.flat(tensor).index_select(0, index)
        return gathered

    def terminated_numpy(self) -> np.ndarray:
        return self.terminated.cpu().numpy()
