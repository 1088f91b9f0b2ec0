"""Rollout storage: one tensor per field, shaped (workers, steps, ...), on the training device.

Step t of worker w holds what the policy saw and did there: its inputs (observation, previous action/reward), the
memory state fed *into* that step (the start state of any sequence beginning there), the sampled actions with their
log-probs, the value estimate, the reward received and whether the action ended the episode.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import torch

from agents.models import InputField


class RolloutBuffer:
    def __init__(
        self,
        workers: int,
        steps: int,
        inputs: Mapping[str, InputField],
        branches: int,
        state_shape: tuple[int, ...],
        device: torch.device | str,
    ) -> None:
        self.workers, self.steps, self.device = workers, steps, torch.device(device)

        def zeros(*shape: int, dtype: torch.dtype = torch.float32) -> torch.Tensor:
            return torch.zeros((workers, steps, *shape), dtype=dtype, device=self.device)

        self.inputs = {name: zeros(*field.shape, dtype=field.dtype) for name, field in inputs.items()}
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

    def flat(self, tensor: torch.Tensor) -> torch.Tensor:
        """A (workers * steps, ...) view, indexed by the flat step numbers of :mod:`agents.sequences`."""
        return tensor.reshape(self.size, *tensor.shape[2:])

    def flat_inputs(self) -> dict[str, torch.Tensor]:
        return {name: self.flat(tensor) for name, tensor in self.inputs.items()}

    def terminated_numpy(self) -> np.ndarray:
        return self.terminated.cpu().numpy()
