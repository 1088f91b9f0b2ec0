"""notebooks/plots.ipynb executes headless, as committed, from the repository root (nbclient, kernel python3).

It runs on a synthetic results directory handed over through MEMORY_GYM_RESULTS, and on its default, the committed
example results (results/examples/proof_of_memory/, produced by configs/examples/proof_of_memory.yaml).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

from tests.support.synthetic_results import write_results

ROOT = Path(__file__).resolve().parent.parent
NOTEBOOK = ROOT / "notebooks" / "plots.ipynb"
DEFAULT_RESULTS = ROOT / "results" / "examples" / "proof_of_memory"


def execute(monkeypatch: pytest.MonkeyPatch, results_dir: Path | None) -> nbformat.NotebookNode:
    """Run every cell in a fresh kernel started in the repository root; a failing cell raises."""
    if results_dir is None:
        monkeypatch.delenv("MEMORY_GYM_RESULTS", raising=False)
    else:
        monkeypatch.setenv("MEMORY_GYM_RESULTS", str(results_dir))
    notebook = nbformat.read(NOTEBOOK, as_version=4)
    client = NotebookClient(notebook, kernel_name="python3", timeout=300, resources={"metadata": {"path": str(ROOT)}})
    client.execute(env=dict(os.environ))
    return notebook


def outputs(notebook: nbformat.NotebookNode) -> tuple[str, int]:
    """All text the cells printed, and the number of PNG images they displayed."""
    text, images = [], 0
    for cell in notebook.cells:
        for output in cell.get("outputs", []):
            text.append(output.get("text", "") or output.get("data", {}).get("text/plain", ""))
            images += "image/png" in output.get("data", {})
    return "\n".join(text), images


def check_shows_results(notebook: nbformat.NotebookNode, methods: set[str]) -> None:
    text, images = outputs(notebook)
    assert "method" in text and "iqm" in text and "low" in text and "high" in text, "the summary table is shown"
    assert all(f" {method} " in text for method in methods)
    assert images == 2, "both figures are displayed"


def test_committed_notebook_has_no_outputs() -> None:
    notebook = json.loads(NOTEBOOK.read_text())
    for cell in notebook["cells"]:
        if cell["cell_type"] == "code":
            assert cell["outputs"] == [] and cell["execution_count"] is None
    assert notebook["metadata"]["kernelspec"]["name"] == "python3"
    source = "\n".join("".join(cell["source"]) for cell in notebook["cells"])
    assert 'DEFAULT = "results/examples/proof_of_memory"' in source, "the default is the committed example"


def test_notebook_executes(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    synthetic = write_results(tmp_path / "results", methods=("ppo", "gru"))
    check_shows_results(execute(monkeypatch, synthetic), {"ppo", "gru"})
    check_shows_results(execute(monkeypatch, None), {"ppo", "gru", "stack4", "stack16", "helm"})
