"""Random numbers exactly as the reference draws them, at a fraction of numpy's cost per call.

Every slot owns the generator the reference builds for ``reset(seed=s)`` (:func:`seeded_generator`). Level
generation makes dozens of small bounded draws (``rng.integers(0, n)``, ``rng.choice(list)``) per reset, and numpy
spends microseconds on each call whatever its size. :class:`BoundedDraws` makes the same draws from 32-bit words
fetched in bulk and leaves the generator in exactly the state the one-by-one calls would have left it, so later
draws (the next level, the next episode of a continuing generator) stay identical to the reference's.
:class:`DirectDraws` serves levels that mix bounded ints with doubles (``rng.uniform``) and make only a few draws
at a time: it calls the bit generator's C functions directly, the ones numpy's calls end in.
"""

from __future__ import annotations

import ctypes
from collections.abc import Sequence
from functools import cache
from typing import Any

import numpy as np
from numpy.random.bit_generator import ISpawnableSeedSequence

_WORD = 1 << 32


_capsule_pointer = ctypes.pythonapi.PyCapsule_GetPointer
_capsule_pointer.restype, _capsule_pointer.argtypes = ctypes.c_void_p, [ctypes.py_object, ctypes.c_char_p]


_UINT32_FUNCTION = ctypes.CFUNCTYPE(ctypes.c_uint32, ctypes.c_void_p)
_DOUBLE_FUNCTION = ctypes.CFUNCTYPE(ctypes.c_double, ctypes.c_void_p)
_bitgen_cache: dict[type, tuple[Any, Any]] = {}  # per bit generator class (its C functions are static)


def _bitgen_functions(bit_generator: np.random.BitGenerator) -> tuple[int, Any, Any]:
    """The state address and the C ``next_uint32`` and ``next_double`` of a bit generator, read from its
    ``bitgen_t`` struct (state, next_uint64, next_uint32, next_double, ...); the functions are checked once per
    class against numpy's ctypes interface. None for the functions if the struct is not as expected."""
    functions = _bitgen_cache.get(type(bit_generator))
    if functions is None:
        functions = _bitgen_cache[type(bit_generator)] = _checked_functions(bit_generator)
    if functions[0] is None:
        return 0, None, None
    return ctypes.c_void_p.from_address(_capsule_pointer(bit_generator.capsule, b"BitGenerator")).value, *functions


def _checked_functions(bit_generator: np.random.BitGenerator) -> tuple[Any, Any]:
    try:
        bitgen = (ctypes.c_void_p * 4).from_address(_capsule_pointer(bit_generator.capsule, b"BitGenerator"))
        interface = bit_generator.ctypes
        expected = [ctypes.cast(f, ctypes.c_void_p).value for f in (interface.next_uint32, interface.next_double)]
    except (AttributeError, TypeError, ValueError):
        return None, None
    if bitgen[0] != interface.state_address or [bitgen[2], bitgen[3]] != expected:
        return None, None
    return _UINT32_FUNCTION(bitgen[2]), _DOUBLE_FUNCTION(bitgen[3])


def next_word(rng: np.random.Generator) -> int:
    """``int(rng.integers(0, 2**32, dtype=np.uint32))`` (a leftover half first, else the low half of a fresh
    output, keeping its high half), calling the bit generator's C function directly: a third of numpy's cost."""
    state, next_uint32, _ = _bitgen_functions(rng.bit_generator)
    if next_uint32 is None:
        return int(rng.integers(0, _WORD, dtype=np.uint32))
    return next_uint32(state)


def seeded_generator(seed: int) -> np.random.Generator:
    """The generator the reference builds for ``reset(seed=s)``: PCG64 over a SeedSequence of the seed."""
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence(seed)))


# numpy's SeedSequence: a pool of four 32-bit words filled by the hash of O'Neill's ``seed_seq_fe``; PCG64 takes its
# first four 64-bit words of output. These are the hash's published constants.
_POOL = 4
_INIT_A, _MULT_A, _INIT_B, _MULT_B = 0x43B0D7E5, 0x931E8875, 0x8B51F9DD, 0x58F38DED
_MIX_L, _MIX_NEG_R = 0xCA01F9DD, (1 << 32) - 0x4973F715  # mix(x, y) = L * x - R * y = L * x + (2**32 - R) * y
_MIX_PAIRS = [(src, dst) for src in range(_POOL) for dst in range(_POOL) if src != dst]
_BATCH_SEEDING_FROM = 3  # fewer seeds: numpy's own SeedSequence is as fast


def _hash_constants(init: int, mult: int, count: int) -> list[tuple[int, int]]:
    """The hash's (xor, multiplier) pair of each successive call: the constant advances by ``mult`` per call, so
    the pairs do not depend on the data."""
    pairs, value = [], init
    for _ in range(count):
        advanced = (value * mult) & 0xFFFFFFFF
        pairs.append((value, advanced))
        value = advanced
    return pairs


_HASH_POOL = _hash_constants(_INIT_A, _MULT_A, _POOL + len(_MIX_PAIRS))
_HASH_OUT = _hash_constants(_INIT_B, _MULT_B, 2 * _POOL)


@cache
def _lane_constants(lanes: int) -> tuple[int, list[tuple[int, int]], list[tuple[int, int]], list[int]]:
    """For ``lanes`` seeds packed one per 64-bit lane: the 32-bit mask, the hash constants repeated in every lane,
    and the pool words that hash the zero padding of a one-word seed (the same for every seed)."""
    ones = int.from_bytes(b"\x01\0\0\0\0\0\0\0" * lanes, "little")

    def zero_word(xor: int, mult: int) -> int:
        value = (xor * mult) & 0xFFFFFFFF
        return (value ^ (value >> 16)) * ones

    return (
        0xFFFFFFFF * ones,
        [(xor * ones, mult) for xor, mult in _HASH_POOL],
        [(xor * ones, mult) for xor, mult in _HASH_OUT],
        [zero_word(*pair) for pair in _HASH_POOL[1:_POOL]],
    )


def _seed_words(seeds: list[int]) -> np.ndarray:
    """``SeedSequence(s).generate_state(4, np.uint64)`` for every seed ``s < 2**32``, as rows of a (seeds, 4) array.

    All seeds at once: each Python int below holds one 64-bit lane per seed with a 32-bit value in it, so one
    multiply, xor or shift steps the hash of every seed (a lane's 32-bit product fits its lane; the mask after each
    step drops what a shift brought down from the next lane). ~40 such steps replace numpy's per-seed Python loop.
    """
    mask, pool_hash, out_hash, zero_words = _lane_constants(len(seeds))
    xor, mult = pool_hash[0]
    value = ((int.from_bytes(np.asarray(seeds, "<u8").tobytes(), "little") ^ xor) * mult) & mask
    pool = [(value ^ (value >> 16)) & mask, *zero_words]
    for (src, dst), (xor, mult) in zip(_MIX_PAIRS, pool_hash[_POOL:], strict=True):
        hashed = ((pool[src] ^ xor) * mult) & mask
        hashed = (hashed ^ (hashed >> 16)) & mask
        value = (((pool[dst] * _MIX_L) & mask) + ((hashed * _MIX_NEG_R) & mask)) & mask
        pool[dst] = (value ^ (value >> 16)) & mask
    halves = []
    for i, (xor, mult) in enumerate(out_hash):
        value = ((pool[i % _POOL] ^ xor) * mult) & mask
        halves.append((value ^ (value >> 16)) & mask)
    # 64-bit words: the low half first, as numpy views its 32-bit output
    words = [(halves[2 * i] | (halves[2 * i + 1] << 32)).to_bytes(8 * len(seeds), "little") for i in range(_POOL)]
    return np.frombuffer(b"".join(words), "<u8").reshape(_POOL, len(seeds)).T.astype(np.uint64, order="C")


class _SeedWords(ISpawnableSeedSequence):
    """A ``SeedSequence(seed)`` whose PCG64 seed words were computed in a batch. PCG64 reads only those words; any
    other use (``spawn``, ``entropy``, pickling) goes to a real SeedSequence of the seed, built on first use."""

    __slots__ = ("seed", "words", "_sequence")

    def __init__(self, seed: int, words: np.ndarray) -> None:
        self.seed, self.words, self._sequence = seed, words, None

    def sequence(self) -> np.random.SeedSequence:
        if self._sequence is None:
            self._sequence = np.random.SeedSequence(self.seed)
        return self._sequence

    def generate_state(self, n_words: int, dtype: Any = np.uint32) -> np.ndarray:
        if n_words == _POOL and dtype is np.uint64:
            return self.words
        return self.sequence().generate_state(n_words, dtype)

    def spawn(self, n_children: int) -> list[np.random.SeedSequence]:
        return self.sequence().spawn(n_children)

    def __getattr__(self, name: str) -> Any:  # entropy, spawn_key, pool, state, ...
        return getattr(self.sequence(), name)

    def __reduce__(self) -> Any:
        return self.sequence().__reduce__()

    def __repr__(self) -> str:
        return repr(self.sequence())


def seeded_generators(seeds: Sequence[int]) -> list[np.random.Generator]:
    """``[seeded_generator(s) for s in seeds]``, with the SeedSequence hashes of the seeds below 2**32 computed
    together when there are several (a reset of many slots): about a third of numpy's cost per generator."""
    seeds = [int(seed) for seed in seeds]
    batched = [i for i, seed in enumerate(seeds) if seed < _WORD]
    if len(batched) < _BATCH_SEEDING_FROM:
        return [seeded_generator(seed) for seed in seeds]
    generators = [None] * len(seeds)
    for i, words in zip(batched, _seed_words([seeds[i] for i in batched]), strict=True):
        generators[i] = np.random.Generator(np.random.PCG64(_SeedWords(seeds[i], words)))
    return [seeded_generator(seed) if rng is None else rng for seed, rng in zip(seeds, generators, strict=True)]


def _pcg64(rng: np.random.Generator, user: str) -> np.random.PCG64:
    """The generator's PCG64 (the only bit generator whose stream these classes reproduce)."""
    if not isinstance(rng.bit_generator, np.random.PCG64):
        raise TypeError(f"{user} reproduces PCG64 streams; got {type(rng.bit_generator).__name__}")
    return rng.bit_generator


def _rewind(bit_generator: np.random.PCG64, saved: dict, outputs: int, has_half: bool, half: int) -> None:
    """Put the generator ``outputs`` 64-bit outputs past the ``saved`` state, holding the leftover high half
    ``half`` if ``has_half`` (what numpy's one-by-one calls would have left)."""
    state = dict(saved)
    state["has_uint32"], state["uinteger"] = int(has_half), half
    bit_generator.state = state  # random_raw below advances the 64-bit state and keeps this half
    if outputs:
        bit_generator.random_raw(outputs)


class BoundedDraws:
    """``rng.integers(0, high)`` values (so also ``rng.choice`` of lists) one by one, from words drawn in bulk.

    Why it is exact: for ``high <= 2**32`` numpy draws a bounded int with Lemire's method on 32-bit words: one word,
    unless a (very rare) biased product asks for another, and no word at all for ``high == 1``. PCG64 hands out
    the low, then the high half of each 64-bit output and keeps an unused high half in its state
    (``has_uint32``/``uinteger``). Emulating both on bulk words gives numpy's values and numpy's generator state.

    Two ways to get the words (both may be used on one object):

    * exact: ``reserve(n)`` draws n words that ``below`` will certainly use (each call with ``high > 1`` uses at
      least one); if they run short (a rejection), more are drawn one by one. The generator is never ahead, so
      nothing is rewound. With ``fresh=True`` (a generator that has drawn nothing, so holds no leftover half) the
      generator's state need not even be read.
    * read-ahead: when the number of draws is not known in advance, ``read_ahead`` (also called by ``below`` when
      no words are left) fetches a block of 64-bit outputs; :meth:`close` then rewinds the generator to just after
      the words that were used. Callers with a hot loop may read ``words[used]`` themselves (advancing ``used``)
      after making sure, with ``read_ahead``, that enough words are there.

    Call :meth:`close` after the last draw.
    """

    BLOCK = 48  # 64-bit outputs fetched per read-ahead (most Mystery Path levels need one block)

    __slots__ = ("rng", "bit_generator", "words", "used", "buffered", "_state", "saved", "mark")

    def __init__(self, rng: np.random.Generator, reserve: int = 0, fresh: bool = False) -> None:
        self.rng, self.bit_generator = rng, _pcg64(rng, "BoundedDraws")
        self.words: list[int] = []
        self.used = 0
        # The generator's state while nothing has been drawn here (read-ahead reuses it), and whether it holds a
        # leftover half word that numpy would hand out next.
        self._state = None if fresh else self.bit_generator.state
        self.buffered = False if fresh else bool(self._state["has_uint32"])
        self.saved: dict | None = None  # the state before the first read-ahead: close() rewinds from it
        self.mark = 0  # words obtained exactly, before the first read-ahead
        self.reserve(reserve)

    def _word(self) -> int:
        """One word through numpy itself, which keeps any leftover half in the bit generator."""
        self.buffered = not self.buffered
        self._state = None
        return next_word(self.rng)

    def reserve(self, count: int) -> None:
        """Make ``count`` more words available, drawing only words that will certainly be used (see the class)."""
        if count <= 0:
            return
        if self.saved is not None:  # reading ahead already: the generator is ahead anyway
            while len(self.words) - self.used < count:
                self.read_ahead()
            return
        if self.buffered:
            self.words.append(self._word())
            count -= 1
        if count >= 2:
            self._state = None
            raw = self.bit_generator.random_raw(count // 2)
            self.words += raw.astype("<u8", copy=False).view("<u4").tolist()  # low half first, like next_uint32
        if count % 2:
            self.words.append(self._word())

    def read_ahead(self, outputs: int = BLOCK) -> None:
        """Append the words of the next ``outputs`` 64-bit outputs (low half first); :meth:`close` rewinds."""
        if self.saved is None:
            self.saved = self._state if self._state is not None else self.bit_generator.state
            self.mark = len(self.words)
            if self.saved["has_uint32"]:  # the leftover half comes first
                self.words.append(self.saved["uinteger"])
        self.words += self.bit_generator.random_raw(outputs).astype("<u8", copy=False).view("<u4").tolist()

    def below(self, high: int) -> int:
        """The value of ``rng.integers(0, high)``, for ``1 <= high <= 2**32``."""
        if high <= 1:
            return 0  # numpy draws nothing when there is only one choice
        words = self.words
        while True:
            if self.used == len(words):
                if self.saved is None:
                    words.append(self._word())
                else:
                    self.read_ahead()
            product = words[self.used] * high
            self.used += 1
            low_bits = product & (_WORD - 1)
            # Lemire: a low part below (2**32 - high) % high would bias the result, so numpy draws again
            if low_bits >= high or low_bits >= (_WORD - high) % high:
                return product >> 32

    def below_many(self, high: int, count: int) -> list[int]:
        """The values of ``count`` calls ``rng.integers(0, high)``, fetching words by read-ahead when needed."""
        if high <= 1:
            return [0] * count
        words, used, out = self.words, self.used, []
        threshold = (_WORD - high) % high
        while len(out) < count:
            if used == len(words):
                self.used = used
                self.read_ahead()
            product = words[used] * high
            used += 1
            low_bits = product & (_WORD - 1)
            if low_bits >= high or low_bits >= threshold:
                out.append(product >> 32)
        self.used = used
        return out

    def close(self) -> None:
        """Check that every exactly drawn word was used, and rewind whatever was read ahead but not used."""
        if self.used < self.mark or (self.saved is None and self.used != len(self.words)):
            raise RuntimeError(f"{len(self.words) - self.used} reserved random words were not used")
        if self.saved is None:
            return
        buffered = int(self.saved["has_uint32"])  # the leftover half was the first word read ahead
        read = self.used - self.mark  # words used since the first read-ahead
        if read == 0 and len(self.words) == self.mark + buffered:
            return  # nothing was read or used: the generator is where it was
        from_outputs = read - buffered
        outputs = (from_outputs + 1) // 2 if from_outputs > 0 else 0
        if from_outputs > 0:  # an odd count leaves the last output's high half to hand out next
            half = self.words[self.mark + buffered + 2 * outputs - 1]
            _rewind(self.bit_generator, self.saved, outputs, bool(from_outputs % 2), half)
        else:  # the saved leftover half was used, or nothing was
            _rewind(self.bit_generator, self.saved, 0, bool(buffered and not read), self.saved["uinteger"])


class DirectDraws:
    """``rng.integers(low, high)`` and ``rng.uniform(low, high)`` values, exactly numpy's, in any order, at a
    fraction of numpy's per-call cost: the bit generator's own C functions (``next_uint32``, ``next_double`` of
    numpy's public ``bitgen_t`` interface, the functions numpy's bounded ints and doubles call) are called directly,
    so the generator's state, including a kept half word, evolves exactly as under numpy's calls and nothing has
    to be read, saved or rewound.

    Why it is exact: numpy draws a bounded int (range up to 2**32) with Lemire's method on ``next_uint32`` words,
    redrawing a biased word, and a double in [0, 1) with ``next_double``; ``uniform`` is ``low + (high - low) *
    double``. Without the C functions (``bitgen_t`` not as expected) the draws go through numpy itself.
    """

    __slots__ = ("rng", "state", "next_uint32", "next_double")

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng  # (keeps the bit generator, and so its state, alive)
        self.state, self.next_uint32, self.next_double = _bitgen_functions(rng.bit_generator)

    def integers(self, low: float, high: float) -> int:
        """The value of ``rng.integers(low, high)`` (float bounds are truncated, as numpy does)."""
        low = int(low)
        span = int(high) - low
        if span <= 1 or span > _WORD:
            if span == 1:
                return low  # numpy draws nothing when there is only one choice
            raise ValueError(f"integers({low}, {high}): expected 1 <= high - low <= 2**32")
        next_uint32 = self.next_uint32
        if next_uint32 is None:
            return int(self.rng.integers(low, low + span))
        while True:
            product = next_uint32(self.state) * span
            low_bits = product & 0xFFFFFFFF
            # Lemire: a low part below (2**32 - span) % span would bias the result, so numpy draws again
            if low_bits >= span or low_bits >= (_WORD - span) % span:
                return low + (product >> 32)

    def uniform(self, low: float, high: float) -> float:
        """The value of ``rng.uniform(low, high)``."""
        low, high = float(low), float(high)
        if self.next_double is None:
            return float(self.rng.uniform(low, high))
        return low + (high - low) * self.next_double(self.state)
