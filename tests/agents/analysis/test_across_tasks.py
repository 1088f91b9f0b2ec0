"""agents.analysis.across_tasks: the aggregates against the rliable package (point estimates equal to 1e-12,
bootstrap intervals at the same quantiles of rliable's own bootstrap distribution up to Monte-Carlo noise, as
test_stats.py does for the IQM), and a panel's summary across tasks (normalisation, methods left out)."""

from __future__ import annotations

import numpy as np
import pytest

from agents.analysis import across_tasks as aggregate
from agents.analysis.results import Records
from tests.support.synthetic_results import episode_rows

rliable_library = pytest.importorskip("rliable.library")
rliable_metrics = pytest.importorskip("rliable.metrics")

REPS = 2000


def assert_same_quantile(ours: float, theirs: np.ndarray, p: float, reps: int) -> None:
    """``ours`` (the p-quantile of ``reps`` replicates) is a p-quantile of rliable's replicates ``theirs`` up to
    noise; with ties the levels at which it sits span an atom's jump, any level of which is a correct quantile."""
    tolerance = 5 * np.sqrt(p * (1 - p) * (1 / reps + 1 / len(theirs)))
    below, at_most = np.mean(theirs < ours - 1e-12), np.mean(theirs <= ours + 1e-12)
    assert below - tolerance <= p <= at_most + tolerance, (ours, below, at_most, p)


MATRICES = {
    "3x4 uniform": np.random.default_rng(0).random((3, 4)),
    "5x6 ties": np.random.default_rng(1).integers(0, 3, size=(5, 6)) / 2.0,
    "3x4 above one": np.random.default_rng(2).random((3, 4)) * 1.6,
}
RLIABLE = {
    "iqm": rliable_metrics.aggregate_iqm,
    "mean": rliable_metrics.aggregate_mean,
    "median": rliable_metrics.aggregate_median,
    "optimality_gap": rliable_metrics.aggregate_optimality_gap,
}


@pytest.mark.parametrize("name", list(MATRICES))
@pytest.mark.parametrize("statistic", list(RLIABLE))
def test_aggregates_and_their_intervals_match_rliable(name: str, statistic: str) -> None:
    scores = MATRICES[name]
    ours = aggregate.interval(scores, aggregate.STATISTICS[statistic], reps=REPS, seed=3)
    assert ours[0] == pytest.approx(RLIABLE[statistic](scores), abs=1e-12)
    np.random.seed(7)  # noqa: NPY002  (rliable follows only the global seed)
    theirs = rliable_library.StratifiedBootstrap(scores).apply(lambda s: np.array([RLIABLE[statistic](s)]), 5_000)
    assert_same_quantile(ours[1], theirs[:, 0], 0.025, REPS)
    assert_same_quantile(ours[2], theirs[:, 0], 0.975, REPS)


@pytest.mark.slow
@pytest.mark.parametrize(("x", "y"), [("3x4 uniform", "3x4 above one"), ("5x6 ties", "5x6 ties")])
def test_probability_of_improvement_matches_rliable(x: str, y: str) -> None:
    sx, sy = MATRICES[x], MATRICES[y] if x != y else MATRICES[y][::-1] * 0.9
    point, low, high = aggregate.improvement_interval(sx, sy, reps=REPS, seed=3)
    assert point == pytest.approx(rliable_metrics.probability_of_improvement(sx, sy), abs=1e-12)
    np.random.seed(7)  # noqa: NPY002
    theirs = rliable_library.StratifiedIndependentBootstrap(sx, sy).apply(
        lambda a, b: np.array([rliable_metrics.probability_of_improvement(a, b)]), 3_000
    )
    assert_same_quantile(low, theirs[:, 0], 0.025, REPS)
    assert_same_quantile(high, theirs[:, 0], 0.975, REPS)
    assert aggregate.probability_of_improvement(sx, sx) == 0.5  # a method against itself


@pytest.mark.slow
def test_score_profile_matches_rliable() -> None:
    scores = MATRICES["3x4 uniform"]
    taus = np.linspace(0.0, 1.0, 11)
    points, lows, highs = aggregate.score_profile(scores, taus, reps=REPS, seed=3)
    np.random.seed(7)  # noqa: NPY002
    profiles, intervals = rliable_library.create_performance_profile({"m": scores}, taus, reps=200)
    np.testing.assert_allclose(points, profiles["m"], atol=1e-12)
    np.random.seed(7)  # noqa: NPY002
    theirs = rliable_library.StratifiedBootstrap(scores).apply(
        lambda s: np.mean(s[..., None] > taus, axis=(0, 1)), 5_000
    )
    for k in range(len(taus)):
        assert_same_quantile(lows[k], theirs[:, k], 0.025, REPS)
        assert_same_quantile(highs[k], theirs[:, k], 0.975, REPS)
    assert intervals["m"].shape == (2, len(taus))


def test_normalise_and_bad_input() -> None:
    np.testing.assert_allclose(
        aggregate.normalise([[0.2, 5.0], [0.6, 15.0]], [0.2, 5.0], [1.0, 25.0]), [[0.0, 0.0], [0.5, 0.5]]
    )
    with pytest.raises(ValueError, match="high must exceed its low"):
        aggregate.normalise([[1.0]], 1.0, 1.0)
    with pytest.raises(ValueError, match="NaN"):
        aggregate.interval([[np.nan]], aggregate.iqm)
    with pytest.raises(ValueError, match="same tasks"):
        aggregate.improvement_interval(np.ones((3, 2)), np.ones((3, 1)))
    with pytest.raises(ValueError, match="confidence"):
        aggregate.interval(np.ones((3, 2)), aggregate.iqm, confidence=1.5)


def test_seeded() -> None:
    scores = MATRICES["3x4 uniform"]
    assert aggregate.interval(scores, aggregate.iqm, seed=4) == aggregate.interval(scores, aggregate.iqm, seed=4)


def _panel(methods: dict[str, float], tasks: dict[str, str], runs: int = 3) -> Records:
    rows = []
    for task_index, (task, env_id) in enumerate(tasks.items()):
        for method, skill in methods.items():
            for run in range(runs):
                for seed in range(4):
                    value = skill * (1 + task_index) * (0.8 + 0.1 * run) if env_id.startswith("Endless") else skill
                    metric = value if env_id.startswith("Endless") else float((seed + run) % 4 < 4 * skill)
                    rows.append(
                        {
                            **episode_rows(
                                methods=(method,), tasks={task: env_id}, runs=1, steps=(512,), seeds=1, repetitions=1
                            )[0],
                            "run": f"seed{run}",
                            "seed": 100 + seed,
                            "metric": metric,
                        }
                    )
    return Records({name: np.array([row[name] for row in rows]) for name in rows[0]})


def test_a_panel_is_normalised_per_task_and_aggregated_per_method() -> None:
    """ProofOfMemory's chance (0.5) is its floor and 1.0 its ceiling; an endless task without a chance level goes
    from PPO's mean final score to the best run's; a method missing on a task is left out, named."""
    tasks = {"cue": "ProofOfMemory-v0", "endless": "Endless-MysteryPath-v0"}
    records = _panel({"ppo": 0.5, "gru": 1.0, "lru": 0.75}, tasks)
    summary = aggregate.across_tasks(records, reps=300, options={"cue": {}, "endless": {}})
    bounds = summary["bounds"]
    assert (bounds["cue"]["low"], bounds["cue"]["low_from"], bounds["cue"]["high"]) == (0.5, "chance", 1.0)
    endless_ppo = np.mean([0.5 * 2 * (0.8 + 0.1 * run) for run in range(3)])
    assert bounds["endless"]["low"] == pytest.approx(endless_ppo) and bounds["endless"]["low_from"].startswith("ppo")
    assert (
        bounds["endless"]["high"] == pytest.approx(1.0 * 2 * 1.0) and bounds["endless"]["high_from"] == "best final run"
    )
    gru = summary["methods"]["gru"]
    assert gru["mean"][0] == pytest.approx(
        np.mean([1.0, np.mean([(2 * x - endless_ppo) / (2.0 - endless_ppo) for x in (0.8, 0.9, 1.0)])])
    )
    assert gru["optimality_gap"][0] >= 0 and len(gru["profile"]["point"]) == len(summary["taus"])
    assert "improvement_over_gru" in summary["methods"]["lru"] and "improvement_over_gru" not in gru
    assert summary["methods"]["lru"]["improvement_over_gru"][0] < 0.5
    partial = Records(
        {
            name: values[~((records["method"] == "lru") & (records["task"] == "cue"))]
            for name, values in records.columns.items()
        }
    )
    summary = aggregate.across_tasks(partial, reps=100, options={"cue": {}, "endless": {}})
    assert summary["left_out"] == {"lru": "no finished runs on cue"} and set(summary["methods"]) == {"gru", "ppo"}
    one_task = Records({name: values[records["task"] == "cue"] for name, values in records.columns.items()})
    assert aggregate.across_tasks(one_task) is None


def test_a_task_in_progress_stays_out_of_the_aggregate() -> None:
    """A third task with one method's run so far would leave every method out; named in progress, it is set aside
    and the aggregate of the finished tasks is the same as without it."""
    tasks = {"cue": "ProofOfMemory-v0", "endless": "Endless-MysteryPath-v0"}
    options = {"cue": {}, "endless": {}, "late": {}}
    finished = _panel({"ppo": 0.5, "gru": 1.0, "lru": 0.75}, tasks)
    late = _panel({"lru": 1.0}, {"late": "ProofOfMemory-v0"}, runs=1)
    records = Records({name: np.concatenate([finished[name], late[name]]) for name in finished.columns})
    without = aggregate.across_tasks(finished, reps=100, options=options)
    assert aggregate.across_tasks(records, reps=100, options=options)["methods"] == {}  # every method left out
    summary = aggregate.across_tasks(records, reps=100, options=options, in_progress={"late": "1 of 9 runs finished"})
    assert summary["tasks"] == ["cue", "endless"] and summary["tasks_in_progress"] == {"late": "1 of 9 runs finished"}
    assert summary["methods"] == without["methods"] and summary["left_out"] == {}
    assert "late" in summary["bounds"]  # still normalisable, only set aside
    from agents.analysis.across_tasks_figure import across_tasks_figure

    title = across_tasks_figure(summary)._suptitle.get_text()
    assert title.startswith("Across 2 tasks (cue, endless)") and "left out while their runs train: late" in title


def test_the_figure_shows_every_aggregate(tmp_path) -> None:
    from agents.analysis.across_tasks_figure import across_tasks_figure
    from agents.analysis.plots import save_figure

    tasks = {"cue": "ProofOfMemory-v0", "endless": "Endless-MysteryPath-v0"}
    summary = aggregate.across_tasks(
        _panel({"ppo": 0.5, "gru": 1.0, "lru": 0.75}, tasks), reps=100, options={"cue": {}, "endless": {}}
    )
    figure = across_tasks_figure(summary)
    titles = [axes.get_title() for axes in figure.axes]
    assert titles[:3] == ["IQM", "Mean", "Optimality gap"] and "P(method > GRU-PPO)" in titles
    assert any(title.startswith("Performance profiles") for title in titles)
    (png, _) = save_figure(figure, tmp_path / "across_tasks")
    assert png.stat().st_size > 10_000


def test_the_figures_title_fits_its_width_however_many_tasks() -> None:
    from agents.analysis.across_tasks_figure import across_tasks_figure

    for count in (2, 4, 12):
        tasks = {f"task_with_a_long_name_{k}": "ProofOfMemory-v0" for k in range(count)}
        summary = aggregate.across_tasks(
            _panel({"ppo": 0.5, "gru": 1.0}, tasks, runs=2), reps=20, options={task: {} for task in tasks}
        )
        figure = across_tasks_figure(summary)
        figure.canvas.draw()
        title = figure._suptitle
        extent = title.get_window_extent()
        assert 0 <= extent.x0 and extent.x1 <= figure.bbox.width, (count, extent, figure.bbox.width)
        assert all(task in title.get_text().replace("\n", " ") for task in tasks)


def test_the_figure_leaves_out_the_tasks_a_summary_names_in_progress(tmp_path) -> None:
    import json

    from agents.analysis.across_tasks_figure import plot_across_tasks
    from tests.support.synthetic_results import write_results

    tasks = {"cue": "ProofOfMemory-v0", "grid": "MortarMayhem-Grid-v0"}
    results = write_results(tmp_path / "results", methods=("ppo", "gru"), tasks=tasks, training=False)
    assert [path.name for path in plot_across_tasks([results], tmp_path / "all")] == [
        "across_tasks.png",
        "across_tasks.pdf",
    ]
    summary = {"across_tasks": {"tasks_in_progress": {"grid": "2 of 6 runs finished"}}}
    (results / "summary.json").write_text(json.dumps(summary))
    assert plot_across_tasks([results], tmp_path / "one") == []  # one finished task: nothing to aggregate
