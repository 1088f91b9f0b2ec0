"""``run.precision``: every method trains and evaluates at fp32 and at bf16 (bfloat16 autocast in the training passes,
a bfloat16 copy of the weights acting), and the linear recurrences carry their state in fp32 under bf16."""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path

import pytest
import torch
from torch import nn

from agents.config import ModelConfig, config_from_dict
from agents.evaluation.loop import evaluate
from agents.memory import MEMORY_MODULES, build_memory
from agents.memory.scan import ScanMemory
from agents.training.trainer import Trainer
from scripts import benchmark_training

TINY = {
    "env": {"id": "ProofOfMemory-v0", "options": {"delay": 3}},
    "model": {"memory_size": 16, "hidden_size": 16, "vector_encoder_size": 8},
    "ppo": {"epochs": 1, "minibatches": 2},
    "run": {
        "total_steps": 2 * 16,
        "workers": 2,
        "worker_steps": 16,
        "seed": 3,
        "progress_bar": False,
        "torch_threads": 1,
        "checkpoint_interval": 0,
    },
    "eval": {"interval": 0},
}
TRXL = (
    "model.memory=trxl",
    "model.trxl.layers=1",
    "model.trxl.heads=2",
    "model.trxl.dim=16",
    "model.trxl.memory_length=3",
)
HELM = (  # a tiny random transformer: no download
    "model.helm.lm=random",
    "model.helm.mem_len=3",
    "model.helm.random_layers=2",
    "model.helm.random_width=32",
    "model.helm.random_vocab=64",
)
# every registered memory, the gated Transformer-XL, the frame stacks and HELM: method -> overrides of TINY
METHODS: dict[str, tuple[str, ...]] = {
    "ppo": ("model.memory=none",),
    "gru": ("model.memory=gru",),
    "lstm": ("model.memory=lstm",),
    "trxl": TRXL,
    "gtrxl": (*TRXL, "model.trxl.gating=true", "run.method=gtrxl"),
    "lru": ("model.memory=lru", "model.memory_layers=2"),
    "ffm": ("model.memory=ffm", "model.ffm.trace_size=4", "model.ffm.context_size=2"),
    "mamba": ("model.memory=mamba", "model.mamba.state_size=4"),
    "mamba2": ("model.memory=mamba2", "model.mamba2.head_dim=8", "model.mamba2.chunk_size=4"),
    "stack4": ("model.memory=none", "model.frame_stack=4"),
    "stack16": ("model.memory=none", "model.frame_stack=16"),
    "helm": ("model.memory=none", *HELM),
}
SCAN_MEMORIES = ("lru", "ffm", "mamba", "mamba2")


def test_every_registered_memory_is_trained_here() -> None:
    """A memory added to the registry must be added to METHODS too."""
    memories = {override.partition("=")[2] for overrides in METHODS.values() for override in overrides[:1]}
    assert memories == set(MEMORY_MODULES)


@pytest.mark.parametrize("precision", ["fp32", "bf16"])
@pytest.mark.parametrize("method", list(METHODS))
def test_one_update_trains_and_the_policy_evaluates(tmp_path: Path, method: str, precision: str) -> None:
    """One update (finite losses, changed weights: the memory's all) and an evaluation of the acting model."""
    config = config_from_dict(TINY, [*METHODS[method], f"run.precision={precision}"])
    trainer = Trainer(config, tmp_path)
    assert config.method == method and (trainer.rollout_model is not trainer.model) == (precision == "bf16")
    before = {name: weight.detach().clone() for name, weight in trainer.model.named_parameters()}
    metrics = trainer.train_update()
    losses = {key: value for key, value in metrics.items() if key.startswith("losses/")}
    assert {"losses/policy_loss", "losses/value_loss", "losses/entropy"} <= set(losses)
    assert all(math.isfinite(value) for value in losses.values()), losses
    changed = {name for name, weight in trainer.model.named_parameters() if not torch.equal(weight, before[name])}
    assert changed
    memory_weights = {name for name in before if name.startswith("memory.")}
    assert memory_weights <= changed or not memory_weights  # the memory itself trains, under bf16 too
    records = evaluate(trainer.rollout_model, trainer.helm, config, [100000, 100001], 2, device=trainer.device)
    assert len(records) == 4
    assert all(math.isfinite(record["return"]) and record["length"] > 0 for record in records)


def _decay_only(name: str) -> ScanMemory:
    """A two-block scan memory whose every projection (linear and convolution layers, LRU's B, C and D) is zero: its
    state only decays (h = a h, with the decays of its parameters), so fp32 and bf16 must give the same next state.
    Its weights are bfloat16 numbers, which a bf16 copy holds exactly."""
    config = ModelConfig(memory=name, memory_size=8, memory_layers=2)
    config.ffm.trace_size, config.ffm.context_size = 4, 2
    config.mamba.state_size = 4
    config.mamba2.head_dim, config.mamba2.chunk_size = 4, 4
    torch.manual_seed(0)
    memory = build_memory(config, 6)
    # Mamba's step size Delta = softplus(W delta + b) sets its decays: its bias b is kept
    step_sizes = [block.step_size for block in memory.blocks] if name == "mamba" else []
    with torch.no_grad():
        for module in memory.modules():
            if isinstance(module, nn.Linear | nn.Conv1d):
                module.weight.zero_()
                if module.bias is not None and not any(module is kept for kept in step_sizes):
                    module.bias.zero_()
        if name == "lru":
            for block in memory.blocks:
                for weight in (block.input_weight, block.output_weight, block.skip):
                    weight.zero_()
        for weight in memory.parameters():
            weight.copy_(weight.bfloat16().float())
    return memory


def _full_precision_state(memory: ScanMemory, slots: int) -> torch.Tensor:
    """Random states with fp32 values that bfloat16 cannot hold, except a convolution's window (its past inputs,
    which are bfloat16 activations under bf16)."""
    state = torch.randn(slots, *memory.state_shape, generator=torch.Generator().manual_seed(1))
    for layer, block in enumerate(memory.blocks):
        window = getattr(block, "conv_size", 0)
        state[:, layer, :window] = state[:, layer, :window].bfloat16().float()
    assert not torch.equal(state, state.bfloat16().float())
    return state


@pytest.mark.parametrize("name", SCAN_MEMORIES)
def test_a_bf16_acting_copy_decays_the_state_in_fp32(name: str) -> None:
    """One decision of a bfloat16 copy of the weights (how bf16 acts) gives the next state of the same weights in
    fp32: the recurrence is not computed on a bfloat16 state (8 bits of mantissa, lost at every decision)."""
    memory = _decay_only(name)
    state = _full_precision_state(memory, 3)
    features = torch.randn(3, 6)
    with torch.no_grad():
        _, expected = memory.step(features, state)
        _, carried = copy.deepcopy(memory).to(torch.bfloat16).step(features.bfloat16(), state)
    assert not torch.allclose(expected, state)  # it decays
    assert carried.dtype == torch.float32
    torch.testing.assert_close(carried, expected, rtol=1e-6, atol=1e-7)


@pytest.mark.parametrize("name", SCAN_MEMORIES)
def test_the_recurrence_under_bf16_autocast_runs_in_fp32(name: str) -> None:
    """A training pass under bfloat16 autocast (how bf16 trains) over sequences of 10 steps (Mamba-2: chunks of 4,
    so the state crosses chunk boundaries) ends in the state of the same pass in fp32."""
    memory = _decay_only(name)
    state = _full_precision_state(memory, 3)
    features = torch.randn(3, 10, 6)
    with torch.no_grad():
        _, expected = memory.run(features, state)
        with torch.autocast("cpu", dtype=torch.bfloat16):
            _, final = memory.run(features, state)
    assert not torch.allclose(expected, state)
    assert final.dtype == torch.float32
    torch.testing.assert_close(final, expected, rtol=1e-6, atol=1e-7)


@pytest.mark.parametrize("name", SCAN_MEMORIES)
def test_the_blocks_get_the_state_in_fp32_under_bf16(name: str) -> None:
    """The stored states (fp32) reach the blocks in fp32 both when a bf16 copy acts and in a training pass under
    autocast, whose features are bfloat16: widened inside a block, a state cast to bfloat16 first stays rounded."""
    memory = _decay_only(name)
    acting = copy.deepcopy(memory).to(torch.bfloat16)
    seen: list[torch.dtype] = []
    for model in (memory, acting):
        model.blocks[0].register_forward_pre_hook(lambda block, args: seen.append(args[1].dtype))
    state = _full_precision_state(memory, 3)
    with torch.no_grad():
        acting.step(torch.randn(3, 6).bfloat16(), state)
        mask = torch.tensor([[True, True, True], [True, False, False], [True, True, False]])
        with torch.autocast("cpu", dtype=torch.bfloat16):
            memory.sequences(torch.randn(6, 6).bfloat16(), state, mask)
    assert seen == [torch.float32, torch.float32]


@pytest.mark.slow
def test_the_training_benchmark_measures_lru_at_its_default_precision(tmp_path: Path) -> None:
    """scripts/benchmark_training.py's default precision is bf16: the LRU (a complex recurrence) is measured at it,
    in a process of its own (configs/mortar_mayhem_b_grid/lru.yaml at a tiny batch)."""
    out = tmp_path / "training.json"
    args = ["--env", "ProofOfMemory-v0", "--workers", "2", "--worker-steps", "8", "--epochs", "1", "--minibatches", "1"]
    args += ["--updates", "1", "--repeats", "1", "--threads", "1", "--methods", "lru", "--sb3", "no"]
    assert benchmark_training.main([*args, "--out", str(out)]) == 0
    record = json.loads(out.read_text())
    assert record["setting"]["precision"] == "bf16"
    for row in record["summary"]["median"]["methods"].values():
        assert row["end_to_end"] > 0 and row["bound"] > 0
