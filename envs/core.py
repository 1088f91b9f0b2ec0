"""The natively batched environment core and its two gymnasium faces.

A family (Mortar Mayhem, Mystery Path, ...) subclasses :class:`BatchedCore`. Its state lives in numpy arrays with a
leading ``num_envs`` axis, and :meth:`BatchedCore.step` advances many slots with array operations. Only the reset
of a slot runs per slot, in plain Python, because level generation must follow the reference's RNG call order:
each slot owns a ``numpy.random.Generator(PCG64(SeedSequence(seed)))``, so slot k reset with seed s produces the
same level as a single environment reset with seed s.

Two faces wrap one core: :class:`MemoryGymEnv` (``gymnasium.make``, one slot) and :class:`MemoryGymVectorEnv`
(``gymnasium.make_vec``, N slots, explicit autoreset mode). The trainer drives a core directly. Cores draw
(row, column, channel) images; a face made with ``layout="memory-gym"`` returns them transposed, as memory-gym's
(x, y, channel) arrays (:data:`OBSERVATION_LAYOUTS`).

What a family implements (``idx`` is ``slice(None)`` for all slots or an int array of slot indices):

* ``option_specs`` (dict of :class:`~envs.options.Option`), ``single_observation_space``, ``single_action_space``;
* ``_reset_slot(k, rng, opts)``: build slot k's level with the reference's RNG calls and draw its first frame; or
  instead ``_reset_slots(slots, rngs, opts)``, which builds the levels of several slots at once (the RNG calls stay
  per slot and in order; array writes and first frames are shared). The default ``_reset_slots`` loops over
  ``_reset_slot``; :meth:`BatchedCore.reset_slots` is the entry point either way;
* ``_step(idx, actions) -> (rewards, terminated)``: advance the slots ``idx`` and draw their frames;
* ``_observation(idx)``: the observation arrays of the slots (views are fine, the faces copy);
* ``_final_info(k)``: the family's episode statistics (``reward`` and ``length`` are added here), or
  ``_final_infos(slots)`` for several finished slots at once (by default a loop over ``_final_info``); keys that the
  reference does not report are listed in ``added_info_keys``;
* ``_max_episode_steps(opts)``: the reference's ``max_episode_steps`` for those options (-1, the default here, means
  no limit is known, as the reference reports for its endless envs);
* optionally ``_step_info(k)`` (endless envs: ``ground_truth``), ``_debug_frame(k)`` and ``render_fps(k)``.

Every face goes through :meth:`BatchedCore.step`, which refuses what a family must never see, before it changes any
state: a step of a slot that has no episode (never reset, or its last reset failed) raises
``gymnasium.error.ResetNeeded``, and actions outside the action space raise ``ValueError`` naming the slot, the action
and the space. Actions are integer arrays, one row per stepped slot (``(n,)`` for ``Discrete``, ``(n, branches)``
for ``MultiDiscrete``; ``Discrete`` also takes ``(n, 1)``, the one-element rows that clients written for memory-gym
send, as they treat every action space as multi-discrete); floats are refused, integer-valued ones too (a float action
is almost always a bug, such as passing probabilities; gymnasium's ``Discrete.contains`` refuses floats as well):
cast with ``astype(int)``.
"""

from __future__ import annotations

import importlib
import os
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium.error import ResetNeeded
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

from envs.options import Option, check_mapping, resolve_options
from envs.rng import seeded_generator, seeded_generators

__all__ = [
    "BatchedCore",
    "Index",
    "MemoryGymEnv",
    "MemoryGymVectorEnv",
    "OBSERVATION_LAYOUTS",
    "layout_observation_space",
    "load_core",
    "seeded_generator",
]

Index = slice | np.ndarray
_SEED_TYPES = (int, np.integer)
_UNSIGNED = {1: np.uint8, 2: np.uint16, 4: np.uint32, 8: np.uint64}  # integer itemsize -> unsigned of that size
_FEW_ACTIONS = 8  # up to this many entries, actions are checked as Python ints (cheaper than numpy calls)
RENDER_MODES = ["rgb_array", "debug_rgb_array", "human"]
# The faces' observation layouts: "rows" (the default), (row, column, channel) images as render() shows them; or
# "memory-gym", their transpose, the (x, y, channel) arrays memory-gym returns (what a policy trained on it expects).
OBSERVATION_LAYOUTS = ("rows", "memory-gym")
DEBUG_SCALE = 4  # the debug picture is the 84x84 ground truth drawing upscaled 4x (336x336)


class BatchedCore:
    """State and mechanics of ``num_envs`` independent episodes of one environment family."""

    env_name: ClassVar[str] = ""
    option_specs: dict[str, Option]
    single_observation_space: gym.Space
    single_action_space: gym.Space
    has_ground_truth_info: ClassVar[bool] = False
    # Final-info keys that memory-gym 1.0.2 does not report (added for the evaluation): tools comparing infos with the
    # reference (the parity replays) drop them.
    added_info_keys: ClassVar[frozenset[str]] = frozenset()
    ground_truth_space: gym.Space | None = None
    base_render_fps: ClassVar[int] = 25
    # memory-gym draws some frames from what an instance's previous episode left behind (Mortar Mayhem's last agent
    # sprite). Off: an episode depends only on its seed and options, whatever the slot played before. The parity
    # replays turn it on (``core.reference_carryover = True``) to reproduce traces recorded on reused instances.
    reference_carryover: bool = False
    # Whether a slot's state is rebuilt by resetting it with its seed and replaying its actions (what a checkpoint
    # stores). A gymnasium environment's copies (envs.gymnasium_core) cannot promise it.
    replayable: ClassVar[bool] = True

    def __init__(self, num_envs: int = 1, options: Mapping[str, Any] | None = None) -> None:
        if not isinstance(num_envs, int | np.integer) or num_envs < 1:
            raise ValueError(f"num_envs={num_envs!r} is invalid: expected an int >= 1")
        self.num_envs = int(num_envs)
        # Options given at construction become this instance's defaults; reset options apply to the episodes that
        # reset starts (and, through ``restart_slots``, to the slots' later episodes).
        self.base_options = resolve_options(self.option_specs, options, name=self.env_name)
        self.rngs: list[np.random.Generator | None] = [None] * self.num_envs
        self.seeds: list[int | None] = [None] * self.num_envs
        # The options of each slot's current episode: one shared (read-only) dict per reset call, so that
        # ``restart_slots`` can group the slots by identity.
        self.slot_options: list[dict[str, Any]] = [self.base_options] * self.num_envs
        # memory-gym's ``max_episode_steps`` of each slot's current episode (0 until the slot's first reset)
        self.max_episode_steps = np.zeros(self.num_envs, dtype=np.int64)
        self.episode_return = np.zeros(self.num_envs, dtype=np.float64)
        self.episode_length = np.zeros(self.num_envs, dtype=np.int64)
        self.unready: set[int] = set(range(self.num_envs))  # slots without an episode: never reset, or reset failed
        self._action_bounds: tuple | None = None  # see ``check_actions``

    # ----------------------------------------------------------------------------------------------- slot API
    def resolve(self, options: Mapping[str, Any] | None) -> dict[str, Any]:
        """Validate ``options`` and merge them over this instance's defaults."""
        return resolve_options(self.option_specs, options, base=self.base_options, name=self.env_name)

    def reset_slot(self, k: int, seed: int | None = None, options: Mapping[str, Any] | None = None) -> None:
        """Start a new episode in slot ``k``. ``seed=None`` continues the slot's generator (OS entropy at first)."""
        self.reset_slots([k], [seed], options)

    def reset_slots(
        self,
        slots: Sequence[int] | np.ndarray,
        seeds: Sequence[int | None] | None = None,
        options: Mapping[str, Any] | None = None,
    ) -> None:
        """Start new episodes in several slots at once, with the same ``options``; ``seeds`` gives one seed (or
        ``None``) per slot. The result equals :meth:`reset_slot` on each slot in turn, but a family may build the
        levels together (its ``_reset_slots`` hook), which saves the per-slot overhead when many episodes end at once.
        """
        slots = _slot_list(slots)
        self.unready.update(slots)  # until the new episodes are built: a failed reset leaves no episode to step
        opts = self.resolve(options)  # validate before touching any other state
        seeds = [None] * len(slots) if seeds is None else list(seeds)
        if len(seeds) != len(slots):
            raise ValueError(f"got {len(seeds)} seeds for {len(slots)} slots")
        for seed in seeds:
            if seed is not None and (not isinstance(seed, _SEED_TYPES) or seed < 0):
                raise ValueError(f"seed={seed!r} is invalid: expected a non-negative int or None")
        self._start_episodes(slots, seeds, opts)

    def restart_slots(self, slots: Sequence[int] | np.ndarray) -> None:
        """New episodes in ``slots``, each with the options of its current episode (those of the slot's last reset
        call), continuing each slot's generator: the autoreset of the vector face."""
        slots = _slot_list(slots)
        groups: dict[int, tuple[dict[str, Any], list[int]]] = {}
        for k in slots:
            opts = self.slot_options[k]
            groups.setdefault(id(opts), (opts, []))[1].append(k)
        for opts, group in groups.values():
            self.unready.update(group)
            self._start_episodes(group, [None] * len(group), opts)

    def _start_episodes(self, slots: list[int], seeds: list[int | None], opts: dict[str, Any]) -> None:
        """Build the episodes of ``slots`` with resolved ``opts`` (seeds already validated)."""
        seeded = iter(seeded_generators([seed for seed in seeds if seed is not None]))
        rngs = []
        for k, seed in zip(slots, seeds, strict=True):
            if seed is not None:
                self.rngs[k] = next(seeded)
                self.seeds[k] = int(seed)
            elif self.rngs[k] is None:
                self.rngs[k] = np.random.default_rng()
            self.slot_options[k] = opts
            rngs.append(self.rngs[k])
        if slots:
            self.episode_return[slots] = 0.0
            self.episode_length[slots] = 0
            self.max_episode_steps[slots] = self._max_episode_steps(opts)
            self._reset_slots(slots, rngs, opts)
            self.unready.difference_update(slots)

    def step(
        self, actions: np.ndarray, idx: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray, dict[int, dict]]:
        """Advance slots ``idx`` (all when ``None``) by one step with ``actions`` (one row per stepped slot).

        Returns the rewards and terminated flags of the stepped slots and the final infos of the slots whose episode
        ended, keyed by slot index. Raises ``ResetNeeded`` for a slot without an episode and ``ValueError`` for
        actions outside the action space (see :meth:`check_actions`), before any state changes.
        """
        sel: Index = slice(None) if idx is None else np.asarray(idx, dtype=np.int64)
        if self.unready:
            self._check_ready(sel)
        actions = self.check_actions(actions, sel)
        rewards, terminated = self._step(sel, actions)
        self.episode_return[sel] += rewards
        self.episode_length[sel] += 1
        finals: dict[int, dict] = {}
        if terminated.any():
            done = self.slots(sel)[terminated]
            returns, lengths = self.episode_return[done].tolist(), self.episode_length[done].tolist()
            done = done.tolist()
            for k, reward, length, info in zip(done, returns, lengths, self._final_infos(done), strict=True):
                finals[k] = {"reward": reward, "length": length, **info}
        return rewards, terminated, finals

    def check_actions(self, actions: Any, idx: Index = slice(None)) -> np.ndarray:
        """``actions`` as an array, if it holds one valid action per slot of ``idx``; else ``ValueError``.

        One vectorised test: the shape, an integer dtype, and every entry below its bound once viewed as unsigned
        (negative entries become huge); a few entries (one slot) are compared as Python ints, which is cheaper. The
        message of a refusal names the slot, the action and the valid space.
        """
        if not isinstance(actions, np.ndarray):
            actions = _as_array(actions, self.single_action_space)
        bounds = self._action_bounds
        if bounds is None:
            bounds = self._action_bounds = _action_bounds(self.single_action_space, self.num_envs)
        batch_shape, row_shape, high, top = bounds
        shape = batch_shape if isinstance(idx, slice) else (len(idx), *row_shape)
        if actions.shape != shape and not row_shape and actions.shape == (*shape, 1):
            actions = actions.reshape(shape)  # Discrete actions as one-element rows (memory-gym's clients send them)
        if actions.shape != shape or actions.dtype.kind not in "iu":
            raise ValueError(_action_error(actions, self.slots(idx), self.single_action_space))
        if actions.size > _FEW_ACTIONS or top is None:
            valid = not np.count_nonzero(actions.view(_UNSIGNED[actions.itemsize]) >= high)
        else:
            values = actions.ravel().tolist()
            valid = min(values) >= 0 and max(values) < top
        if not valid:
            raise ValueError(_action_error(actions, self.slots(idx), self.single_action_space))
        return actions

    def _check_ready(self, sel: Index) -> None:
        waiting = sorted(self.unready.intersection(self.slots(sel).tolist()))
        if waiting:
            which = f"slot {waiting[0]}" if len(waiting) == 1 else f"slots {', '.join(map(str, waiting[:8]))}"
            raise ResetNeeded(
                f"{which} of {self.env_name or type(self).__name__} has no episode to step (never reset, or the last "
                "reset failed): call reset first"
            )

    def observations(self, idx: np.ndarray | None = None) -> np.ndarray | dict[str, np.ndarray]:
        """Copies of the current observations of the slots ``idx`` (all when ``None``)."""
        obs = self._observation(slice(None) if idx is None else np.asarray(idx, dtype=np.int64))
        if isinstance(obs, dict):
            return {key: np.array(v) for key, v in obs.items()}
        return np.array(obs)

    def step_info(self, k: int) -> dict[str, Any]:
        """The info that every step and reset of slot ``k`` carries (empty except for the endless envs)."""
        return self._step_info(k)

    def step_infos(self) -> dict[str, np.ndarray]:
        """The step infos of all slots as arrays with a leading slot axis: row k of ``step_infos()[key]`` equals
        ``step_info(k)[key]`` (same values, same dtype as gymnasium batches them). Every slot has the same keys."""
        return self._step_infos()

    def debug_frame(self, k: int) -> np.ndarray:
        """The 336x336 ground-truth picture of slot ``k``."""
        frame = self._debug_frame(k)
        return np.repeat(np.repeat(frame, DEBUG_SCALE, axis=0), DEBUG_SCALE, axis=1)

    def agent_frame(self, k: int) -> np.ndarray:
        """The 84x84 agent view of slot ``k`` (the visual observation)."""
        obs = self._observation(slice(None))  # views of all slots (not a gathered copy of one), copied once below
        image = obs["visual_observation"] if isinstance(obs, dict) else obs
        return np.array(image[k])

    def render_fps(self, k: int) -> int:
        """Frames per second of the human window (some envs slow down while showing clues)."""
        return self.base_render_fps

    def slots(self, idx: Index) -> np.ndarray:
        """Slot numbers selected by ``idx``."""
        return np.arange(self.num_envs)[idx]

    # ------------------------------------------------------------------------------------------ family hooks
    def _reset_slot(self, k: int, rng: np.random.Generator, opts: dict[str, Any]) -> None:
        raise NotImplementedError

    def _reset_slots(self, slots: list[int], rngs: list[np.random.Generator], opts: dict[str, Any]) -> None:
        # Families override this to build several levels together; the RNG calls stay per slot and in order.
        for k, rng in zip(slots, rngs, strict=True):
            self._reset_slot(k, rng, opts)

    def _step(self, idx: Index, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError

    def _max_episode_steps(self, opts: dict[str, Any]) -> int:
        # What memory-gym 1.0.2 stores in ``max_episode_steps`` at a reset with these options; -1: no known limit.
        return -1

    def _observation(self, idx: Index) -> np.ndarray | dict[str, np.ndarray]:
        raise NotImplementedError

    def _final_info(self, k: int) -> dict[str, Any]:
        return {}

    def _final_infos(self, slots: list[int]) -> list[dict[str, Any]]:
        # Families may override this to gather the statistics of many finished slots at once.
        return [self._final_info(k) for k in slots]

    def _step_info(self, k: int) -> dict[str, Any]:
        return {}

    def _step_infos(self) -> dict[str, np.ndarray]:
        # Families with a step info override this with array operations; this default stacks the per-slot infos.
        if type(self)._step_info is BatchedCore._step_info:
            return {}
        infos = [self._step_info(k) for k in range(self.num_envs)]
        return {key: np.array([info[key] for info in infos]) for key in infos[0]}

    def _debug_frame(self, k: int) -> np.ndarray:
        return self.agent_frame(k)


def _action_bounds(space: gym.Space, num_envs: int) -> tuple[tuple[int, ...], tuple[int, ...], np.ndarray, int | None]:
    """For :meth:`BatchedCore.check_actions`: the shape of all slots' actions and of one, the (exclusive) upper
    bound of each entry, and that bound as an int when it is the same for all entries (else None)."""
    if isinstance(space, gym.spaces.Discrete) and space.start == 0:
        return (num_envs,), (), np.array(space.n, dtype=np.uint64), int(space.n)
    if isinstance(space, gym.spaces.MultiDiscrete) and not np.any(space.start):
        nvec = np.asarray(space.nvec, dtype=np.uint64)
        if np.all(nvec == nvec.flat[0]):  # one bound for all entries: a comparison 4x cheaper than broadcast
            return (num_envs, *space.shape), space.shape, np.array(nvec.flat[0]), int(nvec.flat[0])
        return (num_envs, *space.shape), space.shape, nvec, None
    raise NotImplementedError(f"action checks cover Discrete and MultiDiscrete spaces starting at 0, not {space}")


def _transposes(layout: str) -> bool:
    """Whether ``layout`` transposes the images; ``ValueError`` naming the valid layouts for anything else."""
    if not isinstance(layout, str) or layout not in OBSERVATION_LAYOUTS:
        raise ValueError(f"layout={layout!r} is invalid; valid layouts: {', '.join(OBSERVATION_LAYOUTS)}")
    return layout == "memory-gym"


def layout_observation_space(space: gym.Space, layout: str) -> gym.Space:
    """``space``, a core's observation space (row, column, channel images), as the observations of ``layout`` fill
    it: in memory-gym's layout every image (a ``Box`` of rank 3, also inside a ``Dict``) has its first two axes
    swapped; other parts (the vector observations) stay as they are."""
    if not _transposes(layout):
        return space
    if isinstance(space, gym.spaces.Dict):
        return gym.spaces.Dict({key: layout_observation_space(part, layout) for key, part in space.spaces.items()})
    if isinstance(space, gym.spaces.Box) and len(space.shape) == 3:
        return gym.spaces.Box(space.low.swapaxes(0, 1), space.high.swapaxes(0, 1), dtype=space.dtype)
    return space


def _in_layout(obs: np.ndarray | dict[str, np.ndarray], transposed: bool) -> np.ndarray | dict[str, np.ndarray]:
    """Batched observations, fresh copies from :meth:`BatchedCore.observations`, in memory-gym's layout when
    ``transposed``: each image batch (rank 4) as a view with its axes 1 and 2 swapped. A view, not a copy: a
    contiguous transposed copy of 3-byte pixels costs about 20 times the plain copy they already are."""
    if not transposed:
        return obs
    if isinstance(obs, dict):
        return {key: values.swapaxes(1, 2) if values.ndim == 4 else values for key, values in obs.items()}
    return obs.swapaxes(1, 2)


def _no_limit_before_reset(env_name: str) -> AttributeError:
    return AttributeError(
        f"{env_name} has no max_episode_steps before its first reset (the reset's options set it, as in memory-gym): "
        "call reset first"
    )


def _slot_list(slots: Sequence[int] | np.ndarray) -> list[int]:
    if isinstance(slots, np.ndarray):
        return slots.astype(np.int64, copy=False).tolist()
    return [int(k) for k in slots]


def _as_array(actions: Any, space: gym.Space) -> np.ndarray:
    try:
        return np.asarray(actions)
    except ValueError as err:  # ragged nested sequences
        raise ValueError(f"actions {actions!r} do not form an array of actions in {space}") from err


def _plain_column(values: list[Any]) -> bool:
    """Whether gymnasium batches ``values`` (one per finished slot) into a plain array of the first value's type."""
    kind = type(values[0])
    return kind in (int, float, bool) and all(type(value) is kind for value in values)


def _describe_space(space: gym.Space) -> str:
    if isinstance(space, gym.spaces.Discrete):
        return f"{space} (an integer 0..{space.n - 1})"
    if isinstance(space, gym.spaces.MultiDiscrete):
        ranges = ", ".join(f"0..{n - 1}" for n in np.asarray(space.nvec).reshape(-1).tolist())
        return f"MultiDiscrete({np.asarray(space.nvec).tolist()}) (integers [{ranges}])"
    return str(space)


def _action_error(actions: np.ndarray, slots: np.ndarray, space: gym.Space) -> str:
    """Why ``actions`` (one row per slot of ``slots``) are refused: the first offending slot, its action, the space."""
    valid = _describe_space(space)
    row_shape = space.shape
    # Discrete rows may also be one-element arrays (see ``check_actions``)
    rows = f"{row_shape} or (1,)" if not row_shape else f"{row_shape}"
    if actions.shape[:1] != (len(slots),):
        batch = f"{(len(slots),)} or {(len(slots), 1)}" if not row_shape else f"{(len(slots), *row_shape)}"
        return (
            f"got actions of shape {actions.shape} for {len(slots)} slots: expected one action per slot, an array of "
            f"shape {batch}; each action in {valid}"
        )
    for k, action in zip(slots.tolist(), actions, strict=True):
        action = np.asarray(action)  # rows of an object array are the objects themselves (None, ...)
        value = action.tolist()
        if actions.dtype.kind not in "iufb":  # None, strings, ragged objects: not an action at all
            return f"slot {k}: action {value!r} is not an action: expected an action in {valid}"
        if action.shape != row_shape:
            return f"slot {k}: action {value!r} has shape {action.shape}, expected {rows}: an action in {valid}"
        if actions.dtype.kind not in "iu":
            cast = " (integer-valued floats too: cast with astype(int))" if actions.dtype.kind == "f" else ""
            return f"slot {k}: action {value!r} has dtype {actions.dtype}; actions are integers{cast}, in {valid}"
        if not space.contains(action.astype(np.int64)):
            return f"slot {k}: action {value!r} is outside the action space {valid}"
    return f"actions {actions.tolist()!r} are outside the action space {valid}"


def load_core(core: str | type[BatchedCore]) -> type[BatchedCore]:
    """Resolve ``"module:Class"`` to a core class (the registry stores strings so specs stay picklable)."""
    if isinstance(core, str):
        module, _, name = core.partition(":")
        return getattr(importlib.import_module(module), name)
    return core


class HumanWindow:
    """A pygame window that shows the debug picture at the env's frame rate (created on first use)."""

    def __init__(self) -> None:
        import pygame

        self.pygame = pygame
        pygame.display.init()  # display only: initialising audio is slow and noisy on headless machines
        self.screen: Any = None
        self.clock = pygame.time.Clock()

    def show(self, frame: np.ndarray, title: str, fps: int) -> None:
        pg = self.pygame
        size = (frame.shape[1], frame.shape[0])
        if self.screen is None or self.screen.get_size() != size:
            self.screen = pg.display.set_mode(size)
        pg.event.pump()
        pg.display.set_caption(title)
        pg.surfarray.blit_array(self.screen, np.ascontiguousarray(frame.transpose(1, 0, 2)))
        pg.display.flip()
        self.clock.tick(fps)

    def close(self) -> None:
        # Only the display is closed: other instances in the process keep working (unlike the reference).
        self.pygame.display.quit()


def _check_render_mode(render_mode: str | None) -> None:
    if render_mode is not None and render_mode not in RENDER_MODES:
        raise ValueError(f"render_mode={render_mode!r} is invalid; valid render modes: None, {', '.join(RENDER_MODES)}")
    if render_mode != "human":
        os.environ.setdefault("SDL_VIDEODRIVER", "dummy")


class MemoryGymEnv(gym.Env):
    """The single-environment face: one slot of a batched core behind the ``gymnasium.Env`` API.

    ``layout="memory-gym"`` returns memory-gym's (x, y, channel) images (transposed views of fresh arrays); the
    default ``"rows"`` returns (row, column, channel) images. ``render()`` shows (row, column) pictures either way.
    """

    metadata = {"render_modes": RENDER_MODES, "render_fps": 25}

    def __init__(
        self,
        core: str | type[BatchedCore],
        render_mode: str | None = None,
        options: Mapping[str, Any] | None = None,
        layout: str = "rows",
        **variant: Any,
    ) -> None:
        _check_render_mode(render_mode)
        self._transposed = _transposes(layout)
        self.layout = layout
        self.core = load_core(core)(num_envs=1, options=options, **variant)
        self.observation_space = layout_observation_space(self.core.single_observation_space, layout)
        self.action_space = self.core.single_action_space
        self.render_mode = render_mode
        self.metadata = {"render_modes": RENDER_MODES, "render_fps": self.core.base_render_fps}
        self.has_ground_truth_info = self.core.has_ground_truth_info
        self.ground_truth_space = self.core.ground_truth_space
        self._window: HumanWindow | None = None
        self._was_reset = False

    @property
    def max_episode_steps(self) -> int:
        """memory-gym's bound on the length of the current episode, set by every reset from its options (-1: no
        bound, the endless ids' default). Like memory-gym's, the attribute does not exist before the first reset."""
        if not self._was_reset:
            raise _no_limit_before_reset(self.core.env_name)
        return int(self.core.max_episode_steps[0])

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict]:
        # Not ``super().reset(seed)``: that would seed a second generator (as costly as the level) only to replace
        # it. env.np_random is the generator that builds the levels; np_random_seed follows gymnasium's rules.
        self.core.reset_slot(0, seed, options)
        self._was_reset = True
        self._np_random = self.core.rngs[0]
        if seed is not None:
            self._np_random_seed = int(seed)
        elif self._np_random_seed is None:
            self._np_random_seed = -1  # gymnasium's value for a generator that was not seeded through reset
        if self.render_mode == "human":
            self.render()
        return self._obs(), self.core.step_info(0)

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict]:
        rewards, terminated, finals = self.core.step(_as_array(action, self.action_space)[None])
        info = self.core.step_info(0)
        info.update(finals.get(0, {}))
        if self.render_mode == "human":
            self.render()
        return self._obs(), float(rewards[0]), bool(terminated[0]), False, info

    def _obs(self) -> Any:
        # the only slot; a view, copied once (not gathered, then copied)
        obs = _in_layout(self.core.observations(), self._transposed)
        if isinstance(obs, dict):
            return {key: v[0] for key, v in obs.items()}
        return obs[0]

    def render(self) -> np.ndarray | None:
        if not self._was_reset:  # gymnasium.make adds no OrderEnforcing wrapper (envs._register_all): refuse here
            raise ResetNeeded(f"{self.core.env_name} has nothing to render before its first reset: call reset first")
        if self.render_mode == "rgb_array":
            return self.core.agent_frame(0)
        if self.render_mode == "debug_rgb_array":
            return self.core.debug_frame(0)
        if self.render_mode == "human":
            if self._window is None:
                self._window = HumanWindow()
            self._window.show(self.core.debug_frame(0), f"seed {self.core.seeds[0]}", self.core.render_fps(0))
        return None

    def close(self) -> None:
        if self._window is not None:
            self._window.close()
            self._window = None


class MemoryGymVectorEnv(gym.vector.VectorEnv):
    """The native vector face: all slots of one batched core behind ``gymnasium.vector.VectorEnv``.

    ``reset(seed=s)`` seeds slot k with ``s + k`` (a list gives one seed per slot), so slot k reproduces the
    episode of a single env reset with that seed. Autoreset episodes continue each slot's generator, like
    ``reset(seed=None)`` on a single env. ``options={"reset_mask": mask, ...}`` resets only the masked slots.

    The options of a reset call apply to every episode of the slots it resets, autoresets included, until their next
    reset call; a reset without options goes back to the options given to ``make_vec`` (the defaults). (The single
    face applies reset options to one episode, as memory-gym does: its autoresets are the client's resets.)
    ``max_episode_steps`` is memory-gym's per-episode bound of every slot (an array, updated at each slot's reset).
    ``layout="memory-gym"`` returns memory-gym's (x, y, channel) images (transposed views of fresh arrays).
    """

    metadata = {"render_modes": RENDER_MODES, "render_fps": 25, "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(
        self,
        core: str | type[BatchedCore],
        num_envs: int = 1,
        render_mode: str | None = None,
        options: Mapping[str, Any] | None = None,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        layout: str = "rows",
        **variant: Any,
    ) -> None:
        _check_render_mode(render_mode)
        self._transposed = _transposes(layout)
        self.layout = layout
        self.core = load_core(core)(num_envs=num_envs, options=options, **variant)
        self.num_envs = self.core.num_envs
        try:
            self.autoreset_mode = AutoresetMode(autoreset_mode)
        except ValueError as err:
            valid = ", ".join(m.value for m in AutoresetMode)
            raise ValueError(f"autoreset_mode={autoreset_mode!r} is invalid; valid modes: {valid}") from err
        self.single_observation_space = layout_observation_space(self.core.single_observation_space, layout)
        self.single_action_space = self.core.single_action_space
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.render_mode = render_mode
        self.metadata = {
            "render_modes": RENDER_MODES,
            "render_fps": self.core.base_render_fps,
            "autoreset_mode": self.autoreset_mode,
        }
        self._needs_reset = np.zeros(self.num_envs, dtype=bool)
        self._was_reset = False

    @property
    def max_episode_steps(self) -> np.ndarray:
        """memory-gym's ``max_episode_steps`` of each slot's current episode (int64, one entry per slot, updated at
        every reset and autoreset of the slot; 0 for a slot that a masked reset never reached). Like the single
        face's attribute, it does not exist before the first reset."""
        if not self._was_reset:
            raise _no_limit_before_reset(self.core.env_name)
        return self.core.max_episode_steps.copy()

    def get_attr(self, name: str) -> tuple[Any, ...]:
        """One value per slot, as gymnasium's ``SyncVectorEnv.get_attr`` gives one per sub-environment (clients
        written for memory-gym read ``max_episode_steps`` this way). Only what a slot's single environment would
        report is answered: ``max_episode_steps`` (per slot), ``observation_space``, ``action_space``,
        ``render_mode``."""
        if name == "max_episode_steps":
            return tuple(int(steps) for steps in self.max_episode_steps)
        shared = {
            "observation_space": self.single_observation_space,
            "action_space": self.single_action_space,
            "render_mode": self.render_mode,
        }
        if name not in shared:
            valid = ", ".join(["max_episode_steps", *shared])
            raise AttributeError(f"{self.core.env_name}'s slots report no attribute {name!r}: valid names are {valid}")
        return (shared[name],) * self.num_envs

    def call(self, name: str, *args: Any, **kwargs: Any) -> tuple[Any, ...]:
        """``SyncVectorEnv.call`` for the attributes of :meth:`get_attr` (none of them is a method, so nothing takes
        arguments)."""
        if args or kwargs:
            raise ValueError(f"call({name!r}) takes no arguments here: {name!r} is an attribute, not a method")
        return self.get_attr(name)

    def reset(
        self, *, seed: int | Sequence[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict]:
        check_mapping(options, self.core.option_specs, self.core.env_name, extra=("reset_mask",))
        super().reset(seed=seed if isinstance(seed, int) else None)
        options = dict(options or {})
        mask = np.asarray(options.pop("reset_mask", np.ones(self.num_envs, dtype=bool)), dtype=bool)
        if mask.shape != (self.num_envs,):
            raise ValueError(f"reset_mask has shape {mask.shape}; expected ({self.num_envs},)")
        seeds = self._slot_seeds(seed)
        slots = np.flatnonzero(mask)
        self.core.reset_slots(slots, [seeds[k] for k in slots], options)
        self._was_reset = True
        self._needs_reset[mask] = False
        infos: dict[str, Any] = {}
        if slots.size:
            self._add_step_infos(infos, mask)
        return self._observations(), infos

    def _slot_seeds(self, seed: int | Sequence[int | None] | None) -> list[int | None]:
        if seed is None:
            return [None] * self.num_envs
        if isinstance(seed, int | np.integer):
            return [int(seed) + k for k in range(self.num_envs)]
        seeds = list(seed)
        if len(seeds) != self.num_envs:
            raise ValueError(f"got {len(seeds)} seeds for {self.num_envs} environments")
        return seeds

    def step(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict]:
        actions = _as_array(actions, self.action_space)
        n = self.num_envs
        if self.autoreset_mode == AutoresetMode.NEXT_STEP and self._needs_reset.any():
            actions = self.core.check_actions(actions)  # all of them, also those of the restarting slots (ignored)
            restart = np.flatnonzero(self._needs_reset)
            live = np.flatnonzero(~self._needs_reset)
            rewards = np.zeros(n, dtype=np.float64)
            terminated = np.zeros(n, dtype=bool)
            if live.size:
                r, t, finals = self.core.step(actions[live], idx=live)
                rewards[live], terminated[live] = r, t
            else:
                finals = {}
            self.core.restart_slots(restart)  # with the options of their last reset; their generators continue
        else:
            rewards, terminated, finals = self.core.step(actions)
            rewards = np.asarray(rewards, dtype=np.float64)
        infos: dict[str, Any] = {}
        if self.autoreset_mode == AutoresetMode.SAME_STEP:
            self._same_step_autoreset(infos, finals)
        else:
            self._add_step_infos(infos)
            self._add_final_infos(infos, finals)
        self._needs_reset = terminated.copy() if self.autoreset_mode == AutoresetMode.NEXT_STEP else np.zeros(n, bool)
        truncated = np.zeros(n, dtype=bool)
        return self._observations(), rewards, terminated, truncated, infos

    def _observations(self, idx: np.ndarray | None = None) -> np.ndarray | dict[str, np.ndarray]:
        """Fresh observations of the slots ``idx`` (all when None) in this face's layout."""
        return _in_layout(self.core.observations(idx), self._transposed)

    # Infos are assembled with arrays: gymnasium's format (``info[key]`` batched over the slots, ``info["_key"]`` the
    # mask of the slots that have the key), the values and key order of ``_add_info`` applied slot by slot to each
    # slot's ``step_info`` merged with its final info (NEXT_STEP), or preceded by ``final_obs`` and ``final_info``
    # (SAME_STEP).
    def _add_step_infos(self, infos: dict[str, Any], mask: np.ndarray | None = None) -> None:
        """The step infos of all slots (of the ``mask`` slots; the others' rows are zero and unmasked)."""
        for key, values in self.core.step_infos().items():
            if mask is None:
                infos[key], infos[f"_{key}"] = values, np.ones(self.num_envs, dtype=bool)
            else:
                values[~mask] = 0
                infos[key], infos[f"_{key}"] = values, mask.copy()

    def _add_final_infos(self, infos: dict[str, Any], finals: dict[int, dict[str, Any]]) -> None:
        """The final infos of the finished slots: one array per key when every slot reports the same keys with
        values of one plain type per key (every family here), else slot by slot through gymnasium's ``_add_info``."""
        if not finals:
            return
        slots = list(finals)
        rows = list(finals.values())
        keys = tuple(rows[0])
        columns = [[row[key] for row in rows] for key in keys] if all(tuple(row) == keys for row in rows) else None
        if columns is None or not all(_plain_column(column) for column in columns):
            for k, row in finals.items():
                self._add_info(infos, row, k)
            return
        mask = np.zeros(self.num_envs, dtype=bool)
        mask[slots] = True
        for key, column in zip(keys, columns, strict=True):
            values = np.zeros(self.num_envs, dtype=type(column[0]))
            values[slots] = column
            infos[key], infos[f"_{key}"] = values, mask.copy()

    def _same_step_autoreset(self, infos: dict[str, Any], finals: dict[int, dict[str, Any]]) -> None:
        """SAME_STEP: the finished slots report ``final_obs`` and ``final_info`` (their step info merged with their
        final info) and are reset at once; then every slot reports the step info of its current episode."""
        done = list(finals)
        entries = {}
        if done:
            before = self.core.step_infos()
            obs = self._observations(np.array(done))
            for i, k in enumerate(done):
                final_obs = {key: v[i] for key, v in obs.items()} if isinstance(obs, dict) else obs[i]
                final_info = {key: values[k] for key, values in before.items()}
                final_info.update(finals[k])
                entries[k] = {"final_obs": final_obs, "final_info": final_info}
            self.core.restart_slots(done)
        if done and done[0] == 0:  # slot 0's entries come first, as slot by slot
            self._add_info(infos, entries.pop(0), 0)
        self._add_step_infos(infos)
        for k, entry in entries.items():
            self._add_info(infos, entry, k)

    def render(self) -> tuple[np.ndarray, ...] | None:
        if self.render_mode == "rgb_array":
            return tuple(self.core.agent_frame(k) for k in range(self.num_envs))
        if self.render_mode == "debug_rgb_array":
            return tuple(self.core.debug_frame(k) for k in range(self.num_envs))
        return None
