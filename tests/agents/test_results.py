"""agents.results on synthetic records: reading, run-level scores, matrices, curves, aggregates and summaries."""

from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest

from agents import results, stats
from agents.results import EPISODE_COLUMNS, ResultsWarning
from tests.support.synthetic_results import episode_rows, training_rows, write_csv, write_results


@pytest.fixture
def results_dir(tmp_path: Path) -> Path:
    return write_results(tmp_path / "results")


def brute_scores(rows: list[dict], column: str = "metric") -> dict[tuple[str, int], float]:
    """(run, step) -> mean of the column, by plain Python."""
    grouped = defaultdict(list)
    for row in rows:
        grouped[(row["run"], row["step"])].append(float(row[column]))
    return {key: sum(values) / len(values) for key, values in grouped.items()}


def test_read_episodes_types_and_defaults(tmp_path: Path) -> None:
    rows = episode_rows(methods=("gru",), runs=2, steps=(10,), seeds=2, repetitions=1)
    rows[0]["task"] = ""  # the task defaults to the environment id
    write_csv(tmp_path / "a" / "episodes.csv", rows, EPISODE_COLUMNS)
    episodes = results.read_episodes(tmp_path / "a")
    assert episodes.names[: len(EPISODE_COLUMNS)] == list(EPISODE_COLUMNS) and "success" in episodes
    assert len(episodes) == len(rows)
    assert episodes["step"].dtype == np.int64 and episodes["seed"].dtype == np.int64
    assert episodes["metric"].dtype == np.float64 and episodes["run"].dtype.kind == "U"
    assert episodes["task"][0] == rows[0]["env_id"]


def test_several_directories_are_concatenated_with_their_own_extra_columns(tmp_path: Path) -> None:
    first = episode_rows(methods=("gru",), runs=1, steps=(10,), seeds=2, repetitions=1)
    second = episode_rows(methods=("ppo",), runs=1, steps=(10,), seeds=2, repetitions=1)
    for row in second:
        del row["success"]
        row["coins_collected"] = 3
    write_csv(tmp_path / "a" / "episodes.csv", first, EPISODE_COLUMNS)
    write_csv(tmp_path / "b" / "episodes.csv", second, EPISODE_COLUMNS)
    episodes = results.read_episodes(tmp_path / "a", tmp_path / "b")
    assert len(episodes) == len(first) + len(second)
    n = len(first)
    assert np.all(np.isnan(episodes["coins_collected"][:n])) and np.all(episodes["coins_collected"][n:] == 3)
    assert np.all(np.isnan(episodes["success"][n:])) and np.all(np.isfinite(episodes["success"][:n]))


def test_bad_input_names_what_is_wrong(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="nowhere does not exist"):
        results.read_episodes(tmp_path / "nowhere")
    (tmp_path / "empty").mkdir()
    with pytest.raises(FileNotFoundError, match="has no episodes.csv"):
        results.read_episodes(tmp_path / "empty")
    rows = episode_rows(methods=("gru",), runs=1, steps=(10,), seeds=2, repetitions=1)
    without = [{k: v for k, v in row.items() if k != "metric_reference"} for row in rows]
    write_csv(tmp_path / "c" / "episodes.csv", without, [c for c in EPISODE_COLUMNS if c != "metric_reference"])
    with pytest.raises(ValueError, match="lacks the column\\(s\\) metric_reference"):
        results.read_episodes(tmp_path / "c")
    swapped = ["method", "run", *EPISODE_COLUMNS[2:]]
    write_csv(tmp_path / "d" / "episodes.csv", rows, swapped)
    with pytest.raises(ValueError, match="in this order"):
        results.read_episodes(tmp_path / "d")
    bad = [dict(row) for row in rows]
    bad[1]["return"] = "oops"
    write_csv(tmp_path / "e" / "episodes.csv", bad, EPISODE_COLUMNS)
    with pytest.raises(ValueError, match="line 3: column 'return' holds 'oops'"):
        results.read_episodes(tmp_path / "e")
    bad = [dict(row) for row in rows]
    bad[0]["step"] = ""
    write_csv(tmp_path / "f" / "episodes.csv", bad, EPISODE_COLUMNS)
    with pytest.raises(ValueError, match="line 2: column 'step' is empty"):
        results.read_episodes(tmp_path / "f")
    bad = [dict(row) for row in rows]
    bad[0]["env_id"] = "MysteryPath-v0"
    write_csv(tmp_path / "g" / "episodes.csv", bad, EPISODE_COLUMNS)
    with pytest.raises(ValueError, match="run 'gru/.*/gru-.*' appears with several env_id values"):
        results.read_episodes(tmp_path / "g")
    write_csv(tmp_path / "h" / "episodes.csv", rows, EPISODE_COLUMNS)
    with pytest.raises(ValueError, match="the same run read twice"):
        results.read_episodes(tmp_path / "h", tmp_path / "h")
    write_csv(tmp_path / "j" / "episodes.csv", [], EPISODE_COLUMNS)
    with pytest.raises(ValueError, match="holds no episode records"):
        results.read_episodes(tmp_path / "j")
    (tmp_path / "i").mkdir()
    (tmp_path / "i" / "episodes.csv").write_text("")
    with pytest.raises(ValueError, match="is empty"):
        results.read_episodes(tmp_path / "i")


def test_runs_are_named_within_their_method_and_task(tmp_path: Path) -> None:
    """Sweeps name run directories seed<k> under <method>/<task>/: the same name in two methods is two runs."""
    rows = episode_rows(methods=("gru", "ppo"), runs=2, steps=(10,), seeds=2, repetitions=1)
    for row in rows:
        row["run"] = row["run"].split("-")[-1]  # drop the method from the name
    write_csv(tmp_path / "r" / "episodes.csv", rows, EPISODE_COLUMNS)
    scores = results.run_scores(results.read_episodes(tmp_path / "r"))
    tasks = {row["task"] for row in rows}
    assert len(scores) == 2 * len(tasks) * 2 and sorted(set(scores["run"].tolist())) == sorted(
        {row["run"] for row in rows}
    )
    assert {m: len(s.matrix()) for m, s in results.score_matrices(results.read_episodes(tmp_path / "r")).items()} == {
        "gru": 2,
        "ppo": 2,
    }


def test_training_is_optional_with_a_warning(tmp_path: Path) -> None:
    directory = write_results(tmp_path / "r", training=False)
    with pytest.warns(ResultsWarning, match="no training.csv"):
        loaded = results.read_results(directory)
    assert loaded.training is None and len(loaded.episodes)


def test_training_and_episodes_must_agree_on_a_run(tmp_path: Path) -> None:
    directory = write_results(tmp_path / "r", methods=("gru",))
    rows = training_rows(methods=("gru",))
    for row in rows:
        row["env_id"] = "MysteryPath-v0"
    write_csv(directory / "training.csv", rows, results.TRAINING_COLUMNS)
    with pytest.raises(ValueError, match="episodes.csv and training.csv: run 'gru/.*' appears with several env_id"):
        results.read_results(directory)


def test_run_scores_are_episode_means(results_dir: Path) -> None:
    rows = episode_rows()
    scores = results.run_scores(results.read_episodes(results_dir))
    expected = brute_scores(rows)
    assert len(scores) == len(expected)
    for i in range(len(scores)):
        key = (str(scores["run"][i]), int(scores["step"][i]))
        assert scores["score"][i] == pytest.approx(expected[key], abs=1e-12)
        assert scores["episodes"][i] == 4 * 2


def test_empty_and_partly_empty_columns(tmp_path: Path) -> None:
    tasks = {"ProofOfMemory-v0": "ProofOfMemory-v0", "Endless-MortarMayhem-v0": "Endless-MortarMayhem-v0"}
    directory = write_results(tmp_path / "r", tasks=tasks, training=False)
    episodes = results.read_episodes(directory)
    with pytest.warns(ResultsWarning, match="'success' is empty for 18 run/step pair\\(s\\)"):
        scores = results.run_scores(episodes, "success")
    assert set(scores["task"].tolist()) == {"ProofOfMemory-v0"}
    rows = episode_rows(methods=("gru",), runs=1, steps=(10,), seeds=2, repetitions=1)
    rows[0]["metric"] = ""
    write_csv(tmp_path / "p" / "episodes.csv", rows, EPISODE_COLUMNS)
    with pytest.raises(ValueError, match="'metric' is empty in 1 of the 2 episodes of run"):
        results.run_scores(results.read_episodes(tmp_path / "p"))
    with pytest.raises(ValueError, match="column 'method' is not numeric"):
        results.run_scores(episodes, "method")
    with pytest.raises(KeyError, match="no column 'coins'"):
        results.run_scores(episodes, "coins")


def test_score_matrices_and_curves(results_dir: Path) -> None:
    episodes = results.read_episodes(results_dir)
    expected = brute_scores(episode_rows())
    matrices = results.score_matrices(episodes)
    assert set(matrices) == {"gru", "ppo"}
    gru = matrices["gru"]
    assert gru.tasks == ("MortarMayhem-Grid-v0", "ProofOfMemory-v0") and gru.matrix().shape == (3, 2)
    for j, task in enumerate(gru.tasks):
        for i in range(3):
            assert gru.runs[j][i] == f"gru-{task}-{i}"
            assert gru.matrix()[i, j] == pytest.approx(expected[(f"gru-{task}-{i}", 24576)])
    assert results.score_matrices(episodes, step=8192)["gru"].matrix()[0, 1] == pytest.approx(
        expected[("gru-ProofOfMemory-v0-0", 8192)]
    )
    curves = results.score_curves(episodes)
    assert curves["ppo"].array().shape == (3, 2, 3)
    assert curves["ppo"].checkpoints.tolist() == [8192, 16384, 24576]
    assert curves["ppo"].array()[2, 0, 1] == pytest.approx(expected[("ppo-MortarMayhem-Grid-v0-2", 16384)])
    with pytest.raises(ValueError, match="3 checkpoints"):
        curves["ppo"].matrix()


def test_aggregate_equals_stats_on_the_matrices(results_dir: Path) -> None:
    episodes = results.read_episodes(results_dir)
    rows = results.aggregate(episodes, reps=500, seed=3)
    assert {(row["method"], row["task"]) for row in rows} == {
        (method, task) for method in ("gru", "ppo") for task in ("MortarMayhem-Grid-v0", "ProofOfMemory-v0", "all")
    }
    assert len(rows) == 2 * 3 * 3
    curves = results.score_curves(episodes)
    for row in rows:
        k = [8192, 16384, 24576].index(row["step"])
        array = curves[row["method"]].array()[:, :, k]
        matrix = array if row["task"] == "all" else array[:, [curves[row["method"]].tasks.index(row["task"])]]
        point, low, high = stats.interval_estimates({"m": matrix}, reps=500, seed=3)["m"]
        assert (row["iqm"], row["low"], row["high"]) == pytest.approx((point, low, high), abs=1e-12)
        assert row["runs"] == matrix.size and row["episodes"] == matrix.size * 8
    last = results.aggregate(episodes, steps="last", reps=200)
    assert {row["step"] for row in last} == {24576} and len(last) == 6
    only = results.aggregate(episodes, steps=16384, reps=200, overall=False)
    assert {row["step"] for row in only} == {16384} and {row["task"] for row in only} != {"all"}


def test_different_checkpoints_use_shared_steps_with_a_warning(tmp_path: Path) -> None:
    rows = episode_rows(methods=("gru",), tasks={"ProofOfMemory-v0": "ProofOfMemory-v0"}, runs=3)
    rows = [row for row in rows if not (row["run"].endswith("-2") and row["step"] == 16384)]  # a checkpoint missing
    rows += [{**row, "step": 32768} for row in rows if row["run"].endswith("-0") and row["step"] == 24576]
    write_csv(tmp_path / "r" / "episodes.csv", rows, EPISODE_COLUMNS)
    episodes = results.read_episodes(tmp_path / "r")
    with pytest.warns(
        ResultsWarning, match="different steps .* using the 2 step\\(s\\) all runs share and leaving out 2"
    ):
        aggregated = results.aggregate(episodes, reps=100)
    assert [row["step"] for row in aggregated] == [8192, 24576]
    assert all(row["runs"] == 3 for row in aggregated)
    with pytest.warns(ResultsWarning, match="runs end at different steps \\(24576, 32768\\)"):
        last = results.aggregate(episodes, steps="last", reps=100)
    assert last[0]["step"] == 32768 and last[0]["runs"] == 3
    with pytest.warns(ResultsWarning, match="have no episodes at some of the step"):
        results.aggregate(episodes, steps=[16384], reps=100)
    with pytest.raises(ValueError, match="no episodes at step\\(s\\) 5"):
        results.aggregate(episodes, steps=5)


def test_ragged_tasks_aggregate_but_refuse_a_matrix(tmp_path: Path) -> None:
    rows = episode_rows(methods=("gru",), runs=3)
    rows = [row for row in rows if row["run"] != "gru-ProofOfMemory-v0-2"]
    write_csv(tmp_path / "r" / "episodes.csv", rows, EPISODE_COLUMNS)
    episodes = results.read_episodes(tmp_path / "r")
    with pytest.raises(ValueError, match="different numbers of runs per task \\(MortarMayhem-Grid-v0: 3, Proof"):
        results.score_matrices(episodes)["gru"].matrix()
    overall = [row for row in results.aggregate(episodes, reps=100) if row["task"] == "all"]
    assert [row["runs"] for row in overall] == [5, 5, 5]


def test_run_summary_and_summarize(results_dir: Path) -> None:
    rows = episode_rows()
    episodes = results.read_episodes(results_dir)
    summary = results.run_summary(episodes)
    assert len(summary) == 2 * 2 * 3 * 3
    returns = defaultdict(list)
    for row in rows:
        returns[(row["run"], row["step"])].append(row["return"])
    metric = brute_scores(rows)
    reference = brute_scores(rows, "metric_reference")
    for row in summary:
        key = (row["run"], row["step"])
        assert row["episodes"] == 8
        assert row["mean"] == pytest.approx(np.mean(returns[key]))
        assert row["iqm"] == pytest.approx(stats.iqm(returns[key]))
        assert row["metric"] == pytest.approx(metric[key])
        assert row["metric_reference"] == pytest.approx(reference[key])
    document = results.summarize(episodes, reps=100)
    assert json.loads(json.dumps(document)) == document
    assert document["runs"] == summary and len(document["aggregate"]) == 18
    assert document["aggregate_of"]["confidence"] == 0.95


def test_training_curves(tmp_path: Path) -> None:
    loaded = results.read_results(write_results(tmp_path / "r"))
    curves = results.training_curves(loaded.training, points=10, smoothing=0.1)
    assert set(curves) == {(m, t) for m in ("gru", "ppo") for t in ("MortarMayhem-Grid-v0", "ProofOfMemory-v0")}
    gru = curves[("gru", "ProofOfMemory-v0")]
    assert gru.columns[0].shape == (3, 10) and gru.episodes is None
    assert gru.checkpoints[0] == 1024 and gru.checkpoints[-1] == 29 * 1024  # the last finite update is the 29th
    point = results.estimate(gru, "ProofOfMemory-v0", reps=100)
    assert [row["step"] for row in point] == gru.checkpoints.tolist() and point[0]["episodes"] is None
    assert point[-1]["iqm"] > point[0]["iqm"] + 0.5, "the synthetic return rises"
    rows = training_rows(methods=("gru",), tasks={"ProofOfMemory-v0": "ProofOfMemory-v0"})
    rows = [row for row in rows if not (row["run"].endswith("-1") and row["step"] > 20 * 1024)]
    write_csv(tmp_path / "t" / "training.csv", rows, results.TRAINING_COLUMNS)
    with pytest.warns(ResultsWarning, match="logs end at different steps"):
        cut = results.training_curves(results.read_training(tmp_path / "t"), points=10)
    assert cut[("gru", "ProofOfMemory-v0")].checkpoints[-1] == 19 * 1024


def test_moving_average_keeps_means_at_the_edges() -> None:
    values = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    np.testing.assert_allclose(results._moving_average(values, 3), [1.5, 2.0, 3.0, 4.0, 4.5])
    np.testing.assert_array_equal(results._moving_average(values, 1), values)


def test_format_table() -> None:
    text = results.format_table([{"method": "gru", "iqm": 0.5, "episodes": None}, {"method": "ppo", "iqm": 0.25}])
    assert text.splitlines() == ["method     iqm  episodes", "   gru  0.5000         -", "   ppo  0.2500         -"]
    assert results.format_table([]) == "(no rows)"
