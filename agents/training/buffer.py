"""Rollout storage: one tensor per field, shaped (workers, steps, ...), on the training device.

Step t of worker w holds what the policy saw and did there: its inputs (observation, previous action/reward, the
HELM branch's cached output), the memory's record of that step (:mod:`agents.memory`: for a recurrent memory the
state fed *into* that step, the start state of any sequence beginning there; for a transformer the step's layer
inputs), the sampled actions with their log-probs, the value estimate, the reward received and whether the action
ended the episode, and with an auxiliary ground-truth loss the environment's ground truth at that step. A memory
with a ``history`` of h records also has the h records its slots carried into the rollout before step 0
(:meth:`RolloutBuffer.begin`), and :meth:`RolloutBuffer.memory_records` gives each sequence of a minibatch the h
records before its start and its own, (S, h + P, ...): one copy per sequence, none per step.

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

from agents.policy.models import InputField, join_frames

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
        memory_history: int | None = None,
        record_dtype: torch.dtype = torch.float32,
        ground_truth_size: int = 0,
    ) -> None:
        """``inputs``: the model's inputs (stacked shapes); ``state_shape``: the shape of the memory's per-step record
        (a recurrent memory's state); ``frame_stack``: k, the observations per stack; ``memory_history``,
        ``record_dtype``: the memory's ``history`` and the dtype of its records; ``ground_truth_size``: G, the size
        of each step's ground-truth target (``ground_truth``, (workers, steps, G) float32; None when 0)."""
        self.workers, self.steps, self.device = workers, steps, torch.device(device)
        self.frame_stack = k = frame_stack
        self.memory_history = memory_history

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
        # The memory's records (named for the recurrent memories' start states), after its history if it has one.
        self.memory_states = zeros(*state_shape, dtype=record_dtype, history=memory_history or 0)
        self.actions = zeros(branches, dtype=torch.int64)
        self.log_probs = zeros(branches)
        self.values = zeros()
        self.rewards = zeros()
        self.terminated = zeros(dtype=torch.bool)
        self.advantages = zeros()
        self.returns = zeros()
        self.ground_truth = zeros(ground_truth_size) if ground_truth_size else None

    @property
    def size(self) -> int:
        return self.workers * self.steps

    @property
    def bytes_per_step(self) -> int:
        """Bytes of stored inputs per environment step (the observation history before the rollout and the episode
        positions included)."""
        total = sum(t.numel() * t.element_size() for t in (*self.inputs.values(), self.episode_step))
        return total // self.size

    @property
    def memory_bytes_per_step(self) -> int:
        """Bytes of the memory's records per environment step (its history before the rollout included)."""
        return self.memory_states.numel() * self.memory_states.element_size() // self.size

    def begin(self, stacks: Mapping[str, Tensor], memory_history: Tensor | None = None) -> None:
        """Start a rollout from the policy's current frame stacks (name -> (workers, k, ...), oldest first): their
        k - 1 older observations become the history before step 0; likewise the memory's history records
        (workers, h, ...), when the memory has a history."""
        history = self.frame_stack - 1
        if history:
            for name, stack in stacks.items():
                self.inputs[name][:, :history] = stack[:, :history]
        if self.memory_history:
            if memory_history is None:
                raise ValueError("the memory has a history: begin() needs the records the slots carry in")
            self.memory_states[:, : self.memory_history] = memory_history

    def store_record(self, t: int, record: Tensor) -> None:
        """Step ``t``'s memory record (workers, ...)."""
        self.memory_states[:, t + (self.memory_history or 0)] = record

    def memory_records(self, start_index: Tensor, width: int) -> Tensor:
        """What the memory's training pass reads for sequences starting at the flat steps ``start_index`` (S,) and
        padded to ``width``: the record at each start (S, ...) without a history; with a history of h, the h records
        before each start and the ``width`` from it on, (S, h + width, ...) (rows past a worker's last step repeat
        it: they only ever sit under padding)."""
        if not self.memory_history:
            return self.flat(self.memory_states).index_select(0, start_index)
        h = self.memory_history
        row = h + self.steps
        worker, t = start_index // self.steps, start_index % self.steps
        offsets = torch.arange(h + width, device=start_index.device)
        positions = (t.unsqueeze(1) + offsets).clamp(max=row - 1)  # step t sits at t + h; its window from t on
        flat = self.memory_states.reshape(-1, *self.memory_states.shape[2:])
        rows = flat.index_select(0, (worker.unsqueeze(1) * row + positions).reshape(-1))
        return rows.reshape(start_index.shape[0], h + width, *rows.shape[1:])

    def store(self, t: int, newest: Mapping[str, Tensor], episode_step: Tensor) -> None:
        """Step ``t``'s per-step inputs (the newest observation for stacked fields) and episode position."""
        history = self.frame_stack - 1
        for name, value in newest.items():
            self.inputs[name][:, t + (history if name in STACKED else 0)] = value
        self.episode_step[:, t] = episode_step

    def flat(self, tensor: Tensor) -> Tensor:
        """A (workers * steps, ...) view, indexed by the flat step numbers of :mod:`agents.training.sequences`."""
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
