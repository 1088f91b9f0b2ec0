"""Any gymnasium environment behind the slot API of :class:`~envs.core.BatchedCore`, so that the trainer, the actor
and the evaluation drive it exactly as they drive this project's own cores.

:class:`GymnasiumCore` holds ``num_envs`` copies of the environment in a gymnasium 1.x vector env (``sync``: one
process, ``async``: one subprocess per copy) with ``AutoresetMode.NEXT_STEP``. A slot is reset with its own seed
through the vector env's ``reset(seed=[...], options={"reset_mask": mask})``. A vector env steps every copy at once;
the slot API may step a subset (the slots whose episode goes on while others wait for a reset), so the copies outside
the subset must have no episode in progress: they are stepped with action 0 and their results are dropped (the vector
env restarts them unseeded; the slot's next reset seeds it again).

Spaces, translated to what the model takes (:func:`observation_layout`, :func:`action_layout`):

* observations: a uint8 ``Box`` of rank 3 is an image (``H, W, C``; with ``image_layout="chw"`` it is ``C, H, W``
  and transposed), of rank 2 a one-channel image; every other ``Box`` (any dtype and shape) is flattened into float32
  features, ``Discrete`` and ``MultiDiscrete`` become one-hot codes, ``MultiBinary`` 0/1 features; ``Dict`` and
  ``Tuple`` (nested too) combine them: at most one image, every other part concatenated, in the space's order, into
  one vector. The translated space is the image ``Box`` alone, or a ``Dict`` of ``visual_observation`` and/or
  ``vector_observation``, the keys of this project's cores;
* actions: ``Discrete`` and ``MultiDiscrete`` (1-d), their ``start`` offsets added on the way out; anything else (a
  continuous ``Box`` included) is refused with a ``ValueError`` naming the space.

An episode ends when the environment reports ``terminated`` or ``truncated`` (the final info says which: its
``truncated`` entry is 1 for a cut episode). Final infos hold the episode's ``reward`` (return) and ``length``, the
``truncated`` flag and every scalar of the environment's own info at its last step (booleans as 0/1, nested dicts
flattened as ``outer.inner``).

Seeding: after the first seeded reset, each reset copy must report the seed it was given as its ``np_random_seed``
(what ``gymnasium.Env.reset`` records when an environment seeds through ``super().reset(seed=seed)``). An environment
that ignores the seed cannot reproduce its episodes: :class:`SeedingError` by default, a warning with
``check_seeding=False``.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode

from envs.core import BatchedCore, Index, load_core

__all__ = [
    "GymnasiumCore",
    "SeedingError",
    "UnknownEnvironmentError",
    "UnsupportedSpaceError",
    "VECTORIZATIONS",
    "IMAGE_LAYOUTS",
    "action_layout",
    "make_single_env",
    "observation_layout",
]

VECTORIZATIONS = ("sync", "async")
IMAGE_LAYOUTS = ("hwc", "chw")
VECTOR_KEY, IMAGE_KEY = "vector_observation", "visual_observation"
Path = tuple[str | int, ...]  # where a part sits in a nested (Dict / Tuple) observation


class UnsupportedSpaceError(ValueError):
    """An observation or action space this project cannot feed to (or take from) its model."""


class SeedingError(ValueError):
    """An environment whose reset ignores the seed it is given."""


class UnknownEnvironmentError(ValueError):
    """An id that gymnasium cannot make."""


# ------------------------------------------------------------------------------------------------------ spaces
@dataclass(frozen=True)
class _Part:
    path: Path
    space: gym.Space
    size: int  # features it contributes to the vector (0 for the image)


@dataclass(frozen=True)
class ObservationLayout:
    """How a (batched) observation of ``space`` becomes the model's image and vector arrays."""

    space: gym.Space  # the environment's own observation space
    image: _Part | None
    channels_first: bool
    vector: tuple[_Part, ...]
    single_space: gym.Space  # the translated space (image Box, or Dict of visual/vector_observation)

    def convert(self, batch: Any) -> dict[str, np.ndarray]:
        """A batch of ``n`` observations (gymnasium's batched form) -> {key: (n, ...) array}."""
        arrays: dict[str, np.ndarray] = {}
        if self.image is not None:
            image = np.asarray(_at(batch, self.image.path))
            if image.ndim == 3:  # rank-2 image: one channel
                image = image[..., None]
            elif self.channels_first:
                image = image.transpose(0, 2, 3, 1)
            arrays[IMAGE_KEY] = np.ascontiguousarray(image, dtype=np.uint8)
        if self.vector:
            arrays[VECTOR_KEY] = np.concatenate(
                [_features(part.space, _at(batch, part.path)) for part in self.vector], 1
            )
        return arrays


def observation_layout(space: gym.Space, image_layout: str = "hwc") -> ObservationLayout:
    """The translation of ``space`` (see the module docstring); :class:`UnsupportedSpaceError` names a part this
    project cannot feed to its model."""
    if image_layout not in IMAGE_LAYOUTS:
        raise ValueError(f"image_layout={image_layout!r} is invalid; valid choices: {', '.join(IMAGE_LAYOUTS)}")
    images, vector = [], []
    for path, leaf in _leaves(space, ()):
        if isinstance(leaf, gym.spaces.Box) and leaf.dtype == np.uint8 and len(leaf.shape) in (2, 3):
            images.append(_Part(path, leaf, 0))
        elif isinstance(leaf, gym.spaces.Box | gym.spaces.MultiBinary):
            vector.append(_Part(path, leaf, int(np.prod(leaf.shape))))
        elif isinstance(leaf, gym.spaces.Discrete):
            vector.append(_Part(path, leaf, int(leaf.n)))
        elif isinstance(leaf, gym.spaces.MultiDiscrete):
            vector.append(_Part(path, leaf, int(np.asarray(leaf.nvec).sum())))
        else:
            where = f" (part {_path_text(path)})" if path else ""
            raise UnsupportedSpaceError(
                f"unsupported observation space {leaf}{where} in {space}: expected Box (uint8 images of rank 2 or 3, "
                "any other Box as features), Discrete, MultiDiscrete, MultiBinary, or a Dict / Tuple of them"
            )
    if len(images) > 1:
        where = ", ".join(_path_text(part.path) for part in images)
        raise UnsupportedSpaceError(
            f"observation space {space} holds {len(images)} images ({where}): the model takes one image; drop or merge "
            "the others with a wrapper (env.wrappers)"
        )
    image = images[0] if images else None
    channels_first = image_layout == "chw"
    parts: dict[str, gym.Space] = {}
    if image is not None:
        shape = image.space.shape
        if len(shape) == 2:
            shape = (*shape, 1)
        elif channels_first:
            shape = (shape[1], shape[2], shape[0])
        parts[IMAGE_KEY] = gym.spaces.Box(0, 255, shape, np.uint8)
    size = sum(part.size for part in vector)
    if size:
        parts[VECTOR_KEY] = gym.spaces.Box(-np.inf, np.inf, (size,), np.float32)
    if not parts:
        raise UnsupportedSpaceError(f"observation space {space} has nothing to observe")
    single = parts[IMAGE_KEY] if list(parts) == [IMAGE_KEY] else gym.spaces.Dict(parts)
    return ObservationLayout(space, image, channels_first, tuple(part for part in vector if part.size), single)


def action_layout(space: gym.Space) -> tuple[gym.Space, np.ndarray]:
    """The action space the policy acts in (starting at 0) and the offsets to add for the environment; a
    :class:`UnsupportedSpaceError` for anything but Discrete and 1-d MultiDiscrete."""
    if isinstance(space, gym.spaces.Discrete):
        return gym.spaces.Discrete(int(space.n)), np.asarray(space.start, dtype=np.int64)
    if isinstance(space, gym.spaces.MultiDiscrete) and np.asarray(space.nvec).ndim == 1:
        return gym.spaces.MultiDiscrete(np.asarray(space.nvec)), np.asarray(space.start, dtype=np.int64)
    kind = "continuous actions are not supported (the policy has categorical heads); " if _continuous(space) else ""
    raise UnsupportedSpaceError(
        f"unsupported action space {space}: {kind}expected Discrete or 1-d MultiDiscrete (discretise the actions with "
        "a wrapper in env.wrappers)"
    )


def _continuous(space: gym.Space) -> bool:
    return isinstance(space, gym.spaces.Box) and np.issubdtype(space.dtype, np.floating)


def _leaves(space: gym.Space, path: Path) -> list[tuple[Path, gym.Space]]:
    if isinstance(space, gym.spaces.Dict):
        return [leaf for key, sub in space.spaces.items() for leaf in _leaves(sub, (*path, key))]
    if isinstance(space, gym.spaces.Tuple):
        return [leaf for i, sub in enumerate(space.spaces) for leaf in _leaves(sub, (*path, i))]
    return [(path, space)]


def _path_text(path: Path) -> str:
    return "".join(f"[{key!r}]" for key in path) or "the observation"


def _at(batch: Any, path: Path) -> Any:
    for key in path:
        batch = batch[key]
    return batch


def _features(space: gym.Space, values: Any) -> np.ndarray:
    """(n, features) float32 of one part: Box / MultiBinary flattened, Discrete / MultiDiscrete one-hot."""
    values = np.asarray(values)
    n = values.shape[0]
    if isinstance(space, gym.spaces.Discrete):
        codes = np.zeros((n, int(space.n)), dtype=np.float32)
        codes[np.arange(n), values.reshape(n).astype(np.int64) - int(space.start)] = 1.0
        return codes
    if isinstance(space, gym.spaces.MultiDiscrete):
        nvec = np.asarray(space.nvec, dtype=np.int64).reshape(-1)
        offsets = np.concatenate(([0], np.cumsum(nvec)[:-1]))
        index = values.reshape(n, -1).astype(np.int64) - np.asarray(space.start, dtype=np.int64).reshape(-1) + offsets
        codes = np.zeros((n, int(nvec.sum())), dtype=np.float32)
        np.put_along_axis(codes, index, 1.0, axis=1)
        return codes
    return values.reshape(n, -1).astype(np.float32)


# ---------------------------------------------------------------------------------------------- construction
def make_single_env(
    env_id: str,
    make_kwargs: Mapping[str, Any] | None = None,
    wrappers: Sequence[str | Mapping[str, Any]] = (),
) -> gym.Env:
    """``gymnasium.make(env_id, **make_kwargs)`` (``"module:EnvId"`` imports the module first) with ``wrappers``
    applied in order: each an import path ``"module:Wrapper"`` or ``{"path": "module:Wrapper", "kwargs": {...}}``."""
    try:
        env = gym.make(env_id, **dict(make_kwargs or {}))
    except (gym.error.Error, ModuleNotFoundError) as err:
        raise UnknownEnvironmentError(f"unknown environment id {env_id!r}: gymnasium cannot make it ({err})") from err
    for wrapper in wrappers:
        factory, kwargs = _wrapper(wrapper)
        env = factory(env, **kwargs)
    return env


def _wrapper(entry: str | Mapping[str, Any]) -> tuple[Callable[..., gym.Env], dict[str, Any]]:
    if isinstance(entry, str):
        path, kwargs = entry, {}
    elif isinstance(entry, Mapping) and set(entry) <= {"path", "kwargs"} and isinstance(entry.get("path"), str):
        path, kwargs = entry["path"], dict(entry.get("kwargs") or {})
    else:
        raise ValueError(
            f"wrapper {entry!r} is invalid: expected an import path 'module:Wrapper' or "
            "{path: 'module:Wrapper', kwargs: {...}}"
        )
    module, sep, name = path.partition(":")
    if not sep or not module or not name:
        raise ValueError(f"wrapper {path!r} is invalid: expected an import path 'module:Wrapper'")
    try:
        return load_core(path), kwargs  # type: ignore[return-value]  (the same 'module:Name' resolution)
    except (ImportError, AttributeError) as err:
        raise ValueError(f"wrapper {path!r} cannot be imported: {err}") from err


class GymnasiumCore(BatchedCore):
    """``num_envs`` copies of a gymnasium environment behind the slot API (see the module docstring)."""

    option_specs: dict = {}
    # The environment's internal state cannot be saved: a resumed run starts new episodes in every slot instead of
    # replaying the ones in progress (agents.actor.Actor.load_state).
    replayable = False

    def __init__(
        self,
        env_id: str,
        num_envs: int = 1,
        options: Mapping[str, Any] | None = None,
        make_kwargs: Mapping[str, Any] | None = None,
        wrappers: Sequence[str | Mapping[str, Any]] = (),
        vectorization: str = "sync",
        image_layout: str = "hwc",
        check_seeding: bool = True,
    ) -> None:
        if vectorization not in VECTORIZATIONS:
            raise ValueError(f"vectorization={vectorization!r} is invalid; valid choices: {', '.join(VECTORIZATIONS)}")
        super().__init__(num_envs)
        self.env_name = env_id
        self.base_options = dict(options or {})  # passed to every reset, unchecked: the environment's own names
        self.check_seeding = check_seeding
        make_kwargs, wrappers = dict(make_kwargs or {}), list(wrappers)
        probe = make_single_env(env_id, make_kwargs, wrappers)  # fails here, not in a subprocess, on a bad id
        self.layout = observation_layout(probe.observation_space, image_layout)
        self.single_observation_space = self.layout.single_space
        self.single_action_space, self._action_start = action_layout(probe.action_space)
        limit = probe.spec.max_episode_steps if probe.spec is not None else None
        self.max_episode_steps[:] = -1 if limit is None else int(limit)
        fns = [_EnvFactory(env_id, make_kwargs, wrappers) for _ in range(self.num_envs)]
        mode = AutoresetMode.NEXT_STEP
        if vectorization == "sync":
            fns[0] = _Given(probe)
            self.vec: gym.vector.VectorEnv = gym.vector.SyncVectorEnv(fns, autoreset_mode=mode)
        else:
            probe.close()
            self.vec = gym.vector.AsyncVectorEnv(fns, autoreset_mode=mode)
        self._obs: dict[str, np.ndarray] = {
            key: np.zeros((self.num_envs, *space.shape), dtype=space.dtype) for key, space in self._parts().items()
        }
        self.playing = np.zeros(self.num_envs, dtype=bool)  # slots with an episode in progress
        self._last_infos: dict[str, Any] = {}
        self._truncated = np.zeros(self.num_envs, dtype=bool)
        self._seeding_checked = False

    def _parts(self) -> dict[str, gym.spaces.Box]:
        space = self.single_observation_space
        return dict(space.spaces) if isinstance(space, gym.spaces.Dict) else {IMAGE_KEY: space}

    # ----------------------------------------------------------------------------------------------- slot API
    def resolve(self, options: Mapping[str, Any] | None) -> dict[str, Any]:
        return {**self.base_options, **dict(options or {})}

    def reset_slots(
        self,
        slots: Sequence[int] | np.ndarray,
        seeds: Sequence[int | None] | None = None,
        options: Mapping[str, Any] | None = None,
    ) -> None:
        slots = [int(k) for k in np.asarray(slots, dtype=np.int64).reshape(-1)]
        if not slots:
            return
        seeds = [None] * len(slots) if seeds is None else [None if s is None else int(s) for s in seeds]
        if len(seeds) != len(slots):
            raise ValueError(f"got {len(seeds)} seeds for {len(slots)} slots")
        self.unready.update(slots)
        mask = np.zeros(self.num_envs, dtype=bool)
        mask[slots] = True
        slot_seeds: list[int | None] = [None] * self.num_envs
        for k, seed in zip(slots, seeds, strict=True):
            slot_seeds[k] = seed
            if seed is not None:
                self.seeds[k] = seed
        observations, _ = self.vec.reset(seed=slot_seeds, options={**self.resolve(options), "reset_mask": mask})
        self._store(observations, np.asarray(slots))
        if not self._seeding_checked and any(seed is not None for seed in seeds):
            self._check_seeding(slots, seeds)
        self.episode_return[slots] = 0.0
        self.episode_length[slots] = 0
        self.playing[slots] = True
        self.unready.difference_update(slots)

    def restart_slots(self, slots: Sequence[int] | np.ndarray) -> None:
        self.reset_slots(slots)

    def _check_seeding(self, slots: list[int], seeds: list[int | None]) -> None:
        self._seeding_checked = True
        reported = self.vec.get_attr("np_random_seed")
        ignored = [(k, s, reported[k]) for k, s in zip(slots, seeds, strict=True) if s is not None and reported[k] != s]
        if not ignored:
            return
        k, seed, got = ignored[0]
        message = (
            f"{self.env_name} ignores the seed of reset: slot {k} was reset with seed={seed} but reports "
            f"np_random_seed={got}, so its episodes cannot be reproduced (training seeds, novel evaluation seeds). "
            "Seed the environment's generator through super().reset(seed=seed) in its reset"
        )
        if self.check_seeding:
            raise SeedingError(f"{message}, or set env.check_seeding: false to train on it anyway")
        warnings.warn(f"{message}; env.check_seeding is false: going on with unreproducible episodes", stacklevel=2)

    def _step(self, idx: Index, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        stepped = self.slots(idx)
        full = np.zeros((self.num_envs, *actions.shape[1:]), dtype=np.int64)
        full[stepped] = actions
        if stepped.size != self.num_envs:
            waiting = np.ones(self.num_envs, dtype=bool)
            waiting[stepped] = False
            busy = np.flatnonzero(waiting & self.playing)
            if busy.size:
                raise RuntimeError(
                    f"slot {int(busy[0])} of {self.env_name} is in an episode but not stepped: a gymnasium vector env "
                    "steps every copy, so only slots whose episode ended can wait"
                )
            full[waiting] = 0  # their results are dropped; the vector env restarts them unseeded
        observations, rewards, terminated, truncated, infos = self.vec.step(full + self._action_start)
        self._store(observations, stepped)
        ended = np.asarray(terminated, dtype=bool) | np.asarray(truncated, dtype=bool)
        self._last_infos, self._truncated = infos, np.asarray(truncated, dtype=bool)
        done = stepped[ended[stepped]]
        self.playing[done] = False
        self.unready.update(done.tolist())  # a finished copy must be reset before it is stepped again
        return np.asarray(rewards, dtype=np.float32)[stepped], ended[stepped]

    def _store(self, observations: Any, slots: np.ndarray) -> None:
        converted = self.layout.convert(observations)
        for key, values in converted.items():
            self._obs[key][slots] = values[slots]

    def _observation(self, idx: Index) -> np.ndarray | dict[str, np.ndarray]:
        if isinstance(self.single_observation_space, gym.spaces.Dict):
            return {key: values[idx] for key, values in self._obs.items()}
        return self._obs[IMAGE_KEY][idx]

    def _final_info(self, k: int) -> dict[str, Any]:
        info = {key: value for key, value in _slot_info(self._last_infos, k).items() if key not in ("reward", "length")}
        return {"truncated": int(self._truncated[k]), **info}

    def agent_frame(self, k: int) -> np.ndarray:
        if IMAGE_KEY not in self._obs:
            raise ValueError(f"{self.env_name} has no image observation to show (its observation is a vector)")
        return np.array(self._obs[IMAGE_KEY][k])

    def _debug_frame(self, k: int) -> np.ndarray:
        return self.agent_frame(k)  # no ground-truth view: the agent's view twice

    def close(self) -> None:
        self.vec.close()


def _slot_info(infos: Mapping[str, Any], k: int, prefix: str = "") -> dict[str, Any]:
    """Slot ``k``'s scalars of gymnasium's batched infos (``info[key]`` with the mask ``info["_key"]``)."""
    found: dict[str, Any] = {}
    for key, values in infos.items():
        if key.startswith("_"):
            continue
        mask = infos.get(f"_{key}")
        if mask is not None and not bool(np.asarray(mask)[k]):
            continue
        name = f"{prefix}{key}"
        if isinstance(values, Mapping):
            found.update(_slot_info(values, k, f"{name}."))
            continue
        value = values[k] if isinstance(values, np.ndarray) and values.ndim >= 1 else None
        if isinstance(value, np.bool_ | bool):
            found[name] = int(value)
        elif isinstance(value, np.integer | np.floating):
            found[name] = value.item()
        elif isinstance(value, int | float) and not isinstance(value, bool):
            found[name] = value
    return found


class _EnvFactory:
    """A picklable ``env_fns`` entry (AsyncVectorEnv sends it to a subprocess)."""

    def __init__(self, env_id: str, make_kwargs: dict[str, Any], wrappers: list[Any]) -> None:
        self.env_id, self.make_kwargs, self.wrappers = env_id, make_kwargs, wrappers

    def __call__(self) -> gym.Env:
        return make_single_env(self.env_id, self.make_kwargs, self.wrappers)


class _Given:
    """An ``env_fns`` entry that hands over an environment already made (the probe: made once, not twice)."""

    def __init__(self, env: gym.Env) -> None:
        self.env = env

    def __call__(self) -> gym.Env:
        return self.env
