"""The reference package's boundaries: its ids, what each side may import, and the info keys left out of parity."""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

import envs
from envs import ENV_IDS
from scripts.reference import PROJECT_ONLY_IDS, REFERENCE_IDS
from scripts.reference.parity import replay, replay_batched
from scripts.reference.trace_format import dump_json_gz, load_traces

ROOT = Path(__file__).resolve().parents[2]
# What runs inside the reference venv (gymnasium 0.29 and memory_gym; our envs need gymnasium 1.x), with what it
# imports from this repository, and venv.py, which starts it (standard library only): what they may import.
REFERENCE_VENV_MODULES = ["__init__", "trace_format", "protocol", "recorder", "bench"]
CHECKED = [
    *(f"scripts/reference/{module}.py" for module in [*REFERENCE_VENV_MODULES, "venv"]),
    "agents/__init__.py",
    "agents/runtime/__init__.py",  # imported with agents.runtime.io
    "agents/runtime/io.py",
    "agents/runtime/faults.py",  # the fault-injection hooks of agents/runtime/io.py
    "agents/runtime/preemption.py",  # re-exported by agents/runtime/__init__.py
]
ALLOWED_THIRD_PARTY = {"numpy", "gymnasium", "memory_gym"}
ALLOWED_FIRST_PARTY = {
    "agents.runtime.io",
    "agents.runtime.faults",
    "agents.runtime.preemption",
    "scripts.reference",
    *(f"scripts.reference.{m}" for m in REFERENCE_VENV_MODULES),
}


def imported_modules(path: Path) -> set[str]:
    """Every module that ``path`` imports, at the top or inside a function."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            assert node.level == 0, f"{path}: relative import"
            found.add(node.module)
    return found


def test_reference_ids_are_ours_without_the_project_only_ones() -> None:
    assert list(REFERENCE_IDS) == [env_id for env_id in ENV_IDS if env_id not in PROJECT_ONLY_IDS]
    assert set(PROJECT_ONLY_IDS) < set(ENV_IDS)


@pytest.mark.parametrize("module", CHECKED)
def test_reference_venv_modules_import_only_what_the_reference_venv_has(module: str) -> None:
    for name in imported_modules(ROOT / module):
        top = name.split(".")[0]
        allowed = top in sys.stdlib_module_names or top in ALLOWED_THIRD_PARTY or name in ALLOWED_FIRST_PARTY
        assert allowed, f"{module} imports {name}, which the reference venv cannot import"


def test_nothing_outside_tests_imports_tests() -> None:
    for folder in ("agents", "envs", "scripts"):
        for path in (ROOT / folder).rglob("*.py"):
            bad = {name for name in imported_modules(path) if name.split(".")[0] == "tests"}
            assert not bad, f"{path.relative_to(ROOT)} imports {bad}"


def test_info_keys_that_our_core_declares_as_added_are_not_compared(tmp_path: Path, monkeypatch) -> None:
    env_id = "MortarMayhemB-Grid-v0"
    trace = load_traces(env_id)
    dump_json_gz({**trace, "episodes": trace["episodes"][:3]}, tmp_path / f"{env_id}.json.gz")
    core_class = type(envs.make_core(env_id))
    step_info = core_class.step_info
    monkeypatch.setattr(core_class, "step_info", lambda core, k: {**step_info(core, k), "added_by_us": 1})
    for how in (replay, replay_batched):
        result = how(env_id, root=tmp_path)
        assert result.identical < result.steps, how.__name__
    declared = frozenset(getattr(core_class, "added_info_keys", frozenset()))
    monkeypatch.setattr(core_class, "added_info_keys", declared | {"added_by_us"}, raising=False)
    for how in (replay, replay_batched):
        result = how(env_id, root=tmp_path)
        assert result.steps > 0 and result.identical == result.steps, (how.__name__, result.mismatches)
