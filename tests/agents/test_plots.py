"""agents.plots on synthetic results: colours fixed per method, labels from the metric table, what is drawn."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from matplotlib.colors import to_hex

from agents import plots, results
from agents.metrics import METRICS
from tests.support.synthetic_results import write_results


def test_known_methods_keep_their_colour_in_any_company() -> None:
    alone = plots.method_colors(["gru"])
    crowd = plots.method_colors(["zeta", "gru", "ppo", "alpha", "helm", "stack16", "lstm", "stack4", "trxl"])
    assert alone["gru"] == crowd["gru"] == plots.METHOD_COLORS["gru"]
    assert list(crowd) == ["ppo", "gru", "lstm", "stack4", "stack16", "helm", "trxl", "alpha", "zeta"]
    assert crowd["alpha"] == plots.SPARE_COLORS[0] and crowd["zeta"] == plots.SPARE_COLORS[1]
    assert len(set(crowd.values())) == len(crowd), "no two methods share a colour"
    assert not set(plots.SPARE_COLORS) & set(plots.METHOD_COLORS.values())
    assert plots.method_colors(["b", "a"]) == plots.method_colors(["a", "b"]), "deterministic, whatever the order"
    many = plots.method_colors(f"m{i:02d}" for i in range(len(plots.SPARE_COLORS) + 2))
    assert many["m00"] == many[f"m{len(plots.SPARE_COLORS):02d}"], "spare colours cycle"


def test_metric_labels_come_from_the_table() -> None:
    assert set(METRICS) >= {"ProofOfMemory-v0", "MortarMayhem-v0", "Endless-SearingSpotlights-v0"}
    assert plots.metric_label("MortarMayhem-Grid-v0") == "Commands Executed"
    assert plots.metric_label("MysteryPath-v0") == "Success Rate"
    assert plots.metric_label("SearingSpotlights-v0") == "Task Progress"
    assert plots.metric_label("Endless-MysteryPath-v0") == "Tiles Visited"
    assert plots.metric_label("Endless-SearingSpotlights-v0") == "Coins Collected"
    assert plots.metric_label("Unknown-v0") == "Metric"
    assert plots.metric_label("MysteryPath-v0", "coins_collected") == "Coins collected"


def line_colors(figure) -> set[tuple[str, str]]:
    """(panel title, colour) of every drawn curve."""
    return {(axes.get_title(), to_hex(line.get_color())) for axes in figure.axes for line in axes.lines}


@pytest.fixture(scope="module")
def loaded(tmp_path_factory: pytest.TempPathFactory) -> results.Results:
    directory = write_results(tmp_path_factory.mktemp("r") / "results", methods=("ppo", "gru", "custom"))
    return results.read_results(directory)


def test_curves_figure_panels_and_colours(loaded: results.Results) -> None:
    figure = plots.curves_figure(loaded.episodes, loaded.training, reps=200)
    titles = [axes.get_title() for axes in figure.axes]
    assert titles == [
        "MortarMayhem-Grid-v0: training seeds",
        "MortarMayhem-Grid-v0: novel seeds",
        "ProofOfMemory-v0: training seeds",
        "ProofOfMemory-v0: novel seeds",
    ]
    assert [axes.get_ylabel() for axes in figure.axes] == ["Return", "Commands Executed", "Return", "Success Rate"]
    assert figure.axes[-1].get_xlabel() == plots.STEPS_LABEL
    drawn = {color for _, color in line_colors(figure)}
    assert drawn == {plots.METHOD_COLORS["ppo"], plots.METHOD_COLORS["gru"], plots.SPARE_COLORS[0]}
    novel = figure.axes[3]
    gru = next(line for line in novel.lines if to_hex(line.get_color()) == plots.METHOD_COLORS["gru"])
    np.testing.assert_allclose(gru.get_xdata(), [0.008192, 0.016384, 0.024576])
    expected = [row["iqm"] for row in results.aggregate(loaded.episodes.where(task="ProofOfMemory-v0", method="gru"))]
    np.testing.assert_allclose(gru.get_ydata(), expected)
    assert len(novel.collections) == 3, "one CI band per method"
    assert len(figure.legends) == 1 and [t.get_text() for t in figure.legends[0].get_texts()] == [
        "ppo",
        "gru",
        "custom",
    ]


def test_curves_without_training_and_with_a_subset_keep_colours(loaded: results.Results) -> None:
    subset = loaded.episodes.select(loaded.episodes["method"] == "gru")
    figure = plots.curves_figure(subset, None, reps=100)
    assert len(figure.axes) == 2 and all("novel seeds" in axes.get_title() for axes in figure.axes)
    assert {color for _, color in line_colors(figure)} == {plots.METHOD_COLORS["gru"]}


def test_final_figure_bars(loaded: results.Results) -> None:
    figure = plots.final_figure(loaded.episodes, reps=200)
    assert [axes.get_xlabel() for axes in figure.axes] == ["Commands Executed", "Success Rate"]
    rows = results.aggregate(loaded.episodes, steps="last", reps=200, overall=False)
    for axes, task in zip(figure.axes, ("MortarMayhem-Grid-v0", "ProofOfMemory-v0"), strict=True):
        assert [label.get_text() for label in axes.get_yticklabels()] == ["ppo", "gru", "custom"]
        bars = axes.patches
        assert [to_hex(bar.get_facecolor()[:3]) for bar in bars] == [
            plots.METHOD_COLORS["ppo"],
            plots.METHOD_COLORS["gru"],
            plots.SPARE_COLORS[0],
        ]
        for bar, method in zip(bars, ("ppo", "gru", "custom"), strict=True):
            row = next(r for r in rows if r["task"] == task and r["method"] == method)
            assert bar.get_x() == pytest.approx(row["low"]) and bar.get_width() == pytest.approx(
                row["high"] - row["low"]
            )
        left, right = axes.get_xlim()  # every interval and tick inside the panel, none pinned to its edge
        task_rows = [r for r in rows if r["task"] == task]
        assert left < min(r["low"] for r in task_rows) and right > max(r["high"] for r in task_rows)


def test_save_figure_writes_png_and_pdf_atomically(loaded: results.Results, tmp_path: Path) -> None:
    figure = plots.final_figure(loaded.episodes, reps=50)
    paths = plots.save_figure(figure, tmp_path / "deep" / "final")
    assert [path.name for path in paths] == ["final.png", "final.pdf"]
    assert sorted(path.name for path in (tmp_path / "deep").iterdir()) == ["final.pdf", "final.png"]
    assert paths[0].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and paths[1].read_bytes()[:5] == b"%PDF-"
