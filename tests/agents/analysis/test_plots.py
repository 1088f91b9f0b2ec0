"""agents.analysis.plots on synthetic results: colours fixed per method, labels from the metric table, what is drawn:
axis ranges, chance lines, legend entries, method labels and task titles, read off the matplotlib objects."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from matplotlib.colors import to_hex

from agents.analysis import plots, results, scores
from agents.analysis.metrics import METRICS
from agents.config import expand_grid, read_config_file
from tests.support.synthetic_results import episode_rows, write_csv, write_results

ROOT = Path(__file__).resolve().parents[3]
FIXED = plots.known_methods()[0]  # the fixed colour of every known method: this module's agents and the memories'


def test_known_methods_keep_their_colour_in_any_company() -> None:
    alone = plots.method_colors(["gru"])
    crowd = plots.method_colors(["zeta", "gru", "ppo", "alpha", "helm", "stack16", "lstm", "stack4", "trxl"])
    assert alone["gru"] == crowd["gru"] == FIXED["gru"]
    assert list(crowd) == ["ppo", "gru", "lstm", "stack4", "stack16", "helm", "trxl", "alpha", "zeta"]
    assert crowd["alpha"] == plots.SPARE_COLORS[0] and crowd["zeta"] == plots.SPARE_COLORS[1]
    assert len(set(crowd.values())) == len(crowd), "no two methods share a colour"
    assert not set(plots.SPARE_COLORS) & set(FIXED.values())
    agents = [method for method in FIXED if method != "none"]  # none: the memory-less agent, PPO's colour
    assert len({FIXED[method] for method in agents}) == len(agents), "no two known agents share a colour"
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
    """(panel title, colour) of every drawn curve (chance lines left out)."""
    return {
        (axes.get_title(), to_hex(line.get_color()))
        for axes in figure.axes
        for line in axes.lines
        if line.get_gid() != plots.CHANCE_LABEL
    }


def chance_lines(axes) -> list:
    return [line for line in axes.lines if line.get_gid() == plots.CHANCE_LABEL]


def legend_texts(figure) -> list[str]:
    assert len(figure.legends) == 1
    return [text.get_text() for text in figure.legends[0].get_texts()]


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
    assert drawn == {FIXED["ppo"], FIXED["gru"], plots.SPARE_COLORS[0]}
    novel = figure.axes[3]
    gru = next(line for line in novel.lines if to_hex(line.get_color()) == FIXED["gru"])
    np.testing.assert_allclose(gru.get_xdata(), [0.008192, 0.016384, 0.024576])
    expected = [row["iqm"] for row in scores.aggregate(loaded.episodes.where(task="ProofOfMemory-v0", method="gru"))]
    np.testing.assert_allclose(gru.get_ydata(), expected)
    assert len(novel.collections) == 3, "one CI band per method"
    assert legend_texts(figure) == ["PPO", "GRU-PPO", "custom", "chance"]  # ProofOfMemory's 0.5 is drawn


def test_curves_without_training_and_with_a_subset_keep_colours(loaded: results.Results) -> None:
    subset = loaded.episodes.select(loaded.episodes["method"] == "gru")
    figure = plots.curves_figure(subset, None, reps=100)
    assert len(figure.axes) == 2 and all("novel seeds" in axes.get_title() for axes in figure.axes)
    assert {color for _, color in line_colors(figure)} == {FIXED["gru"]}


def test_final_figure_bars(loaded: results.Results) -> None:
    figure = plots.final_figure(loaded.episodes, reps=200)
    assert [axes.get_xlabel() for axes in figure.axes] == ["Commands Executed", "Success Rate"]
    rows = scores.aggregate(loaded.episodes, steps="last", reps=200, overall=False)
    for axes, task in zip(figure.axes, ("MortarMayhem-Grid-v0", "ProofOfMemory-v0"), strict=True):
        assert [label.get_text() for label in axes.get_yticklabels()] == ["PPO", "GRU-PPO", "custom"]
        bars = axes.patches
        assert [to_hex(bar.get_facecolor()[:3]) for bar in bars] == [
            FIXED["ppo"],
            FIXED["gru"],
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


# --------------------------------------------------- C8: ranges, chance lines, legends, readable labels and titles
def test_every_method_of_the_configs_has_a_readable_label() -> None:
    methods = set()
    for path in sorted((ROOT / "configs").rglob("*.yaml")):
        raw = read_config_file(path)
        methods |= {point.config.method for point in expand_grid(raw)}
    assert methods >= {"ppo", "gru", "stack4", "stack16", "helm"}
    unreadable = {method for method in methods if plots.method_label(method) == method}
    assert not unreadable, f"methods of configs/ without a label: {sorted(unreadable)}"
    assert [plots.method_label(m) for m in ("ppo", "gru", "lstm", "stack4", "stack16", "helm")] == [
        "PPO",
        "GRU-PPO",
        "LSTM-PPO",
        "4-Stack",
        "16-Stack",
        "HELM",
    ]
    assert plots.method_label("gru-stack4") == "GRU + 4-Stack" and plots.method_label("lstm-helm") == "LSTM + HELM"
    assert plots.method_label("custom") == "custom" and plots.method_label("gru-custom") == "gru-custom"


# What the figures showed before the memories' labels and colours moved into their files (agents/memory/): every
# method of the committed results and of configs/, with a few derived names, in legend order.
BEFORE = {  # method: (label, colour), the colours as method_colors gives them for all of these at once
    "ppo": ("PPO", "#d55e00"),
    "gru": ("GRU-PPO", "#0072b2"),
    "lstm": ("LSTM-PPO", "#009e73"),
    "stack4": ("4-Stack", "#e69f00"),
    "stack16": ("16-Stack", "#cc79a7"),
    "helm": ("HELM", "#56b4e9"),
    "trxl": ("TrXL-PPO", "#000000"),
    "lru": ("LRU-PPO", "#332288"),
    "ffm": ("FFM-PPO", "#117733"),
    "mamba": ("Mamba-PPO", "#882255"),
    "mamba2": ("Mamba2-PPO", "#aa4499"),
    "custom": ("custom", "#44aa99"),
    "gru-stack4": ("GRU + 4-Stack", "#999933"),
    "gtrxl": ("GTrXL-PPO", "#88ccee"),
    "lstm-helm": ("LSTM + HELM", "#cc6677"),
    "trxl_gt": ("TrXL-PPO + GT", "#ddcc77"),
    "trxl_recon": ("TrXL-PPO + recon.", "#f0e442"),
}


def committed_methods() -> set[str]:
    """The method names of the committed results (results/**/episodes.csv and summary.json)."""
    methods = set()
    for path in ROOT.glob("results/**/episodes.csv"):
        with open(path, newline="") as rows:
            methods |= {row["method"] for row in csv.DictReader(rows)}
    for path in ROOT.glob("results/**/summary.json"):
        stack = [json.loads(path.read_text())]
        while stack:  # every "method" value at any depth
            node = stack.pop()
            if isinstance(node, dict):
                methods |= {node["method"]} if isinstance(node.get("method"), str) else set()
                stack.extend(node.values())
            elif isinstance(node, list):
                stack.extend(node)
    return methods


def test_figures_label_and_colour_every_committed_method_as_before() -> None:
    methods = committed_methods()
    assert methods >= {"ppo", "gru", "trxl", "mamba2", "stack4"}
    for path in sorted((ROOT / "configs").rglob("*.yaml")):
        methods |= {point.config.method for point in expand_grid(read_config_file(path))}
    assert methods <= set(BEFORE), f"methods to add to BEFORE: {sorted(methods - set(BEFORE))}"
    colours = plots.method_colors(BEFORE)
    assert list(colours.items()) == [(method, colour) for method, (_, colour) in BEFORE.items()], "order and colours"
    assert {method: plots.method_label(method) for method in BEFORE} == {m: label for m, (label, _) in BEFORE.items()}


def test_suffix_and_part_rules_name_no_memory() -> None:
    """An auxiliary loss's suffix and a derived name's parts work for any memory of the registry."""
    assert plots.method_label("gru_recon") == "GRU-PPO + recon." and plots.method_label("gtrxl_gt") == "GTrXL-PPO + GT"
    assert plots.method_label("mamba2-stack4") == "Mamba2 + 4-Stack"
    assert plots.method_label("gru-stack4_recon") == "GRU + 4-Stack + recon."
    assert plots.method_label("custom_gt") == "custom_gt" and plots.method_label("_gt") == "_gt"


def test_the_metric_table_knows_ranges_and_chance_levels() -> None:
    assert (METRICS["ProofOfMemory-v0"].low, METRICS["ProofOfMemory-v0"].high) == (0.0, 1.0)
    assert plots.metric_range("MortarMayhem-Grid-v0") == (0.0, 1.0)
    assert plots.metric_range("MortarMayhem-Grid-v0", "metric_reference") == (0.0, 1.0)
    assert plots.metric_range("Endless-MysteryPath-v0") == (0.0, None)
    assert plots.metric_range("MysteryPath-v0", "return") == (None, None)
    assert plots.chance_level("ProofOfMemory-v0", None) == 0.5 == plots.chance_level("ProofOfMemory-v0", {"delay": 9})
    assert plots.chance_level("MortarMayhem-Grid-v0", {"command_count": [1]}) == pytest.approx(0.2)  # 1 of 5
    ten = sum(0.2**k for k in range(1, 11)) / 10  # the default: 10 commands, the episode ends at the first miss
    assert plots.chance_level("MortarMayhem-Grid-v0", {}) == pytest.approx(ten)
    assert plots.chance_level("MortarMayhem-v0", {"command_count": [1, 2]}) == pytest.approx(
        (1 / 9 + (1 / 9 + 1 / 81) / 2) / 2
    )
    assert plots.chance_level("MortarMayhem-Grid-v0", None) is None, "options unknown"
    assert plots.chance_level("MortarMayhem-Grid-v0", {"command_count": [1]}, "metric_reference") is None
    for env_id in ("MortarMayhemB-Grid-v0", "MysteryPath-v0", "SearingSpotlights-v0", "Endless-MysteryPath-v0"):
        assert plots.chance_level(env_id, {}) is None, env_id


def test_task_titles_name_the_env_and_its_options() -> None:
    assert plots.task_title("MortarMayhem-Grid-v0", {"command_count": [1]}) == "MortarMayhem-Grid-v0, command_count=1"
    assert plots.task_title("ProofOfMemory-v0", {"delay": 16, "reward_wrong": -1.0}) == (
        "ProofOfMemory-v0, delay=16, reward_wrong=-1.0"
    )
    assert plots.task_title("MortarMayhem-Grid-v0", {"command_count": [1, 2]}) == (
        "MortarMayhem-Grid-v0, command_count=[1, 2]"
    )
    assert plots.task_title("ProofOfMemory-v0", {}, "delay6") == "ProofOfMemory-v0"
    assert plots.task_title("ProofOfMemory-v0", None, "delay6") == "ProofOfMemory-v0 (delay6)", "options unknown"


@pytest.fixture(scope="module")
def with_options(tmp_path_factory: pytest.TempPathFactory) -> results.Results:
    """Mortar Mayhem under the sweep-style task name mm1 with one command, ProofOfMemory with delay 16."""
    tasks = {"mm1": "MortarMayhem-Grid-v0", "pom16": "ProofOfMemory-v0"}
    directory = tmp_path_factory.mktemp("o") / "results"
    write_results(directory, methods=("ppo", "gru"), tasks=tasks)
    rows = episode_rows(methods=("ppo", "gru"), tasks=tasks)
    for row in rows:
        row["env_options"] = '{"command_count":[1]}' if row["task"] == "mm1" else '{"delay":16}'
    write_csv(directory / "episodes.csv", rows, results.EPISODE_COLUMNS)
    return results.read_results(directory)


def test_curves_span_the_metric_range_unless_zoomed(with_options: results.Results) -> None:
    episodes, training = with_options.episodes.where(method="ppo"), with_options.training.where(method="ppo")
    fixed = plots.curves_figure(episodes, training, reps=100)
    zoomed = plots.curves_figure(episodes, training, reps=100, zoom=True)
    pad = plots.RANGE_PAD
    for row in (1, 3):  # the novel-seed panels: the metric on [0, 1], padded a little; PPO stays below 0.6
        assert fixed.axes[row].get_ylim() == pytest.approx((-pad, 1 + pad))
        assert zoomed.axes[row].get_ylim()[1] < 0.6
    for row in (0, 2):  # training return: no known range, fitted to the data either way
        assert fixed.axes[row].get_ylim() == pytest.approx(zoomed.axes[row].get_ylim())


def test_chance_lines_where_the_table_knows_them(with_options: results.Results) -> None:
    figure = plots.curves_figure(with_options.episodes, with_options.training, reps=100)
    titles = [axes.get_title() for axes in figure.axes]
    assert titles == [
        "MortarMayhem-Grid-v0, command_count=1: training seeds",
        "MortarMayhem-Grid-v0, command_count=1: novel seeds",
        "ProofOfMemory-v0, delay=16: training seeds",
        "ProofOfMemory-v0, delay=16: novel seeds",
    ]
    for axes, level in ((figure.axes[1], 0.2), (figure.axes[3], 0.5)):
        (line,) = chance_lines(axes)
        assert np.allclose(line.get_ydata(), level) and line.get_linestyle() == "--"
    assert not chance_lines(figure.axes[0]) and not chance_lines(figure.axes[2]), "none for the training return"
    assert legend_texts(figure) == ["PPO", "GRU-PPO", "chance"]
    final = plots.final_figure(with_options.episodes, reps=100)
    for axes, level in zip(final.axes, (0.2, 0.5), strict=True):
        (line,) = chance_lines(axes)
        assert np.allclose(line.get_xdata(), level)
        assert axes.get_xlim() == pytest.approx((-plots.RANGE_PAD, 1 + plots.RANGE_PAD))
        assert [label.get_text() for label in axes.get_yticklabels()] == ["PPO", "GRU-PPO"]
    assert final.axes[0].get_title().replace("\n", " ").startswith("MortarMayhem-Grid-v0, command_count=1")
    # options unknown (older records): ProofOfMemory's chance does not depend on them, Mortar Mayhem's does
    unknown = with_options.episodes.select(np.ones(len(with_options.episodes), dtype=bool))
    unknown.columns["env_options"] = np.full(len(unknown), "")
    figure = plots.curves_figure(unknown, None, reps=100)
    assert [axes.get_title() for axes in figure.axes] == [
        "MortarMayhem-Grid-v0 (mm1): novel seeds",
        "ProofOfMemory-v0 (pom16): novel seeds",
    ]
    assert not chance_lines(figure.axes[0]) and len(chance_lines(figure.axes[1])) == 1


def test_methods_without_a_shared_step_leave_the_legend_and_are_named(tmp_path: Path) -> None:
    rows = episode_rows(methods=("ppo", "gru", "stack4"), tasks={"ProofOfMemory-v0": "ProofOfMemory-v0"}, runs=2)
    for row in rows:
        if row["method"] == "stack4":  # its two runs were evaluated at different steps
            row["step"] += 1 if row["run"].endswith("1") else 0
    write_csv(tmp_path / "r" / "episodes.csv", rows, results.EPISODE_COLUMNS)
    episodes = results.read_episodes(tmp_path / "r")
    with pytest.warns(results.ResultsWarning) as caught:
        figure = plots.curves_figure(episodes, None, reps=100)
    assert legend_texts(figure) == ["PPO", "GRU-PPO", "chance"]
    assert FIXED["stack4"] not in {color for _, color in line_colors(figure)}
    assert any("'stack4' (4-Stack)" in str(w.message) and "drawn in no panel" in str(w.message) for w in caught)


def test_plot_results_finds_the_options_of_older_records_in_the_saved_configs(tmp_path: Path) -> None:
    """The committed CPU panel predates the env_options column: its titles and chance line come from config.yaml."""
    committed = Path(__file__).resolve().parents[3] / "results" / "cpu" / "mm_grid_1" / "results"
    loaded = results.read_results(committed)
    options = results.task_options(loaded.episodes, [committed])
    figure = plots.final_figure(loaded.episodes, reps=50, options=options)
    (axes,) = figure.axes
    assert axes.get_title().replace("\n", " ").startswith("MortarMayhem-Grid-v0, command_count=1")
    assert np.allclose(chance_lines(axes)[0].get_xdata(), 0.2)
    assert [label.get_text() for label in axes.get_yticklabels()] == [
        "PPO",
        "GRU-PPO",
        "4-Stack",
        "16-Stack",
        "HELM",
        "TrXL-PPO",
        "LRU-PPO",
        "FFM-PPO",
        "Mamba-PPO",
        "Mamba2-PPO",
    ]
