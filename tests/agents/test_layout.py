"""The house's layout (agents/__init__.py): no import circle anywhere in envs/, agents/ or scripts/, imports only
from a higher floor to a lower one, no module of agents/ over 600 lines, and every room's face documented.

The import graph is read with ``ast``: every ``import`` and ``from ... import`` at any depth (inside functions too),
relative imports resolved, ``from package import module`` taken as an import of the module, and imports under
``if TYPE_CHECKING:`` too: never executed, but a type hint is a dependency all the same (the memory floor names the
model config by a protocol of its own, :class:`agents.memory.base.ModelSettings`, not by importing it)."""

from __future__ import annotations

import ast
import importlib
from collections.abc import Iterable, Mapping
from pathlib import Path

import pytest

ROOT = next(path for path in Path(__file__).resolve().parents if (path / "pyproject.toml").is_file())
TOPS = ("envs", "agents", "scripts")
MAX_LINES = 600
# The floors, top first; rooms on one floor are siblings and do not import each other.
FLOORS: tuple[tuple[str, ...], ...] = (
    ("scripts",),
    ("agents.cli",),
    ("agents.experiments",),
    ("agents.training",),
    ("agents.evaluation",),
    ("agents.analysis", "agents.policy"),
    ("agents.runtime",),
    ("agents.config",),
    ("agents.memory",),
    ("agents.settings", "agents.layers"),
    ("envs",),
)
FLOOR_OF = {room: len(FLOORS) - index for index, rooms in enumerate(FLOORS) for room in rooms}


def module_names(root: Path = ROOT) -> dict[str, Path]:
    """Every module of the three packages by its dotted name (a package by its own name)."""
    found = {}
    for top in TOPS:
        for path in sorted((root / top).rglob("*.py")):
            parts = list(path.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            found[".".join(parts)] = path
    return found


def imports_of(name: str, path: Path, modules: Iterable[str]) -> set[str]:
    """The modules of ``modules`` that module ``name`` (at ``path``) imports, at any depth."""
    known = set(modules)
    tree = ast.parse(path.read_text(), str(path))
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*parts, *([node.module] if node.module else [])])
            for alias in node.names:
                inner = f"{base}.{alias.name}"
                found.add(inner if inner in known else base)
    return {module for module in found if module in known and module != name}


def import_graph(root: Path = ROOT) -> dict[str, set[str]]:
    modules = module_names(root)
    return {name: imports_of(name, path, modules) for name, path in modules.items()}


def cycles(graph: Mapping[str, Iterable[str]]) -> list[list[str]]:
    """The import circles: every strongly connected set of more than one module (Tarjan), each as one circle path."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(start: str) -> None:  # iterative, so that deep graphs need no recursion limit
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            node, edges = work[-1]
            for target in edges:
                if target not in index:
                    index[target] = low[target] = len(index)
                    stack.append(target)
                    on_stack.add(target)
                    work.append((target, iter(sorted(graph[target]))))
                    break
                if target in on_stack:
                    low[node] = min(low[node], index[target])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    component = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.append(member)
                        if member == node:
                            break
                    if len(component) > 1:
                        found.append(_circle(graph, set(component)))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return found


def _circle(graph: Mapping[str, Iterable[str]], members: set[str]) -> list[str]:
    """One closed path through a strongly connected set, from its first module back to it."""
    start = min(members)
    paths = {start: [start]}
    queue = [start]
    while queue:
        node = queue.pop(0)
        for target in sorted(graph[node]):
            if target == start:
                return [*paths[node], start]
            if target in members and target not in paths:
                paths[target] = [*paths[node], target]
                queue.append(target)
    raise AssertionError(f"no circle through {sorted(members)}")  # a strongly connected set always has one


def room_of(module: str) -> str | None:
    """The room a module lives in: the longest room name that is the module or a package above it."""
    rooms = [room for room in FLOOR_OF if module == room or module.startswith(room + ".")]
    return max(rooms, key=len) if rooms else None


def upward_imports(graph: Mapping[str, Iterable[str]]) -> list[str]:
    """``importer -> imported`` for every import that does not go down a floor (siblings included), but within a
    room; the package root ``agents`` (the map of the rooms) imports nothing at all."""
    found = []
    for importer, targets in sorted(graph.items()):
        for target in sorted(targets):
            if importer == "agents":
                found.append(f"{importer} -> {target} (agents/__init__.py is the map of the rooms: no imports)")
                continue
            source_room, target_room = room_of(importer), room_of(target)
            if source_room is None or target_room is None or source_room == target_room:
                continue
            if FLOOR_OF[target_room] >= FLOOR_OF[source_room]:
                found.append(f"{importer} ({source_room}) -> {target} ({target_room})")
    return found


# ------------------------------------------------------------------------------------------------------ the house
def test_no_import_circle_in_envs_agents_or_scripts() -> None:
    found = cycles(import_graph())
    assert not found, "import circles: " + "; ".join(" -> ".join(circle) for circle in found)


def test_imports_only_go_down_the_floors() -> None:
    found = upward_imports(import_graph())
    assert not found, "imports that do not go down a floor:\n  " + "\n  ".join(found)


def test_every_module_is_in_a_room() -> None:
    assert [name for name in module_names() if name != "agents" and room_of(name) is None] == []


def test_no_module_of_agents_is_over_600_lines() -> None:
    long = {
        str(path.relative_to(ROOT)): count
        for path in sorted((ROOT / "agents").rglob("*.py"))
        if (count := len(path.read_text().splitlines())) > MAX_LINES
    }
    assert not long, f"modules over {MAX_LINES} lines (split them by concern): {long}"


ROOMS = sorted(path.parent for path in (ROOT / "agents").glob("*/__init__.py"))


@pytest.mark.parametrize("package", ROOMS, ids=lambda path: path.name)
def test_every_room_has_a_documented_face_that_exports_its_names(package: Path) -> None:
    tree = ast.parse((package / "__init__.py").read_text())
    assert ast.get_docstring(tree), f"agents/{package.name}/__init__.py has no docstring saying what lives there"
    exported = [node for node in tree.body if isinstance(node, ast.Assign) and "__all__" in ast.unparse(node.targets)]
    assert exported, f"agents/{package.name}/__init__.py has no __all__"
    module = importlib.import_module(f"agents.{package.name}")
    for name in module.__all__:  # a name, or a module of the room that the face leaves to be imported
        assert hasattr(module, name) or importlib.util.find_spec(f"{module.__name__}.{name}"), name


def test_the_package_root_is_the_map_of_the_rooms() -> None:
    tree = ast.parse((ROOT / "agents" / "__init__.py").read_text())
    assert ast.get_docstring(tree) and len(tree.body) == 1, "agents/__init__.py: one docstring, no code"
    documented = ast.get_docstring(tree)
    assert all(f":mod:`agents.{package.name}`" in documented for package in ROOMS), "a room is missing from the map"


# ------------------------------------------------------------------------------------------------ the checks' own
def _tree(tmp_path: Path, files: Mapping[str, str]) -> Path:
    for name, text in files.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    for top in TOPS:
        (tmp_path / top).mkdir(exist_ok=True)
    return tmp_path


def test_the_graph_finds_a_circle_through_a_function_level_and_a_relative_import(tmp_path: Path) -> None:
    root = _tree(
        tmp_path,
        {
            "agents/__init__.py": "",
            "agents/config/__init__.py": "",
            "agents/config/schema.py": "def check():\n    from agents.memory import registry\n",
            "agents/memory/__init__.py": "",
            "agents/memory/registry.py": "from ..config import schema\n",
            "agents/memory/lru.py": "import typing\nif typing.TYPE_CHECKING:\n    import agents.config.schema\n",
        },
    )
    graph = import_graph(root)
    assert graph["agents.memory.registry"] == {"agents.config.schema"}
    assert graph["agents.memory.lru"] == {"agents.config.schema"}, "an import for type hints is an arrow too"
    assert cycles(graph) == [["agents.config.schema", "agents.memory.registry", "agents.config.schema"]]
    assert upward_imports(graph) == [
        "agents.memory.lru (agents.memory) -> agents.config.schema (agents.config)",
        "agents.memory.registry (agents.memory) -> agents.config.schema (agents.config)",
    ]


def test_siblings_and_the_map_may_not_import(tmp_path: Path) -> None:
    root = _tree(
        tmp_path,
        {
            "envs/__init__.py": "",
            "agents/__init__.py": "import envs\n",
            "agents/policy/__init__.py": "",
            "agents/policy/models.py": "from agents.analysis import metrics\n",
            "agents/analysis/__init__.py": "",
            "agents/analysis/metrics.py": "",
        },
    )
    found = upward_imports(import_graph(root))
    assert any(line.startswith("agents.policy.models (agents.policy) -> agents.analysis.metrics") for line in found)
    assert any(line.startswith("agents -> envs") for line in found)
