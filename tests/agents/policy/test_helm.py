"""The HELM branch (agents/policy/helm.py): retrieval, frozenness, the step memory and its resets, loading of models."""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest
import torch
from torch import Tensor, nn

pytest.importorskip("transformers")

from agents.policy.helm import HelmBranch, HelmMemory  # noqa: E402

SHAPE = (12, 10, 3)
TINY = {"random_layers": 2, "random_width": 32, "random_heads": 4, "random_vocab": 256}


@pytest.fixture(scope="module")
def branch() -> HelmBranch:
    return HelmBranch(SHAPE, mem_len=4, seed=3, **TINY)


def images(steps: int, batch: int, seed: int = 0) -> Tensor:
    """``(steps, batch, H, W, C)`` random uint8 observations."""
    generator = torch.Generator().manual_seed(seed)
    return torch.randint(0, 256, (steps, batch, *SHAPE), dtype=torch.uint8, generator=generator)


def run(branch: HelmBranch, frames: Tensor, starts: Tensor, memory: HelmMemory | None = None) -> Tensor:
    """Step a memory through ``(T, B, ...)`` frames with ``(T, B)`` episode starts -> ``(T, B, d)``."""
    memory = branch.initial_memory(frames.shape[1], "cpu") if memory is None else memory
    return torch.stack([branch.step(frames[t], memory, starts[t]) for t in range(frames.shape[0])])


def banded_reference(model: nn.Module, embeds: Tensor, mem_len: int, positions: Tensor) -> Tensor:
    """Last hidden states of one episode ``(T, d)`` through ``model`` with a sliding-window causal mask."""
    t = torch.arange(embeds.shape[0])
    lag = t[:, None] - t[None, :]
    mask = torch.where((lag >= 0) & (lag <= mem_len), 0.0, float("-inf"))[None, None]
    with torch.no_grad():
        out = model(inputs_embeds=embeds[None], attention_mask=mask, position_ids=positions[None], use_cache=False)
    return out.last_hidden_state[0]


def test_large_beta_retrieves_the_nearest_token_embedding(branch: HelmBranch) -> None:
    table = branch.token_embeddings
    generator = torch.Generator().manual_seed(1)
    index = torch.randint(0, table.shape[0], (20,), generator=generator)
    queries = 3.0 * table[index] + 0.002 * torch.randn(20, table.shape[1], generator=generator)
    cosine = nn.functional.normalize(queries, dim=-1) @ nn.functional.normalize(table, dim=-1).T
    assert torch.equal(cosine.argmax(dim=-1), index)
    torch.testing.assert_close(branch.retrieve(queries), table[index], rtol=0, atol=1e-6)
    # and any query, with a large enough beta: its nearest token by cosine
    queries = torch.randn(20, table.shape[1], generator=generator)
    nearest = (nn.functional.normalize(queries, dim=-1) @ nn.functional.normalize(table, dim=-1).T).argmax(-1)
    sharp = HelmBranch(SHAPE, beta=1e7, mem_len=4, seed=3, **TINY)
    torch.testing.assert_close(sharp.retrieve(queries), table[nearest], rtol=0, atol=1e-6)
    # beta 0: the mean embedding
    flat = HelmBranch(SHAPE, beta=0.0, mem_len=4, seed=3, **TINY)
    torch.testing.assert_close(flat.retrieve(queries), table.mean(0).expand(20, -1), rtol=1e-5, atol=1e-6)


def test_projection_is_channel_mean_then_fixed_gaussian(branch: HelmBranch) -> None:
    frames = images(1, 4)[0]
    grey = frames.double().mean(-1).flatten(1)
    torch.testing.assert_close(
        branch.project(frames).double(), grey @ branch.projection.double().T, rtol=1e-5, atol=1e-4
    )
    width, pixels = branch.projection.shape
    assert (width, pixels) == (branch.output_size, SHAPE[0] * SHAPE[1])
    assert abs(branch.projection.var().item() * width - 1.0) < 0.1  # entries N(0, 1/d)


def test_frozen_under_an_optimizer_step(branch: HelmBranch) -> None:
    class Agent(nn.Module):
        def __init__(self) -> None:
            super().__init__()
            self.helm = branch
            self.head = nn.Linear(branch.output_size, 3)

    agent = Agent()
    agent.train()
    assert not branch.training and not any(m.training for m in branch.modules())
    assert all(not p.requires_grad for p in branch.parameters()) and len(list(branch.parameters())) > 0
    before = {k: v.clone() for k, v in branch.lm.state_dict().items()}
    projection = branch.projection.clone()
    head = agent.head.weight.detach().clone()
    optimizer = torch.optim.AdamW(agent.parameters(), lr=0.1, weight_decay=0.1)
    memory = branch.initial_memory(4, "cpu")
    frames = images(3, 4)
    for t in range(3):
        features = branch.step(frames[t], memory, torch.zeros(4, dtype=torch.bool))
        assert not features.requires_grad and features.dtype == torch.float32
        optimizer.zero_grad()
        agent.head(features).square().sum().backward()
        optimizer.step()
    assert all(p.grad is None for p in branch.parameters())
    assert all(torch.equal(v, before[k]) for k, v in branch.lm.state_dict().items())
    assert torch.equal(branch.projection, projection)
    assert not torch.equal(agent.head.weight, head)
    # the branch is rebuilt from its arguments: absent from the state dict, and a strict load leaves it as it is
    state = agent.state_dict()
    assert set(state) == {"head.weight", "head.bias"}
    agent.load_state_dict(state)
    assert all(torch.equal(v, before[k]) for k, v in branch.lm.state_dict().items())


def test_step_equals_a_fresh_recomputation_of_each_episode(branch: HelmBranch) -> None:
    steps, batch = 17, 3
    frames = images(steps, batch)
    starts = torch.zeros(steps, batch, dtype=torch.bool)
    starts[0] = True
    starts[6, 0] = starts[9, 1] = starts[10, 0] = True  # episodes of 6, 4 and 7 steps in slot 0
    outputs = run(branch, frames, starts)
    assert outputs.shape == (steps, batch, branch.output_size) and outputs.dtype == torch.float32
    for slot in range(batch):
        bounds = [*starts[:, slot].nonzero().flatten().tolist(), steps]
        for begin, end in zip(bounds[:-1], bounds[1:], strict=True):
            expected = branch.recompute_episode(frames[begin:end, slot])
            torch.testing.assert_close(outputs[begin:end, slot], expected, rtol=0, atol=1e-4)


def test_the_window_drops_steps_beyond_mem_len(branch: HelmBranch) -> None:
    steps = 13  # > 2 * (mem_len + 1): the ring wraps twice
    frames = images(steps, 1, seed=5)
    starts = torch.zeros(steps, 1, dtype=torch.bool)
    outputs = run(branch, frames, starts)[:, 0]
    embeds = branch.retrieve(branch.project(frames[:, 0]))
    positions = torch.arange(steps)
    expected = banded_reference(branch.lm, embeds, branch.mem_len, positions)
    torch.testing.assert_close(outputs, expected, rtol=0, atol=1e-4)
    unbounded = banded_reference(branch.lm, embeds, steps, positions)
    torch.testing.assert_close(outputs[: branch.mem_len + 1], unbounded[: branch.mem_len + 1], rtol=0, atol=1e-4)
    assert (outputs[-1] - unbounded[-1]).abs().max() > 1e-3  # the dropped steps mattered
    # an image seen more than mem_len steps ago no longer reaches layer 1; the oldest visible one does
    memory = branch.initial_memory(1, "cpu")
    assert memory.nbytes() > 0 and memory.lengths.tolist() == [0]
    run(branch, frames, starts, memory)
    assert memory.lengths.tolist() == [branch.mem_len] and memory.steps.tolist() == [steps]


def test_a_reset_slot_equals_a_fresh_memory_and_spares_the_others(branch: HelmBranch) -> None:
    steps, batch, reset_at = 12, 3, 7
    frames = images(steps, batch, seed=2)
    starts = torch.zeros(steps, batch, dtype=torch.bool)
    starts[0] = True
    plain = run(branch, frames, starts)
    starts[reset_at, 1] = True
    reset = run(branch, frames, starts)
    assert torch.equal(reset[:, [0, 2]], plain[:, [0, 2]])  # other slots: bit for bit
    assert torch.equal(reset[:reset_at], plain[:reset_at])
    fresh_frames = frames[reset_at:].clone()
    fresh_frames[:, [0, 2]] = images(steps - reset_at, 2, seed=9)  # whatever the other slots see
    fresh = run(branch, fresh_frames, torch.zeros(steps - reset_at, batch, dtype=torch.bool))
    assert torch.equal(reset[reset_at:, 1], fresh[:, 1])
    assert (reset[reset_at:, 1] - plain[reset_at:, 1]).abs().max() > 1e-3


def test_a_slot_replayed_alone_and_loaded_continues_the_episode(branch: HelmBranch) -> None:
    steps, batch, cut = 11, 3, 8
    frames = images(steps, batch, seed=6)
    starts = torch.zeros(steps, batch, dtype=torch.bool)
    starts[0] = True
    starts[2, 1] = True  # slot 1's episode began at step 2
    memory = branch.initial_memory(batch, "cpu")
    outputs = run(branch, frames, starts, memory)
    # rebuild the memory at step `cut` as a resume would: replay slot 1's episode alone, then load it
    resumed = branch.initial_memory(batch, "cpu")
    run(branch, frames[:cut], starts[:cut], resumed)
    alone = branch.initial_memory(1, "cpu")
    run(branch, frames[2:cut, 1:2], torch.zeros(cut - 2, 1, dtype=torch.bool), alone)
    resumed.reset(torch.tensor([False, True, False]))
    resumed.load_slot(1, alone)
    assert resumed.steps.tolist() == [cut, cut - 2, cut]
    continued = run(branch, frames[cut:], starts[cut:], resumed)
    torch.testing.assert_close(continued, outputs[cut:], rtol=0, atol=1e-5)


def tiny_causal_lm(kind: str) -> nn.Module:
    import transformers

    torch.manual_seed(0)
    common = {"vocab_size": 96, "hidden_size": 32, "num_hidden_layers": 2, "num_attention_heads": 4}
    if kind == "gpt_neox":
        config = transformers.GPTNeoXConfig(**common, intermediate_size=64)
    elif kind == "llama":  # rotary, grouped-query attention (2 key/value heads)
        config = transformers.LlamaConfig(**common, intermediate_size=64, num_key_value_heads=2)
    else:  # learned absolute positions, a table of 6: saturates within the test's episode
        config = transformers.GPT2Config(
            vocab_size=96,
            n_embd=32,
            n_layer=2,
            n_head=4,
            n_positions=6,
            attn_pdrop=0.0,
            resid_pdrop=0.0,
            embd_pdrop=0.0,
        )
    return transformers.AutoModelForCausalLM.from_config(config).eval()


@pytest.mark.parametrize("kind", ["gpt_neox", "llama", "gpt2"])
def test_lm_from_a_local_directory(kind: str, tmp_path: Path) -> None:
    model = tiny_causal_lm(kind)
    model.save_pretrained(tmp_path)
    loaded = HelmBranch(SHAPE, lm=str(tmp_path), beta=30.0, mem_len=3, seed=1)
    table = model.get_input_embeddings().weight.detach()
    assert torch.equal(loaded.token_embeddings, table)
    assert loaded.output_size == table.shape[1]
    assert loaded.position_limit == (6 if kind == "gpt2" else None)

    steps = 10
    frames = images(steps, 2, seed=4)
    starts = torch.zeros(steps, 2, dtype=torch.bool)
    outputs = run(loaded, frames, starts)
    # the reference: the saved model itself, with the retrieval written out here
    grey = frames[:, 0].float().mean(-1).flatten(1)
    cosine = nn.functional.normalize(grey @ loaded.projection.T, dim=-1) @ nn.functional.normalize(table, dim=-1).T
    embeds = torch.softmax(30.0 * cosine, dim=-1) @ table
    positions = torch.arange(steps).clamp(max=5) if kind == "gpt2" else torch.arange(steps)
    expected = banded_reference(model.base_model, embeds, 3, positions)
    torch.testing.assert_close(outputs[:, 0], expected, rtol=0, atol=1e-4)


def test_bad_lm_names_the_value_and_the_choices(tmp_path: Path) -> None:
    for bad in ["no-such-model-xyz", str(tmp_path / "missing"), str(tmp_path)]:
        with pytest.raises(ValueError, match="random") as raised:
            HelmBranch(SHAPE, lm=bad, mem_len=2)
        message = str(raised.value)
        assert repr(bad) in message and "local directory" in message and "hub" in message


def test_random_lm_is_seeded_bit_for_bit() -> None:
    rng = torch.get_rng_state()
    first = HelmBranch(SHAPE, mem_len=2, seed=11, **TINY)
    assert torch.equal(torch.get_rng_state(), rng)  # building the branch leaves the global RNG alone
    second = HelmBranch(SHAPE, mem_len=2, seed=11, **TINY)
    other = HelmBranch(SHAPE, mem_len=2, seed=12, **TINY)
    a, b, c = (m.lm.state_dict() for m in (first, second, other))
    assert all(torch.equal(a[k], b[k]) for k in a) and torch.equal(first.projection, second.projection)
    assert first.fingerprint() == second.fingerprint() != other.fingerprint()
    assert not torch.equal(a["embed_in.weight"], c["embed_in.weight"])
    assert not torch.equal(first.projection, other.projection)
    assert first.lm.config.num_hidden_layers == 2 and first.output_size == 32 and first.token_embeddings.shape[0] == 256


def test_transformers_is_imported_only_when_a_branch_is_built(monkeypatch: pytest.MonkeyPatch) -> None:
    import agents.policy.helm

    tree = ast.parse(Path(agents.policy.helm.__file__).read_text())
    top_level = [n for n in tree.body if isinstance(n, (ast.Import, ast.ImportFrom))]
    names = {a.name for n in top_level if isinstance(n, ast.Import) for a in n.names}
    names |= {n.module for n in top_level if isinstance(n, ast.ImportFrom)}
    assert "torch" in names and not any(name and name.split(".")[0] == "transformers" for name in names)
    monkeypatch.setitem(sys.modules, "transformers", None)
    with pytest.raises(ImportError, match=r'pip install -e "\.\[helm\]"'):
        HelmBranch(SHAPE, mem_len=2, **TINY)
