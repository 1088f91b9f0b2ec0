"""The console commands (pyproject's [project.scripts]) and the scripts of the same name are one program each: a
command's entry point is the ``main`` its script calls; the scripts are thin and run from a checkout without
touching ``sys.path`` (``pip install -e .`` makes ``agents``, ``envs`` and ``scripts`` importable)."""

from __future__ import annotations

import ast
import importlib
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = next(path for path in Path(__file__).resolve().parents if (path / "pyproject.toml").is_file())


def _commands() -> dict[str, str]:
    """pyproject's memgym-* console commands: name -> ``module:function``."""
    import tomllib  # Python 3.11+, as in tests/test_readme.py

    declared = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    return {name: target for name, target in declared.items() if name.startswith("memgym-")}


COMMANDS = _commands()
BIN = Path(sys.executable).parent  # the environment's console scripts live beside its python


def test_the_four_commands_are_declared() -> None:
    assert set(COMMANDS) == {"memgym-train", "memgym-evaluate", "memgym-sweep", "memgym-plot"}


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_a_commands_entry_point_is_the_main_of_its_script(command: str) -> None:
    module_name, _, function = COMMANDS[command].partition(":")
    entry = getattr(importlib.import_module(module_name), function)
    script = importlib.import_module(f"scripts.{command.removeprefix('memgym-')}")
    assert script.main is entry, f"{command} is {COMMANDS[command]}, but {script.__name__} calls another main"


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_a_commands_script_is_thin(command: str) -> None:
    """A docstring naming the command, the import of its main, and ``sys.exit(main())``: no code of its own."""
    path = ROOT / "scripts" / f"{command.removeprefix('memgym-')}.py"
    tree = ast.parse(path.read_text())
    assert command in (ast.get_docstring(tree) or ""), f"{path.name}'s docstring does not name {command}"
    kinds = {type(node).__name__ for node in tree.body[1:]}
    assert kinds <= {"Import", "ImportFrom", "If"}, f"{path.name} holds {kinds}: library code belongs to agents/cli/"


def test_no_script_edits_sys_path() -> None:
    found = []
    for path in sorted((ROOT / "scripts").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Attribute) and node.attr == "path" and getattr(node.value, "id", "") == "sys":
                found.append(str(path.relative_to(ROOT)))
    assert not found, f"scripts that touch sys.path (they run after pip install -e .): {sorted(set(found))}"


def test_memgym_train_help_runs_as_a_command(tmp_path: Path) -> None:
    command = BIN / "memgym-train"
    assert command.is_file(), f"{command} is missing: install the project again (pip install -e .)"
    done = subprocess.run([str(command), "--help"], cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("usage: memgym-train") and "--resume DIR" in done.stdout


def test_a_script_runs_from_outside_the_checkout(tmp_path: Path) -> None:
    done = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "plot_benchmarks.py"), "--help"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr  # it imports scripts.benchmark_envs, which imports scripts.reference
