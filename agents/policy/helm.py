"""A HELM-like frozen branch: observations become pseudo-tokens of a frozen language model with a step memory.

What the branch computes, for every environment step of every slot (Paischer et al., ICML 2022, "HELM"):

1. The observation (H, W, C, uint8) is turned grey by averaging its channels (as the original does; not the ITU-R
   601 luma that frame stacking uses) and flattened to ``o`` of size ``H * W``.
2. A fixed random projection ``P`` (``d x H*W``, entries N(0, 1/d), drawn from ``seed``, never trained) gives the
   query ``q = P o`` in the language model's embedding width ``d``. The scale of ``o`` does not matter: the
   retrieval below only sees the direction of ``q``.
3. Frozen Hopfield retrieval over the model's token-embedding matrix ``E`` (``V x d``): the cosine similarity of
   ``q`` with every token embedding, a softmax with inverse temperature ``beta``, and the weighted sum of the
   embeddings, ``E^T softmax(beta * cos(q, E))``. The inverse norms of the rows of ``E`` are computed once at
   construction (no second copy of ``E``), so a step costs two ``(B, d) x (d, V)`` products. With a large ``beta``
   (the paper uses 1000) this is close to picking the nearest token embedding.
4. That pseudo-token embedding goes through the frozen causal transformer as ``inputs_embeds``, one token per
   environment step. The token attends to itself and to the last ``mem_len`` steps of the current episode, whose
   keys and values every layer keeps in a per-slot ring buffer (:class:`HelmMemory`): a step costs one token's
   forward, never a re-run of the window. This is Transformer-XL's memory with segments of one step: the keys of a
   past step at layer ``l`` were computed when that step was current, from its own window, so deeper layers see
   further back than ``mem_len`` (the same as a full forward over the episode with a sliding-window mask, which
   :meth:`HelmBranch.recompute_episode` does and the tests compare against).
5. The output is the transformer's last hidden state for the current token (after the model's final layer norm),
   width ``d``; the caller concatenates it with its trainable features. Nothing in the branch is trained: no
   parameter requires a gradient, the module stays in eval mode, and :meth:`HelmBranch.step` runs under
   ``torch.no_grad``. The original computes the output once per rollout step and stores it in the buffer; the PPO
   epochs read that cache.

Positions. A past step's keys are cached with the position they had when computed, so the position scheme must
survive a window that slides:

- rotary models (GPT-NeoX/Pythia, Llama, Qwen, ...): a token's position is its step index in the episode
  (0, 1, 2, ... without bound). Rotary attention depends only on the distance between query and key, so a sliding
  window needs no re-encoding; the distances seen are at most ``mem_len``, well inside the trained context. This is
  the closest match to Transformer-XL's relative encoding. Rotary angles are computed in float32: at step 10^5 the
  fastest-turning pair is off by about 0.006 rad, which is harmless.
- models with a learned absolute position table (GPT-2): the position is the step index while it fits in the table
  and then stays at the table's last entry (it saturates). After ``max_position_embeddings`` steps of one episode
  all new tokens share that position; order is then known only through which steps are still cached. Prefer a
  rotary model.
- other schemes (ALiBi, as in BLOOM, builds its bias from a padding mask) are refused with an error.

Language models. ``lm`` is ``"random"``, a local directory written by ``save_pretrained`` or a Hugging Face hub
name; a directory and a name go through the same ``AutoModelForCausalLM.from_pretrained`` call (only the base
model is kept: the output head is dropped). The model must expose ``get_input_embeddings()`` and accept
``inputs_embeds``, ``position_ids``, a 4-d float attention mask and a ``transformers`` ``Cache``. It is loaded in
float32. The attention mask is always the branch's own (causal, windowed, per slot), never the model's.

Recommended model. HELM's ``transfo-xl-wt103`` (18 layers, d = 1024, relative positions, 267 735-token vocabulary,
about 285M parameters, 1.14 GB in float32) no longer loads in current ``transformers`` (it was removed for its
``pickle`` loading). The recommended replacement is the Pythia family (GPT-NeoX architecture, trained on the Pile,
Apache-2.0), because its rotary positions act on query-key distances like Transformer-XL's relative encoding, so
the sliding step memory works with no position trick, and its 50 304-token vocabulary makes the retrieval over
``E`` five times cheaper than over TrXL's:

- ``EleutherAI/pythia-410m`` is the faithful choice for accelerator runs: d = 1024 as in TrXL (and as HELM's
  1024-wide query CNN), 24 layers (TrXL 18), 16 heads; about 405M parameters with untied input and output
  embeddings, of which the kept base model is about 354M (1.4 GB in float32);
- ``EleutherAI/pythia-160m`` (12 layers, d = 768, GPT-2 small's shape; base model about 124M parameters, 0.5 GB)
  is the one to use on a CPU: see the costs below.

GPT-2 (``gpt2``, same shape as pythia-160m) also loads, but its absolute positions saturate after 1024 steps of an
episode (see above). Larger, better-trained rotary models load too, but a large vocabulary is paid for at every
step: Qwen2.5-0.5B's 151 936 tokens make the retrieval alone three times as costly as over a 50k vocabulary.
A hub name needs the network on first use; where there is none, ``save_pretrained`` the model into a directory
elsewhere and pass that directory.

Random language model (a deviation). ``lm="random"`` builds, with no download, a GPT-NeoX (Pythia-shaped: rotary on
a quarter of each head, parallel residual, GELU MLP of width 4d) of ``random_layers`` layers, width
``random_width``, ``random_heads`` heads and ``random_vocab`` tokens, initialised by ``transformers`` (normal
weights, std 0.02) from ``seed`` and frozen. The same seed gives bit-identical weights on every run (same torch and
transformers versions, which ``constraints.txt`` pins); building it does not touch the global torch RNG. It keeps
HELM's mechanics (retrieval into a token table, a frozen causal transformer with a step memory) but loses the
pretrained language prior, so results with it measure the architecture only; report it as such.

Cost. Per step and batch of B slots: the projection is a ``(B, H*W) x (H*W, d)`` product, the retrieval two
``(B, d) x (d, V)`` products, the transformer one token through every layer plus attention over ``mem_len + 1``
cached keys per layer. The memory holds ``2 * layers * B * (mem_len + 1) * d`` float32 values (4.2 MB for the
default random model at B = 16, 152 MB at GPT-2-small size, 406 MB at pythia-410m size). Measured with
``scripts/benchmark_helm.py`` on this project's 2-core CPU (torch 2.13, 2 threads, B = 16, 84x84 observations,
mem_len 128, random weights of the given shape; best of 5-7 rounds of 10-20 steps, the machine being shared):

==========================================  =========  ==========  =========  ===========
shape (layers x width, vocabulary)          step (ms)  projection  retrieval  transformer
==========================================  =========  ==========  =========  ===========
2 x 256, 8 192                                    6.8         0.8        2.1          3.9
4 x 256, 8 192 (the ``random`` default)           8.8         0.8        1.8          6.2
12 x 768, 50 257 (GPT-2 small, pythia-160m)       116         2.5         48           66
24 x 1024, 50 304 (pythia-410m)                   287         3.9         72          211
==========================================  =========  ==========  =========  ===========

At GPT-2-small size the retrieval over 50k tokens costs almost as much as the 12 layers: both stream their
weights (154 MB of ``E``, twice; 340 MB of layers) once per step, so a step grows less than B: at B = 32 it took
156 ms (the default random model 11.7 ms).

Checkpoints. The branch is rebuilt from its arguments (``lm``, ``seed`` and the sizes), so it adds nothing to a
``state_dict`` and :meth:`~torch.nn.Module.load_state_dict` leaves it as built; store :meth:`HelmBranch.fingerprint`
with a checkpoint to check that a resumed run rebuilt the same weights. The memory is not checkpointed either:
replaying each slot's current episode through :meth:`HelmBranch.step` rebuilds it, bit for bit at the same batch
size (what the other slots hold does not matter), to float rounding otherwise (e.g. one slot replayed alone and
copied in with :meth:`HelmMemory.load_slot`).
"""

from __future__ import annotations

import functools
import hashlib
import os
from typing import Any

import numpy as np
import torch
from torch import Tensor, nn
from torch.nn import functional as F

RANDOM_LM = "random"
INSTALL_HINT = 'pip install -e ".[helm]"'
# Leaf names of learned absolute position tables in transformers models (GPT-2: wpe; OPT: embed_positions).
_ABSOLUTE_POSITION_TABLES = ("wpe", "embed_positions", "position_embeddings")


def _import_transformers() -> Any:
    """The ``transformers`` package, imported only when a branch is built."""
    try:
        import transformers
    except ImportError as error:
        raise ImportError(
            f"the HELM branch needs the optional dependency transformers; install it with {INSTALL_HINT}"
        ) from error
    return transformers


def _derived_seeds(seed: int) -> tuple[int, int]:
    """Two independent 63-bit seeds from ``seed``: one for the projection, one for the random language model."""
    children = np.random.SeedSequence(seed).spawn(2)
    return tuple(int(child.generate_state(1, np.uint64)[0]) >> 1 for child in children)  # type: ignore[return-value]


@functools.cache
def _ring_cache_classes() -> tuple[type, type]:
    """The ``transformers`` cache classes over a :class:`HelmMemory` (defined lazily: transformers is optional)."""
    from transformers.cache_utils import Cache, CacheLayerMixin

    class RingLayer(CacheLayerMixin):
        """One layer's ring buffer: ``update`` writes the current token at each slot's ring index, in place."""

        is_sliding = False

        def __init__(self, keys: Tensor, values: Tensor, rows: Tensor, slots: Tensor) -> None:
            super().__init__()
            self.keys, self.values = keys, values
            self.rows, self.slots = rows, slots
            self.is_initialized = True

        def lazy_initialization(self, key_states: Tensor, value_states: Tensor) -> None:
            return None

        def update(self, key_states: Tensor, value_states: Tensor, *args: Any, **kwargs: Any) -> tuple[Tensor, Tensor]:
            if key_states.shape[-2] != 1:
                raise ValueError("the HELM memory takes one token per step")
            self.keys[self.rows, :, self.slots] = key_states[:, :, 0]
            self.values[self.rows, :, self.slots] = value_states[:, :, 0]
            return self.keys, self.values

        def get_mask_sizes(self, query_length: int) -> tuple[int, int]:
            return self.keys.shape[-2], 0

        def get_seq_length(self) -> int:
            return self.keys.shape[-2]

        def get_max_length(self) -> int:
            return self.keys.shape[-2]

    class RingCache(Cache):
        """A ``Cache`` whose layers write into the ring buffers of a :class:`HelmMemory`."""

        def __init__(self, memory: HelmMemory, slots: Tensor) -> None:
            rows = torch.arange(memory.batch, device=slots.device)
            layers = [RingLayer(k, v, rows, slots) for k, v in zip(memory.keys, memory.values, strict=True)]
            super().__init__(layers=layers)

    return RingLayer, RingCache


class HelmMemory:
    """The step memory of a batch of environment slots, owned by the caller (one per batch of environments).

    Per layer of the language model, ``keys[l]`` and ``values[l]`` are ring buffers of shape
    ``(batch, kv_heads, mem_len + 1, head_dim)``: slot ``b``'s step ``t`` of the current episode sits at ring index
    ``t % (mem_len + 1)``, so the ring holds the last ``mem_len`` steps plus the current one. ``steps[b]`` counts the
    steps of slot ``b``'s current episode already in the memory (its next step's position); ring entries outside the
    last ``min(steps, mem_len)`` steps are masked out of the attention, so a reset only sets ``steps`` to 0 and
    leaves the stale keys where they are. Slots never see each other's entries.
    """

    def __init__(self, keys: list[Tensor], values: list[Tensor], steps: Tensor, mem_len: int) -> None:
        self.keys = keys
        self.values = values
        self.steps = steps
        self.mem_len = mem_len

    @property
    def batch(self) -> int:
        """Number of environment slots."""
        return int(self.steps.shape[0])

    @property
    def device(self) -> torch.device:
        """Where the buffers live."""
        return self.steps.device

    @property
    def lengths(self) -> Tensor:
        """``(batch,)`` number of past steps each slot's next step attends to (at most ``mem_len``)."""
        return self.steps.clamp(max=self.mem_len)

    def reset(self, mask: Tensor) -> None:
        """Forget the episode of every slot where ``mask`` (``(batch,)`` bool) is true; O(batch), no copy."""
        self.steps.masked_fill_(mask.to(device=self.steps.device, dtype=torch.bool), 0)

    def load_slot(self, slot: int, source: HelmMemory, source_slot: int = 0) -> None:
        """Make ``slot`` an exact copy of ``source``'s ``source_slot`` (e.g. an episode replayed alone on resume)."""
        if source.mem_len != self.mem_len or len(source.keys) != len(self.keys):
            raise ValueError("the two memories belong to different branches")
        for mine, theirs in zip((*self.keys, *self.values), (*source.keys, *source.values), strict=True):
            mine[slot].copy_(theirs[source_slot])
        self.steps[slot] = source.steps[source_slot]

    def nbytes(self) -> int:
        """Bytes held by the key/value buffers."""
        return sum(t.numel() * t.element_size() for t in (*self.keys, *self.values))


class HelmBranch(nn.Module):
    """HELM's frozen branch: observation -> random projection -> Hopfield retrieval -> frozen causal LM with memory.

    Frozen: no parameter requires grad; the module stays in eval mode (``train()`` is a no-op) and contributes
    nothing to ``state_dict`` (it is rebuilt from its arguments). See the module docstring for the computation, the
    position scheme and the recommended models.

    Args:
        image_shape: ``(H, W, C)`` of the observations.
        lm: ``"random"``, a local directory holding a ``transformers`` causal LM, or a hub model name.
        beta: inverse temperature of the retrieval softmax (HELM 100, the Memory Gym paper 1000).
        mem_len: number of past steps of the episode the current step attends to.
        seed: seed of the projection and of the random language model.
        random_layers, random_width, random_heads, random_vocab: size of the ``"random"`` language model.
    """

    output_size: int

    def __init__(
        self,
        image_shape: tuple[int, int, int],
        lm: str = RANDOM_LM,
        beta: float = 1000.0,
        mem_len: int = 128,
        seed: int = 0,
        random_layers: int = 4,
        random_width: int = 256,
        random_heads: int = 4,
        random_vocab: int = 8192,
    ) -> None:
        super().__init__()
        if len(image_shape) != 3:
            raise ValueError(f"image_shape must be (H, W, C), got {image_shape}")
        if mem_len < 1:
            raise ValueError(f"mem_len must be at least 1, got {mem_len}")
        self.image_shape = tuple(int(s) for s in image_shape)
        self.lm_name = lm
        self.beta = float(beta)
        self.mem_len = int(mem_len)
        self.seed = int(seed)
        projection_seed, lm_seed = _derived_seeds(self.seed)

        self.lm = _load_language_model(lm, lm_seed, random_layers, random_width, random_heads, random_vocab)
        self.position_limit = _position_limit(self.lm)
        embeddings = self.lm.get_input_embeddings().weight
        self.output_size = width = int(embeddings.shape[1])
        if int(getattr(self.lm.config, "hidden_size", width)) != width:
            raise ValueError(f"lm={lm!r}: embedding width {width} differs from the hidden size")

        pixels = self.image_shape[0] * self.image_shape[1]
        generator = torch.Generator().manual_seed(projection_seed)
        projection = torch.randn(width, pixels, generator=generator) / width**0.5
        self.register_buffer("projection", projection, persistent=False)
        norms = embeddings.detach().norm(dim=-1).clamp_min(1e-12)
        self.register_buffer("inverse_norms", norms.reciprocal(), persistent=False)

        self.requires_grad_(False)
        super().train(False)
        self._kv_shapes = self._probe_cache_shapes()
        self.register_state_dict_post_hook(_drop_own_state)
        self.register_load_state_dict_pre_hook(_fill_own_state)

    # -- frozen module ---------------------------------------------------------------------------------------------
    def train(self, mode: bool = True) -> HelmBranch:
        """Stays in eval mode whatever ``mode`` is (dropout must never switch on in a frozen branch)."""
        return super().train(False)

    @property
    def token_embeddings(self) -> Tensor:
        """The language model's token-embedding matrix ``E`` (``V x d``)."""
        return self.lm.get_input_embeddings().weight

    def fingerprint(self) -> str:
        """A short SHA-256 of the projection and the language model's weights, to check a rebuilt branch."""
        digest = hashlib.sha256()
        tensors = [("projection", self.projection), *sorted(self.lm.state_dict().items())]
        for name, tensor in tensors:
            digest.update(name.encode())
            digest.update(str(tuple(tensor.shape)).encode())
            digest.update(tensor.detach().cpu().contiguous().view(-1).view(torch.uint8).numpy())
        return digest.hexdigest()[:16]

    # -- the pieces ------------------------------------------------------------------------------------------------
    def project(self, images: Tensor) -> Tensor:
        """``(B, H, W, C)`` uint8 observations -> ``(B, d)`` queries: channel mean, flatten, random projection."""
        if tuple(images.shape[1:]) != self.image_shape:
            raise ValueError(f"expected images of shape (B, {self.image_shape}), got {tuple(images.shape)}")
        grey = images.to(self.projection.dtype).mean(dim=-1).flatten(1)
        return grey @ self.projection.T

    def retrieve(self, queries: Tensor) -> Tensor:
        """Hopfield retrieval ``E^T softmax(beta * cos(q, E))`` of ``(B, d)`` queries -> ``(B, d)`` embeddings."""
        similarity = (F.normalize(queries, dim=-1) @ self.token_embeddings.T) * self.inverse_norms
        weights = torch.softmax(self.beta * similarity, dim=-1)
        return weights @ self.token_embeddings

    def positions(self, steps: Tensor) -> Tensor:
        """Position ids of tokens at episode step ``steps`` (saturating for absolute position tables)."""
        return steps if self.position_limit is None else steps.clamp(max=self.position_limit - 1)

    # -- memory and stepping ---------------------------------------------------------------------------------------
    def initial_memory(self, batch: int, device: torch.device | str | None = None) -> HelmMemory:
        """An empty memory for ``batch`` environment slots (zeroed buffers: masked entries must be finite)."""
        device = self.projection.device if device is None else torch.device(device)
        window = self.mem_len + 1
        dtype = self.projection.dtype
        keys = [torch.zeros(batch, h, window, dk, dtype=dtype, device=device) for h, dk, _ in self._kv_shapes]
        values = [torch.zeros(batch, h, window, dv, dtype=dtype, device=device) for h, _, dv in self._kv_shapes]
        steps = torch.zeros(batch, dtype=torch.long, device=device)
        return HelmMemory(keys, values, steps, self.mem_len)

    @torch.no_grad()
    def step(self, images: Tensor, memory: HelmMemory, episode_start: Tensor) -> Tensor:
        """One environment step of every slot.

        Args:
            images: ``(B, H, W, C)`` uint8 observations.
            memory: the slots' memory (from :meth:`initial_memory`), updated in place.
            episode_start: ``(B,)`` bool; those slots' memory is cleared before this step.

        Returns:
            ``(B, output_size)`` float32: the language model's last hidden state of this step's token.
        """
        if images.shape[0] != memory.batch:
            raise ValueError(f"{images.shape[0]} images for a memory of {memory.batch} slots")
        memory.reset(episode_start)
        steps = memory.steps
        window = self.mem_len + 1
        embeds = self.retrieve(self.project(images))[:, None]
        ring = torch.arange(window, device=steps.device)
        visible = ring[None, :] <= steps[:, None]  # all of the ring once steps >= mem_len
        mask = torch.zeros(visible.shape, dtype=embeds.dtype, device=steps.device)
        mask = mask.masked_fill_(~visible, float("-inf"))[:, None, None, :]
        _, ring_cache = _ring_cache_classes()
        out = self.lm(
            inputs_embeds=embeds,
            attention_mask=mask,
            position_ids=self.positions(steps)[:, None],
            past_key_values=ring_cache(memory, steps % window),
            use_cache=True,
        )
        memory.steps += 1
        return out.last_hidden_state[:, 0].float()

    @torch.no_grad()
    def recompute_episode(self, images: Tensor) -> Tensor:
        """The outputs of one episode's steps, ``(T, H, W, C)`` -> ``(T, output_size)``, in one full forward.

        Every token attends to itself and the ``mem_len`` steps before it (a sliding-window causal mask), with the
        same positions as :meth:`step`; equal to stepping a fresh memory through the episode, up to float rounding.
        Cost is quadratic in ``T``: for checks and tests, not for rollouts.
        """
        length = images.shape[0]
        embeds = self.retrieve(self.project(images))[None]
        t = torch.arange(length, device=embeds.device)
        lag = t[:, None] - t[None, :]
        visible = (lag >= 0) & (lag <= self.mem_len)
        mask = torch.zeros(visible.shape, dtype=embeds.dtype, device=embeds.device)
        mask = mask.masked_fill_(~visible, float("-inf"))[None, None]
        out = self.lm(inputs_embeds=embeds, attention_mask=mask, position_ids=self.positions(t)[None], use_cache=False)
        return out.last_hidden_state[0].float()

    def _probe_cache_shapes(self) -> list[tuple[int, int, int]]:
        """Per layer ``(kv_heads, key_dim, value_dim)``, read off one dummy token's cache."""
        from transformers.cache_utils import DynamicCache

        cache = DynamicCache()
        embeds = torch.zeros(1, 1, self.output_size, dtype=self.projection.dtype)
        with torch.no_grad():
            self.lm(inputs_embeds=embeds, position_ids=torch.zeros(1, 1, dtype=torch.long), past_key_values=cache)
        shapes = []
        for layer in cache.layers:
            keys, values = getattr(layer, "keys", None), getattr(layer, "values", None)
            if keys is None or values is None or keys.ndim != 4:
                raise ValueError(
                    f"lm={self.lm_name!r}: its cache layer {type(layer).__name__} is not a key/value cache"
                )
            shapes.append((int(keys.shape[1]), int(keys.shape[-1]), int(values.shape[-1])))
        if not shapes:
            raise ValueError(f"lm={self.lm_name!r} filled no key/value cache")
        return shapes


def _drop_own_state(module: nn.Module, state_dict: dict[str, Tensor], prefix: str, local_metadata: Any) -> None:
    """State-dict hook: the branch is rebuilt from its arguments, so none of its tensors are saved."""
    for key in [k for k in state_dict if k.startswith(prefix)]:
        del state_dict[key]


def _fill_own_state(module: nn.Module, state_dict: dict[str, Tensor], prefix: str, *args: Any) -> None:
    """Load pre-hook: keys the branch did not save are filled with its own tensors, so a strict load succeeds."""
    for name, tensor in module.lm.state_dict(keep_vars=True).items():
        state_dict.setdefault(f"{prefix}lm.{name}", tensor)


def _load_language_model(lm: str, seed: int, layers: int, width: int, heads: int, vocab: int) -> nn.Module:
    """The frozen base model (no output head) of ``lm``, in float32."""
    transformers = _import_transformers()
    if lm == RANDOM_LM:
        config = transformers.GPTNeoXConfig(
            vocab_size=vocab,
            hidden_size=width,
            num_hidden_layers=layers,
            num_attention_heads=heads,
            intermediate_size=4 * width,
            hidden_dropout=0.0,
            attention_dropout=0.0,
            max_position_embeddings=2048,
        )
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(seed)
            return transformers.AutoModel.from_config(config, dtype=torch.float32)
    choices = f"valid values: {RANDOM_LM!r}, a local directory holding a transformers causal LM, or a hub model name"
    if not isinstance(lm, str) or not lm:
        raise ValueError(f"lm={lm!r} is not a model; {choices}")
    try:
        model = transformers.AutoModelForCausalLM.from_pretrained(lm, dtype=torch.float32)
    except (OSError, ValueError, KeyError) as error:
        where = "a local directory" if os.path.isdir(lm) else "no such local directory, nor a loadable hub model"
        raise ValueError(f"lm={lm!r} could not be loaded ({where}: {error}); {choices}") from error
    return model.base_model


def _position_limit(model: nn.Module) -> int | None:
    """``None`` for a rotary model (unbounded positions); the table size for learned absolute positions."""
    for module in model.modules():
        if "rotary" in type(module).__name__.lower():
            return None
    for name, module in model.named_modules():
        if isinstance(module, nn.Embedding) and name.rsplit(".", 1)[-1] in _ABSOLUTE_POSITION_TABLES:
            return int(getattr(model.config, "max_position_embeddings", module.num_embeddings))
    raise ValueError(
        f"{type(model).__name__}: neither rotary nor learned absolute positions; the HELM branch supports those two"
    )
