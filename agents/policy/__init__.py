"""The policy room: the agent that acts, assembled from parts, and its saved form.

* :mod:`agents.policy.models`: the actor-critic (encoders -> memory -> body -> separate policy and value streams,
  one categorical head per action dimension), its inputs, the action distribution;
* :mod:`agents.policy.actor`: the one loop that steps environments for a policy (training and evaluation alike):
  slots reset with seeds, sampled or greedy actions, memory state, previous action/reward, frame stacks, HELM memory;
* :mod:`agents.policy.helm`: the HELM branch (frozen Hopfield retrieval into a frozen language model);
* :mod:`agents.policy.checkpoint`: building the acting parts from a config, checkpoints written atomically with a
  checksum, and a trained policy loaded back.

The policy stands on the runtime, the config and the memories; the analysis room is its sibling (neither imports the
other), and training and evaluation stand on both.
"""

from __future__ import annotations

from agents.policy.actor import Actor, Outcome, refresh_copy, rollout_copy
from agents.policy.checkpoint import (
    DamagedCheckpoint,
    Policy,
    build_agent,
    checkpoint_path,
    checkpoint_update,
    latest_checkpoint,
    list_checkpoints,
    load_policy,
    read_checkpoint,
    run_config,
    write_checkpoint,
)
from agents.policy.helm import HelmBranch
from agents.policy.models import (
    IMAGE_ENCODERS,
    ActorCritic,
    InputField,
    choose_actions,
    log_probs_and_entropy,
    model_inputs,
    observation_fields,
)

__all__ = [
    "IMAGE_ENCODERS",
    "Actor",
    "ActorCritic",
    "DamagedCheckpoint",
    "HelmBranch",
    "InputField",
    "Outcome",
    "Policy",
    "build_agent",
    "checkpoint_path",
    "checkpoint_update",
    "choose_actions",
    "latest_checkpoint",
    "list_checkpoints",
    "load_policy",
    "log_probs_and_entropy",
    "model_inputs",
    "observation_fields",
    "read_checkpoint",
    "rollout_copy",
    "refresh_copy",
    "run_config",
    "write_checkpoint",
]
