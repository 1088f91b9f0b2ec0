"""The memory registry: a memory is one file of agents/memory/. The registry's names and order, the config's
blocks and choices read from it, what the config, the figures, the sweep and the benchmarks name (no memory), a
package copy without a memory's file (every other memory works, its name is refused) and with one new file (it
trains by name, its block validated, with nothing else changed)."""

from __future__ import annotations

import ast
import dataclasses
import os
import shutil
import subprocess
import sys
import textwrap
import types
from pathlib import Path

import pytest

from agents.config import ConfigError, ModelConfig, config_from_dict
from agents.memory import MEMORY_MODULES, MEMORY_SPECS, Memory, MemorySpec, build_memory
from agents.memory import _collect as collect_specs
from agents.memory.base import DEFAULT_ORDER

ROOT = Path(__file__).resolve().parents[3]
BUILT_IN = ["none", "gru", "lstm", "trxl", "lru", "ffm", "mamba", "mamba2"]


def test_the_registry_holds_the_built_in_memories_in_a_fixed_order() -> None:
    assert list(MEMORY_SPECS) == list(MEMORY_MODULES) == BUILT_IN
    files = {name: spec.module for name, spec in MEMORY_SPECS.items()}
    assert files == {
        "none": "agents.memory.recurrent",
        "gru": "agents.memory.recurrent",
        "lstm": "agents.memory.recurrent",
        "trxl": "agents.memory.transformer",
        **{name: f"agents.memory.{name}" for name in ("lru", "ffm", "mamba", "mamba2")},
    }
    assert [spec.order for spec in MEMORY_SPECS.values()] == sorted(spec.order for spec in MEMORY_SPECS.values())
    assert max(spec.order for spec in MEMORY_SPECS.values()) < DEFAULT_ORDER, "a new file comes after them"
    assert [name for name, spec in MEMORY_SPECS.items() if spec.stateless] == ["none"]
    assert {name: dict(spec.variants) for name, spec in MEMORY_SPECS.items() if spec.variants} == {
        "trxl": {"gtrxl": "GTrXL-PPO"}
    }
    with_settings = [name for name, spec in MEMORY_SPECS.items() if spec.settings is not None]
    assert with_settings == ["trxl", "lru", "ffm", "mamba", "mamba2"]


def test_shared_machinery_exports_no_memory() -> None:
    import agents.memory.base
    import agents.memory.packed_gru
    import agents.memory.scan
    import agents.memory.ssm

    for module in (agents.memory.base, agents.memory.scan, agents.memory.ssm, agents.memory.packed_gru):
        assert not hasattr(module, "MEMORIES"), module.__name__


def test_the_model_block_takes_its_memory_blocks_from_the_registry() -> None:
    """Same keys, defaults and order as when the blocks were written into ModelConfig (the config.yaml of every
    run lists them so: a change would change every saved config)."""
    fields = [field.name for field in dataclasses.fields(ModelConfig)]
    assert fields == [
        *("encoder", "memory", "memory_size", "memory_layers", "memory_options", "hidden_size"),
        *("vector_encoder_size", "mlp_sizes", "previous_action", "previous_reward", "frame_stack", "grayscale"),
        *("helm", "trxl", "lru", "ffm", "mamba", "mamba2"),
    ]
    model = ModelConfig()
    for name in ("trxl", "lru", "ffm", "mamba", "mamba2"):
        assert type(getattr(model, name)) is MEMORY_SPECS[name].settings
    assert (model.trxl.dim, model.lru.r_max, model.ffm.trace_size, model.mamba.state_size) == (384, 0.99, 32, 16)
    assert model.mamba2.head_dim == 64 and model.trxl is not ModelConfig().trxl, "a fresh block per config"
    with pytest.raises(ConfigError, match=r"model\.ffm\.trace_size=0 is invalid: expected an int in \[1, inf\]"):
        config_from_dict({"model": {"ffm": {"trace_size": 0}}})


def test_a_memory_check_spanning_the_model_block_is_its_specs() -> None:
    """Mamba-2's heads split its inner width: its spec's check, run when model.memory names it."""
    message = (
        "model.mamba2.head_dim=48 is invalid: expected a divisor of the inner width "
        "model.mamba2.expand x model.memory_size = 1024"
    )
    with pytest.raises(ConfigError) as error:
        config_from_dict({"model": {"memory": "mamba2", "mamba2": {"head_dim": 48}}})
    assert str(error.value) == message
    config_from_dict({"model": {"memory": "gru", "mamba2": {"head_dim": 48}}})  # another memory: not checked


def test_an_unknown_memory_is_refused_with_the_valid_ones() -> None:
    with pytest.raises(ConfigError, match="model.memory='rwkv' is invalid; valid choices: " + ", ".join(BUILT_IN)):
        config_from_dict({"model": {"memory": "rwkv"}})
    with pytest.raises(ValueError, match="valid memories: none, gru, lstm"):
        build_memory(ModelConfig(memory="rwkv"), 4)


def _module(name: str, *specs: object) -> types.ModuleType:
    module = types.ModuleType(f"agents.memory.{name}")
    module.MEMORIES = specs  # type: ignore[attr-defined]
    return module


def _spec(name: str, order: int = DEFAULT_ORDER, **kwargs: object) -> MemorySpec:
    return MemorySpec(name, name.upper(), "#123456", lambda config, size: Memory(), order=order, **kwargs)


def test_specs_are_ordered_by_order_then_file_then_place() -> None:
    modules = [_module("alpha", _spec("a2"), _spec("a1")), _module("beta", _spec("b", order=5)), _module("gamma")]
    assert list(collect_specs(modules)) == ["b", "a2", "a1"]


@pytest.mark.parametrize(
    ("modules", "error", "message"),
    [
        ([_module("a", _spec("x")), _module("b", _spec("x"))], ValueError, "'x' is exported twice: by agents.memory.a"),
        (
            [_module("a", _spec("x", variants={"y": "Y"})), _module("b", _spec("y"))],
            ValueError,
            "'y' is exported twice",
        ),
        ([_module("a", "gru")], TypeError, "agents.memory.a.MEMORIES[0] is 'gru', not an agents.memory.MemorySpec"),
    ],
)
def test_a_name_given_twice_or_a_spec_that_is_none_is_an_error(modules: list, error: type, message: str) -> None:
    with pytest.raises(error, match=message.replace("[", r"\[").replace("]", r"\]").replace(".", r"\.")):
        collect_specs(modules)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"name": "My-RNN"}, "memory name 'My-RNN' is invalid: expected a lower-case identifier"),
        ({"variants": {"g:x": "G"}}, "memory name 'g:x' is invalid"),
        ({"colour": "blue"}, "colour 'blue' is invalid: expected '#rrggbb'"),
        ({"settings": dict}, "is not a dataclass deriving from Settings"),
    ],
)
def test_a_bad_spec_says_what_is_wrong(kwargs: dict, message: str) -> None:
    fields = {"name": "mine", "label": "Mine", "colour": "#123456", "builder": lambda config, size: Memory(), **kwargs}
    with pytest.raises(ValueError, match=message):
        MemorySpec(**fields)


# The modules that read the registry instead of naming memories, and their string constants (docstrings left out;
# "none" is also an ordinary word of other choices, layer_norm: none, and is left out too).
READERS = [
    *sorted((ROOT / "agents" / "config").glob("*.py")),
    ROOT / "agents" / "analysis" / "plots.py",
    *sorted((ROOT / "agents" / "experiments").glob("*.py")),
    ROOT / "scripts" / "benchmark_training.py",
    ROOT / "scripts" / "benchmark_memories.py",
]


def named_memories(path: Path) -> list[tuple[int, str]]:
    """(line, name) of the memory names (and variants' method names) that ``path`` writes as string constants
    outside docstrings."""
    names = {name for spec in MEMORY_SPECS.values() for name in (spec.name, *spec.variants)} - {"none"}
    tree = ast.parse(path.read_text())
    docstrings = {
        id(node.body[0].value)
        for node in ast.walk(tree)
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef)
        and node.body
        and isinstance(node.body[0], ast.Expr)
        and isinstance(node.body[0].value, ast.Constant)
    }
    return sorted(
        (node.lineno, node.value)
        for node in ast.walk(tree)
        if isinstance(node, ast.Constant) and node.value in names and id(node) not in docstrings
    )


@pytest.mark.parametrize("path", READERS, ids=lambda path: str(path.relative_to(ROOT)))
def test_the_config_figures_sweep_and_benchmarks_name_no_memory(path: Path) -> None:
    # the one name written: the default of model.memory (the paper's GRU-PPO), the benchmarks' reference
    allowed = ["gru"] if path == ROOT / "agents" / "config" / "schema.py" else []
    named = named_memories(path)
    assert [name for _, name in named] == allowed, f"{path.relative_to(ROOT)} names memories (line, name): {named}"


# --------------------------------------------------------------------------- a copy of the package, one file less
def package_copy(tmp_path: Path, drop: str = "", add: dict[str, str] | None = None) -> Path:
    """agents/ and envs/ copied to ``tmp_path`` without agents/memory/``drop`` and with the files ``add``."""
    ignore = shutil.ignore_patterns("__pycache__", *([drop] if drop else []))
    for package in ("agents", "envs"):
        shutil.copytree(ROOT / package, tmp_path / package, ignore=ignore)
    for name, text in (add or {}).items():
        (tmp_path / "agents" / "memory" / name).write_text(textwrap.dedent(text))
    return tmp_path


def run_in(copy: Path, script: str) -> str:
    """``script`` in a fresh interpreter whose agents and envs are the copy's; its output (a failure shows why)."""
    env = {**os.environ, "PYTHONPATH": str(copy), "PYTHONDONTWRITEBYTECODE": "1"}
    prelude = f"import agents, sys\nassert agents.__file__.startswith({str(copy)!r}), agents.__file__\n"
    done = subprocess.run(
        [sys.executable, "-c", prelude + textwrap.dedent(script)],
        cwd=copy,
        env=env,
        capture_output=True,
        text=True,
        check=False,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    return done.stdout


@pytest.mark.parametrize("removed", ["mamba2", "ffm", "mamba"])
def test_removing_a_memory_file_leaves_every_other_memory_working(tmp_path: Path, removed: str) -> None:
    copy = package_copy(tmp_path, drop=f"{removed}.py")
    others = [name for name in BUILT_IN if name != removed]
    out = run_in(
        copy,
        f"""
        import dataclasses, torch
        torch.set_num_threads(1)
        from agents.config import ConfigError, ModelConfig, config_from_dict
        from agents.memory import MEMORY_SPECS
        from agents.policy.checkpoint import build_agent
        from agents.analysis import plots

        assert list(MEMORY_SPECS) == {others!r}, list(MEMORY_SPECS)
        assert {removed!r} not in [field.name for field in dataclasses.fields(ModelConfig)]
        config = config_from_dict({{"model": {{"memory": "gru", "memory_size": 8, "hidden_size": 8}}}})
        model, _ = build_agent(config, config.env.make_core(1))
        assert model.memory.output_size == 8
        try:
            config_from_dict({{"model": {{"memory": {removed!r}}}}})
        except ConfigError as error:
            print(error)
        try:
            config_from_dict({{"model": {{{removed!r}: {{}}}}}})
        except ConfigError as error:
            print(error)
        print(plots.method_label("gru"), plots.method_label("trxl_recon"), plots.method_colors(["gru"])["gru"])
        print(plots.method_label({removed!r}))
        """,
    )
    refused, unknown_block, labels, removed_label = out.splitlines()
    assert refused.startswith(f"model.memory={removed!r} is invalid")  # with a close name's hint where one is
    assert refused.endswith(f"; valid choices: {', '.join(others)}")
    assert unknown_block.startswith(f"unknown config key 'model.{removed}'")
    assert labels == "GRU-PPO TrXL-PPO + recon. #0072b2"
    assert removed_label == removed, "a method of no memory is shown as it is"


NEW_MEMORY = '''
    """A leaky integrator (``model.memory: leaky``): h_t = leak * h_{t-1} + W x_t, output tanh(h_t)."""

    from __future__ import annotations

    from dataclasses import dataclass

    import torch
    from torch import nn

    from agents.memory.base import Memory, MemorySpec
    from agents.settings import ConfigError, Settings, param


    @dataclass
    class LeakyConfig(Settings):
        """``model.leaky``: the integrator's settings."""

        leak: float = param(0.9, "share of the state each step keeps", low=0.0, high=1.0)


    class Leaky(Memory):
        def __init__(self, input_size, width, leak):
            super().__init__()
            self.leak = leak
            self.project = nn.Linear(input_size, width)
            self.output_size = width
            self.state_shape = self.record_shape = (width,)

        def step(self, features, state, episode_step=None):
            h = self.leak * state + self.project(features)
            return torch.tanh(h), h

        def sequences(self, features, records, mask, episode_step=None):
            s, p = mask.shape
            projected = self.project(features)
            inputs = projected.new_zeros((s, p, self.output_size))
            inputs[mask] = projected
            h, outputs = records, []
            for t in range(p):
                h = self.leak * h + inputs[:, t]
                outputs.append(torch.tanh(h))
            return torch.stack(outputs, dim=1)[mask]


    def build(config, input_size):
        return Leaky(input_size, config.memory_size, config.leaky.leak)


    def check_width(config, prefix):
        if config.memory_size % 2:
            raise ConfigError(f"{prefix}.memory_size={config.memory_size} is invalid: expected an even width")


    MEMORIES = (MemorySpec("leaky", "Leaky-PPO", "#888888", build, settings=LeakyConfig, check=check_width),)
'''


def test_a_new_memory_file_trains_by_name_with_nothing_else_changed(tmp_path: Path) -> None:
    copy = package_copy(tmp_path, add={"leaky.py": NEW_MEMORY})
    out = run_in(
        copy,
        """
        import torch
        from agents.config import ConfigError, config_from_dict, dump_config
        from agents.memory import MEMORY_SPECS
        from agents.training.trainer import Trainer
        from agents.analysis import plots

        print(list(MEMORY_SPECS))
        raw = {
            "env": {"id": "ProofOfMemory-v0"},
            "model": {"memory": "leaky", "memory_size": 8, "hidden_size": 8, "leaky": {"leak": 0.5}},
            "ppo": {"epochs": 1, "minibatches": 1},
            "run": {"total_steps": 32, "workers": 2, "worker_steps": 16, "progress_bar": False, "torch_threads": 1},
        }
        config = config_from_dict(raw)
        print(config.method, config.model.leaky.leak, "leaky:" in dump_config(config))
        trainer = Trainer(config, "run")
        metrics = trainer.train_update()
        print(type(trainer.model.memory).__name__, torch.isfinite(torch.tensor(metrics["losses/policy_loss"])).item())
        for bad in ({"leaky": {"leak": 2}}, {"leaky": {"leek": 0.5}}, {"memory": "leaky", "memory_size": 7}):
            try:
                config_from_dict({**raw, "model": {**raw["model"], **bad}})
            except ConfigError as error:
                print(error)
        labels = plots.method_label("leaky"), plots.method_label("leaky-stack4")
        print(*labels, list(plots.method_colors(["leaky", "x"])))
        """,
    )
    lines = out.splitlines()
    assert lines[0] == str([*BUILT_IN, "leaky"]), "a new file comes after the built-in memories"
    assert lines[1] == "leaky 0.5 True"
    assert lines[2] == "Leaky True"
    assert lines[3] == "model.leaky.leak=2.0 is invalid: expected a number in [0, 1]"
    assert lines[4].startswith("unknown config key 'model.leaky.leek' (did you mean 'model.leaky.leak'?)")
    assert lines[5] == "model.memory_size=7 is invalid: expected an even width"
    assert lines[6] == "Leaky-PPO Leaky + 4-Stack ['leaky', 'x']", "its own colour, before the unknown methods"
