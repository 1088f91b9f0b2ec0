"""The one acting loop: a batched environment core driven by a policy. Training and evaluation both act through it.

An :class:`Actor` owns the core, the acting copy of the model, the optional frozen HELM branch and, per environment
slot, everything the policy carries from one decision to the next (:class:`SlotMemory`): the memory module's state,
the previous action and reward, the last k observations of a frame stack, the HELM branch's memory and the episode's
seed and actions (enough to rebuild the slot on resume). One decision is :meth:`Actor.decide` (the policy's forward
pass on the current inputs, actions sampled or argmax) then :meth:`Actor.advance` (the environment steps, with the
action repeated ``env.frame_skip`` times, and the slot memory moves on; a slot whose episode ended starts a new one
with the next seed, or stops when there is none).

Slot memory at an episode start: memory state zeros, previous action "none" (-1: an all-zero one-hot), previous
reward 0, the frame stack filled with copies of the first observation, the HELM memory empty.
"""

from __future__ import annotations

import copy
import hashlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from torch import Tensor

from agents.config import Config
from agents.policy.models import OBSERVATION_KEYS, ActorCritic, choose_actions, join_frames, observation_fields
from envs.core import BatchedCore

SeedSource = Callable[[int], list[int]]  # how many seeds -> that many episode seeds


def rollout_copy(model: ActorCritic, precision: str) -> ActorCritic:
    """The model that acts. With bf16 it is a bfloat16 copy of the weights (acting at one step per slot is bound by
    reading the weights, and autocast would cast them anew at every step); :func:`refresh_copy` updates it after
    each update. With fp32 it is the model itself."""
    if precision != "bf16":
        return model
    return copy.deepcopy(model).to(torch.bfloat16).requires_grad_(False)


def refresh_copy(acting: ActorCritic, model: ActorCritic) -> None:
    """Called after every change of the model's weights (an update, a checkpoint load): copies them into a bf16
    acting copy, and marks the memory's acting caches built from the old ones stale (``weights_generation``)."""
    acting.weights_generation += 1
    if acting is not model:
        with torch.no_grad():
            for low, weight in zip(acting.parameters(), model.parameters(), strict=True):
                low.copy_(weight)


def grayscale(images: np.ndarray) -> np.ndarray:
    """RGB uint8 (..., 3) -> luma uint8 (..., 1) with the ITU-R 601 weights 0.299, 0.587, 0.114 in OpenCV's 14-bit
    fixed-point arithmetic (what ``cv2.cvtColor(RGB2GRAY)`` returns, used by the frame-stacking baseline)."""
    weights = np.array([4899, 9617, 1868], dtype=np.uint32)
    luma = (images.astype(np.uint32) @ weights + (1 << 13)) >> 14
    return luma.astype(np.uint8)[..., None]


@dataclass
class Decision:
    """One decision of every slot: what the policy saw and did (what the rollout buffer stores)."""

    inputs: dict[str, Tensor]  # the model's inputs (stacked observations)
    newest: dict[str, Tensor]  # the per-step fields to store: newest frame/vector, previous action/reward, helm
    episode_step: Tensor  # (B,) decisions since each slot's episode start
    record: Tensor  # what the buffer keeps of the memory at this step (the state fed in, for a recurrent memory)
    actions: Tensor  # (B, branches) int64
    log_probs: Tensor  # (B, branches)
    values: Tensor  # (B,)
    next_state: Tensor
    ground_truth: Tensor | None = None  # (B, G) float32: the environment's info["ground_truth"] of these inputs


@dataclass
class Outcome:
    """What the environment answered: summed rewards, episode ends, and the final infos of ended episodes."""

    rewards: Tensor  # (B,) float32
    terminated: Tensor  # (B,) bool
    finals: dict[int, dict[str, Any]]  # slot -> final info (reward, length and the env's own metrics)


@dataclass
class SlotMemory:
    """What each slot carries between decisions besides the environment itself."""

    recurrent: Tensor  # (B, *state_shape): the memory module's state
    previous_action: Tensor  # (B, branches) int64, -1 at an episode start
    previous_reward: Tensor  # (B,) float32
    episode_step: Tensor  # (B,) int64
    stacks: dict[str, Tensor]  # observation name -> (B, k, ...) the last k observations, oldest first
    helm: Any = None  # the HELM branch's memory (agents.policy.helm), when there is a branch
    seeds: list[int] = field(default_factory=list)
    actions: list[list[np.ndarray]] = field(default_factory=list)  # decisions of each slot's current episode


class Actor:
    """A batched core and a policy acting in it (see the module docstring)."""

    def __init__(
        self,
        core: BatchedCore,
        model: ActorCritic,
        config: Config,
        generator: torch.Generator,
        helm: Any = None,
        device: torch.device | str = "cpu",
        ground_truth: bool = False,
    ) -> None:
        """``ground_truth``: every decision also carries the environment's ``info['ground_truth']`` of its inputs
        (the targets of ``ppo.ground_truth_coef``, which training needs and evaluation does not)."""
        self.core, self.model, self.config = core, model, config
        self.ground_truth = ground_truth
        self.generator, self.helm, self.device = generator, helm, torch.device(device)
        self.num_envs = core.num_envs
        self.frame_skip = config.env.frame_skip
        self.discrete = isinstance(core.single_action_space, gym.spaces.Discrete)
        self.fields = observation_fields(core.single_observation_space, config.model.grayscale)
        self.stack = config.model.frame_stack
        self.active = np.ones(self.num_envs, dtype=bool)  # slots still playing (evaluation stops finished ones)
        self.seed_source: SeedSource | None = None
        self.memory = self._empty_memory()
        # The memory's acting cache (Memory.acting_cache), the state it matches and the weights_generation it was
        # built with; derived from the state, so never checkpointed.
        self._acting_cache: tuple[Any, Tensor | None, int] = (None, None, -1)
        self.helm_features = None if helm is None else torch.zeros((self.num_envs, helm.output_size), device=device)

    # ------------------------------------------------------------------------------------------------- episodes
    def start(self, seeds: Sequence[int], seed_source: SeedSource | None = None) -> None:
        """New episodes in every slot with ``seeds`` (one per slot). ``seed_source`` gives the seeds of the episodes
        that follow; without one, a slot stops when its episode ends (see :attr:`active`)."""
        if len(seeds) != self.num_envs:
            raise ValueError(f"got {len(seeds)} seeds for {self.num_envs} slots")
        self.seed_source = seed_source
        self.active[:] = True
        self._reset(np.arange(self.num_envs), [int(s) for s in seeds])

    def decide(self, greedy: bool = False) -> Decision:
        """The policy's decision for every active slot on the current inputs (sampled, or argmax with ``greedy``);
        a stopped slot (evaluation) costs nothing, keeps its memory state and gets action 0."""
        inputs = self.inputs()
        state, episode_step = self.memory.recurrent, self.memory.episode_step
        with torch.inference_mode():
            if self.active.all():
                cache = self._cache(state, episode_step)
                logits, values, next_state = self.model.step(inputs, state, episode_step, cache)
                self._acting_cache = (cache, next_state, self.model.weights_generation)  # the step advanced it
                actions, log_probs = choose_actions(logits, self.generator, greedy)
            else:
                self._acting_cache = (None, None, -1)  # the stopped slots do not step: built anew when all do
                rows = torch.from_numpy(np.flatnonzero(self.active)).to(self.device)
                some = {name: tensor.index_select(0, rows) for name, tensor in inputs.items()}
                logits, some_values, some_state = self.model.step(
                    some, state.index_select(0, rows), episode_step.index_select(0, rows)
                )
                some_actions, some_log_probs = choose_actions(logits, self.generator, greedy)
                actions = some_actions.new_zeros((self.num_envs, some_actions.shape[1])).index_copy(
                    0, rows, some_actions
                )
                log_probs = some_log_probs.new_zeros(actions.shape).index_copy(0, rows, some_log_probs)
                values = some_values.new_zeros(self.num_envs).index_copy(0, rows, some_values)
                next_state = state.to(some_state.dtype).index_copy(0, rows, some_state)
        newest = {name: stack[:, -1] for name, stack in self.memory.stacks.items()}
        for name in ("previous_action", "previous_reward", "helm"):
            if name in inputs:
                newest[name] = inputs[name]
        record = self.model.memory.record(state, next_state)
        ground_truth = None
        if self.ground_truth:  # the targets of the auxiliary loss: what the environment is at these inputs
            truth = self.core.step_infos()["ground_truth"]
            ground_truth = torch.from_numpy(np.asarray(truth, dtype=np.float32)).to(self.device)
        return Decision(
            inputs, newest, episode_step.clone(), record, actions, log_probs, values, next_state, ground_truth
        )  # fmt: skip

    def advance(self, decision: Decision) -> Outcome:
        """Step the active slots with the decision's actions and move every slot's memory on."""
        actions = decision.actions.cpu().numpy()
        slots = np.flatnonzero(self.active)
        rewards, terminated, finals = self._env_step(actions, slots)
        memory = self.memory
        for k in slots.tolist():
            memory.actions[k].append(actions[k])
        rewards_t = torch.from_numpy(rewards).to(self.device)
        terminated_t = torch.from_numpy(terminated).to(self.device)
        alive = ~terminated_t
        next_state = decision.next_state.to(self.model.memory.state_dtype)  # a bf16 acting copy keeps its state dtype
        if terminated.any():  # zeroed in place, row by row: a window memory's state is megabytes, a copy per end costs
            with torch.inference_mode():  # the state came out of inference mode (an inference tensor)
                next_state[terminated_t] = 0.0
        memory.recurrent = next_state
        cache, matched, generation = self._acting_cache
        if matched is decision.next_state:  # the same state but for the slots cleared to an episode start
            self._acting_cache = (cache, memory.recurrent, generation)
        memory.previous_action = torch.where(alive.unsqueeze(-1), decision.actions, -1)
        memory.previous_reward = rewards_t * alive
        memory.episode_step = (memory.episode_step + 1) * alive
        ended = np.flatnonzero(terminated)
        if ended.size and self.seed_source is not None:
            self._reset(ended, self.seed_source(ended.size), observe_others=True)
        else:
            self.active[ended] = False
            self._observe(np.flatnonzero(self.active & ~terminated), starts=np.zeros(0, dtype=np.int64))
        return Outcome(rewards_t, terminated_t, finals)

    def inputs(self) -> dict[str, Tensor]:
        """The model's inputs for the current step of every slot."""
        memory = self.memory
        inputs = {}
        for name, stack in memory.stacks.items():  # (B, k, ..., C) -> (B, ..., k C): the oldest frame first
            inputs[name] = join_frames(stack)
        model_inputs = self.model.inputs
        if "previous_action" in model_inputs:
            inputs["previous_action"] = memory.previous_action
        if "previous_reward" in model_inputs:
            inputs["previous_reward"] = memory.previous_reward
        if "helm" in model_inputs:
            inputs["helm"] = self.helm_features
        return inputs

    # ------------------------------------------------------------------------------------- resume and replay
    def state(self) -> dict[str, Any]:
        """What a checkpoint needs to rebuild every slot: seeds and actions of the current episodes (replayed on
        load, which rebuilds the environment, the frame stacks and the HELM memory), the states that depend on the
        weights at the time (memory state, previous action/reward) and a digest of the observations."""
        memory = self.memory
        return {
            "seeds": list(memory.seeds),
            "actions": [np.array(a) for a in memory.actions],
            "recurrent": memory.recurrent.clone(),
            "previous_action": memory.previous_action.clone(),
            "previous_reward": memory.previous_reward.clone(),
            "episode_step": memory.episode_step.clone(),
            "active": self.active.copy(),
            "observation_digest": self.observation_digest(),
        }

    def load_state(self, state: dict[str, Any], seed_source: SeedSource | None = None) -> None:
        """Rebuild every slot from :meth:`state`: reset with its seed and replay its actions. The replays end together
        (a slot with a shorter episode starts later), so every step of the HELM branch sees the whole batch as it did
        when the steps were first taken; the slots not started yet are cleared when they start.

        A core that is not ``replayable`` (a gymnasium environment's copies) cannot rebuild the episodes in progress:
        every slot starts a new episode with the next seeds of ``seed_source`` instead (deterministic, since the
        seed generator is restored first, but not what an uninterrupted run would have played)."""
        self.seed_source = seed_source
        seeds, actions = state["seeds"], state["actions"]
        self.active[:] = True
        if not self.core.replayable:  # the episodes in progress cannot be rebuilt: new ones, with the next seeds
            self._reset(np.arange(self.num_envs), seed_source(self.num_envs) if seed_source else seeds)
            return
        slots = np.arange(self.num_envs)
        self.core.reset_slots(slots, [int(s) for s in seeds])
        self._clear(slots, seeds)
        lengths = np.array([len(a) for a in actions], dtype=np.int64)
        begin = lengths.max(initial=0) - lengths  # the replay step at which each slot shows its first observation
        for j in range(int(lengths.max(initial=0)) + 1):
            stepping = np.flatnonzero(begin < j)
            if stepping.size:
                step_actions = np.zeros((self.num_envs, len(self.model.action_dims)), dtype=np.int64)
                step_actions[stepping] = np.stack([actions[k][j - begin[k] - 1] for k in stepping])
                _, terminated, _ = self._env_step(step_actions, stepping)
                if terminated.any():
                    raise RuntimeError(
                        "an episode ended during checkpoint replay: the environment is not deterministic"
                    )
            self._observe(np.flatnonzero(begin <= j), starts=np.flatnonzero(begin == j))
        memory = self.memory
        memory.actions = [list(a) for a in actions]
        memory.recurrent = state["recurrent"].to(self.device)
        memory.previous_action = state["previous_action"].to(self.device)
        memory.previous_reward = state["previous_reward"].to(self.device)
        memory.episode_step = state["episode_step"].to(self.device)
        self.active[:] = state["active"]
        if self.observation_digest() != state["observation_digest"]:
            raise RuntimeError(
                f"replaying the checkpoint's episodes did not reproduce the environment state: {self.config.env.id} "
                "is not deterministic given seed and actions, so the run cannot resume exactly"
            )

    def observation_digest(self) -> str:
        digest = hashlib.sha256()
        for name in sorted(self.memory.stacks):
            digest.update(self.memory.stacks[name][:, -1].cpu().numpy().tobytes())
        return digest.hexdigest()

    # ------------------------------------------------------------------------------------------------ internals
    def _cache(self, state: Tensor, episode_step: Tensor) -> Any:
        """The memory's acting cache of ``state``: the one the last decision advanced, if ``state`` is the one it
        led to and the weights are unchanged since (:func:`refresh_copy`), else a new one (None: the memory keeps
        none)."""
        cache, matched, generation = self._acting_cache
        if cache is None or matched is not state or generation != self.model.weights_generation:
            cache = self.model.memory.acting_cache(state, episode_step)
        return cache

    def _empty_memory(self) -> SlotMemory:
        n, k, device = self.num_envs, self.stack, self.device
        return SlotMemory(
            recurrent=self.model.initial_state(n, device),
            previous_action=torch.full((n, len(self.model.action_dims)), -1, dtype=torch.int64, device=device),
            previous_reward=torch.zeros(n, device=device),
            episode_step=torch.zeros(n, dtype=torch.int64, device=device),
            stacks={
                name: torch.zeros((n, k, *f.shape), dtype=f.dtype, device=device) for name, f in self.fields.items()
            },
            helm=None if self.helm is None else self.helm.initial_memory(n, device),
            seeds=[0] * n,
            actions=[[] for _ in range(n)],
        )

    def _reset(self, slots: np.ndarray, seeds: Sequence[int], observe_others: bool = False) -> None:
        """New episodes in ``slots``: the core's reset, fresh slot memory, then the first observation (of the other
        active slots too when ``observe_others``: the step that ended these episodes moved them on as well)."""
        self.core.reset_slots(slots, [int(s) for s in seeds])
        self._clear(slots, seeds)
        observed = np.flatnonzero(self.active) if observe_others else slots
        self._observe(observed, starts=slots)

    def _clear(self, slots: np.ndarray, seeds: Sequence[int]) -> None:
        """The slot memory of an episode start in ``slots`` (frame stacks and HELM memory start at the observation)."""
        memory = self.memory
        index = torch.from_numpy(slots).to(self.device)
        with torch.inference_mode():  # the state may be a step's output, an inference tensor
            memory.recurrent[index] = 0.0
        memory.previous_action[index] = -1
        memory.previous_reward[index] = 0.0
        memory.episode_step[index] = 0
        for k, seed in zip(slots.tolist(), seeds, strict=True):
            memory.seeds[k] = int(seed)
            memory.actions[k] = []

    def _observe(self, slots: np.ndarray, starts: np.ndarray) -> None:
        """Take the current observation of ``slots`` into their frame stacks (filled with it in ``starts``, the
        slots that begin an episode), and the current observation of every slot through the HELM branch (one call is
        one step of the whole batch: the branch's outputs for a slot do not depend on the others, and a slot that is
        not playing just fills a memory that is cleared when it starts again)."""
        if slots.size == 0:
            return
        every = slots.size == self.num_envs or self.helm is not None
        raw = self.core.observations(None if every else slots)
        arrays = raw if isinstance(raw, dict) else {"visual_observation": raw}
        if self.helm is not None:
            image = torch.from_numpy(np.ascontiguousarray(arrays["visual_observation"])).to(self.device)
            episode_start = torch.zeros(self.num_envs, dtype=torch.bool, device=self.device)
            episode_start[torch.from_numpy(starts).to(self.device)] = True
            self.helm_features = self.helm.step(image, self.memory.helm, episode_start)
            if slots.size != self.num_envs:
                arrays = {key: array[slots] for key, array in arrays.items()}
        every = slots.size == self.num_envs
        memory, device = self.memory, self.device
        index = torch.from_numpy(slots).to(device)
        is_start = np.isin(slots, starts)
        start_rows = torch.from_numpy(is_start).to(device)
        for key, array in arrays.items():
            name = OBSERVATION_KEYS[key]
            if name == "image" and self.config.model.grayscale:
                array = grayscale(array)
            new = torch.from_numpy(np.ascontiguousarray(array)).to(device).reshape(len(slots), *self.fields[name].shape)
            stack = memory.stacks[name]
            rows = stack if every else stack[index]
            if self.stack > 1:  # shift the window by one; a slot that starts an episode is filled with its first frame
                rows[:, :-1] = rows[:, 1:].clone()
                if is_start.any():
                    rows[start_rows] = new[start_rows].unsqueeze(1)
            rows[:, -1] = new
            if not every:
                stack[index] = rows

    def _env_step(self, actions: np.ndarray, slots: np.ndarray) -> tuple[np.ndarray, np.ndarray, dict[int, dict]]:
        """Step ``slots`` with their rows of ``actions`` (B, branches), each repeated ``frame_skip`` times (rewards
        summed; a slot whose episode ends stops repeating). Returns (B,) rewards and ends, and the final infos."""
        rewards = np.zeros(self.num_envs, dtype=np.float32)
        terminated = np.zeros(self.num_envs, dtype=bool)
        finals: dict[int, dict] = {}
        env_actions = actions[:, 0] if self.discrete else actions
        live = slots
        for _ in range(self.frame_skip):
            if live.size == 0:
                break
            every = live.size == self.num_envs
            step_rewards, ended, step_finals = self.core.step(env_actions[live], idx=None if every else live)
            rewards[live] += step_rewards
            terminated[live] = ended
            finals.update(step_finals)
            live = live[~ended]
        return rewards, terminated, finals
