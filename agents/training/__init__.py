"""The training room: PPO on one config into one run directory, resumable exactly.

* :mod:`agents.training.buffer`: rollout storage (inputs, actions, rewards, memory records, frame-stack history);
* :mod:`agents.training.sequences`: episodes split into sequences, zero-padded to the longest present, masks,
minibatches;
* :mod:`agents.training.ppo`: GAE, the clipped surrogate, value loss and entropy averaged over real steps only;
* :mod:`agents.training.trainer`: :class:`Trainer`, collect -> GAE -> minibatch epochs -> log -> evaluate -> checkpoint,
  and its resume;
* :mod:`agents.training.logs`: what a run writes beside its checkpoints (``training.csv``, ``run_info.json``,
  TensorBoard scalars) and what a resume checks of it.

It stands on evaluation (the in-training evaluation), the policy, the analysis (metrics, digests) and the runtime;
the experiments train through it.
"""

from __future__ import annotations

from agents.training.buffer import RolloutBuffer
from agents.training.logs import TrainingLog, default_run_dir, extend_run, run_info, run_records
from agents.training.ppo import gae_advantages, ppo_loss, ppo_update
from agents.training.sequences import Sequences, minibatch_ids, pad_sequences, split_sequences
from agents.training.trainer import Trainer, TrainingDiverged, WriteFailed

__all__ = [
    "RolloutBuffer",
    "Sequences",
    "Trainer",
    "TrainingDiverged",
    "TrainingLog",
    "WriteFailed",
    "default_run_dir",
    "extend_run",
    "gae_advantages",
    "minibatch_ids",
    "pad_sequences",
    "ppo_loss",
    "ppo_update",
    "run_info",
    "run_records",
    "split_sequences",
]
