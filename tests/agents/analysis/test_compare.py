"""Two results directories compared (agents/analysis/compare.py): the record files byte for byte, the summary but
for its evaluation's provenance."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

from agents.analysis.compare import PROVENANCE, differences
from agents.runtime.io import ROOT, provenance

EXAMPLE = ROOT / "results" / "examples" / "proof_of_memory"


def copy_of_example(target: Path) -> Path:
    target.mkdir(parents=True)
    for name in ("episodes.csv", "training.csv", "summary.json"):
        shutil.copy2(EXAMPLE / name, target / name)
    return target


def rewrite_summary(directory: Path, change: dict) -> None:
    summary = json.loads((directory / "summary.json").read_text())
    for dotted, value in change.items():
        holder = summary
        *parents, key = dotted.split(".")
        for part in parents:
            holder = holder[part]
        holder[key] = value
    (directory / "summary.json").write_text(json.dumps(summary, indent=2))


def test_provenance_is_what_the_results_record_of_how_they_were_made() -> None:
    assert set(PROVENANCE) == set(provenance())


def test_a_copy_with_other_provenance_and_an_absolute_config_path_is_the_same(tmp_path: Path) -> None:
    produced = copy_of_example(tmp_path / "produced")
    rewrite_summary(
        produced,
        {
            "evaluation.time": "2030-01-01T00:00:00+00:00",
            "evaluation.git": {"revision": "0" * 40, "dirty": True},
            "evaluation.command": ["sweep.py", "elsewhere"],
            "evaluation.machine": {},
            "evaluation.versions": {},
            "config": str(ROOT / "configs" / "examples" / "proof_of_memory.yaml"),
        },
    )
    assert differences(produced, EXAMPLE) == []


def test_a_changed_record_and_a_changed_score_are_named(tmp_path: Path) -> None:
    produced = copy_of_example(tmp_path / "produced")
    lines = (produced / "training.csv").read_text().splitlines(keepends=True)
    lines[3] = lines[3].replace(",c", ",d", 1)
    (produced / "training.csv").write_text("".join(lines))
    rewrite_summary(produced, {"evaluation.seeds": [0, 9], "config": "configs/other.yaml"})
    found = differences(produced, EXAMPLE, produced_base=ROOT)
    assert found[0].startswith("training.csv: line 4 differs") and len(found) == 2, found
    assert found[1] == "summary.json: config, evaluation.seeds[0], evaluation.seeds[1] differ"


def test_a_missing_file_is_named(tmp_path: Path) -> None:
    produced = copy_of_example(tmp_path / "produced")
    (produced / "episodes.csv").unlink()
    assert differences(produced, EXAMPLE) == [f"episodes.csv: missing in {produced / 'episodes.csv'}"]
