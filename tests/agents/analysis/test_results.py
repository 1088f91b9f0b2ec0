"""agents.analysis.results and agents.analysis.scores on synthetic records: reading, run-level scores, matrices, curves,
aggregates and summaries."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import warnings
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest

from agents.analysis import results, stats
from agents.analysis import scores as scoring
from agents.analysis.digest import config_digest
from agents.analysis.results import EPISODE_COLUMNS, Records, ResultsWarning
from agents.config import MAX_TASK_NAME, NOT_IN_DIGEST, check_name, dump_config, load_config, task_name
from agents.experiments.planning import load_panel
from agents.training.trainer import Trainer
from tests.support.synthetic_results import episode_rows, training_rows, write_csv, write_results

ROOT = Path(__file__).resolve().parents[3]


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
    scores = scoring.run_scores(results.read_episodes(tmp_path / "r"))
    tasks = {row["task"] for row in rows}
    assert len(scores) == 2 * len(tasks) * 2 and sorted(set(scores["run"].tolist())) == sorted(
        {row["run"] for row in rows}
    )
    assert {m: len(s.matrix()) for m, s in scoring.score_matrices(results.read_episodes(tmp_path / "r")).items()} == {
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
    scores = scoring.run_scores(results.read_episodes(results_dir))
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
        scores = scoring.run_scores(episodes, "success")
    assert set(scores["task"].tolist()) == {"ProofOfMemory-v0"}
    rows = episode_rows(methods=("gru",), runs=1, steps=(10,), seeds=2, repetitions=1)
    rows[0]["metric"] = ""
    write_csv(tmp_path / "p" / "episodes.csv", rows, EPISODE_COLUMNS)
    with pytest.raises(ValueError, match="'metric' is empty in 1 of the 2 episodes of run"):
        scoring.run_scores(results.read_episodes(tmp_path / "p"))
    with pytest.raises(ValueError, match="column 'method' is not numeric"):
        scoring.run_scores(episodes, "method")
    with pytest.raises(KeyError, match="no column 'coins'"):
        scoring.run_scores(episodes, "coins")


def test_score_matrices_and_curves(results_dir: Path) -> None:
    episodes = results.read_episodes(results_dir)
    expected = brute_scores(episode_rows())
    matrices = scoring.score_matrices(episodes)
    assert set(matrices) == {"gru", "ppo"}
    gru = matrices["gru"]
    assert gru.tasks == ("MortarMayhem-Grid-v0", "ProofOfMemory-v0") and gru.matrix().shape == (3, 2)
    for j, task in enumerate(gru.tasks):
        for i in range(3):
            assert gru.runs[j][i] == f"gru-{task}-{i}"
            assert gru.matrix()[i, j] == pytest.approx(expected[(f"gru-{task}-{i}", 24576)])
    assert scoring.score_matrices(episodes, step=8192)["gru"].matrix()[0, 1] == pytest.approx(
        expected[("gru-ProofOfMemory-v0-0", 8192)]
    )
    curves = scoring.score_curves(episodes)
    assert curves["ppo"].array().shape == (3, 2, 3)
    assert curves["ppo"].checkpoints.tolist() == [8192, 16384, 24576]
    assert curves["ppo"].array()[2, 0, 1] == pytest.approx(expected[("ppo-MortarMayhem-Grid-v0-2", 16384)])
    with pytest.raises(ValueError, match="3 checkpoints"):
        curves["ppo"].matrix()


def test_aggregate_equals_stats_on_the_matrices(results_dir: Path) -> None:
    episodes = results.read_episodes(results_dir)
    rows = scoring.aggregate(episodes, reps=500, seed=3)
    assert {(row["method"], row["task"]) for row in rows} == {
        (method, task) for method in ("gru", "ppo") for task in ("MortarMayhem-Grid-v0", "ProofOfMemory-v0", "all")
    }
    assert len(rows) == 2 * 3 * 3
    curves = scoring.score_curves(episodes)
    for row in rows:
        k = [8192, 16384, 24576].index(row["step"])
        array = curves[row["method"]].array()[:, :, k]
        matrix = array if row["task"] == "all" else array[:, [curves[row["method"]].tasks.index(row["task"])]]
        point, low, high = stats.interval_estimates({"m": matrix}, reps=500, seed=3)["m"]
        assert (row["iqm"], row["low"], row["high"]) == pytest.approx((point, low, high), abs=1e-12)
        assert row["runs"] == matrix.size and row["episodes"] == matrix.size * 8
    last = scoring.aggregate(episodes, steps="last", reps=200)
    assert {row["step"] for row in last} == {24576} and len(last) == 6
    only = scoring.aggregate(episodes, steps=16384, reps=200, overall=False)
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
        aggregated = scoring.aggregate(episodes, reps=100)
    assert [row["step"] for row in aggregated] == [8192, 24576]
    assert all(row["runs"] == 3 for row in aggregated)
    with pytest.warns(ResultsWarning, match="task 'ProofOfMemory-v0': runs end at different steps \\(24576, 32768\\)"):
        last = scoring.aggregate(episodes, steps="last", reps=100)
    assert last[0]["step"] == 32768 and last[0]["runs"] == 3
    with pytest.warns(ResultsWarning, match="have no episodes at some of the step"):
        scoring.aggregate(episodes, steps=[16384], reps=100)
    with pytest.raises(ValueError, match="no episodes at step\\(s\\) 5"):
        scoring.aggregate(episodes, steps=5)


def test_tasks_with_different_budgets_take_each_last_without_a_warning(tmp_path: Path) -> None:
    # A suite's tasks may train for different step counts: that is no mismatch, and each task's last counts.
    rows = episode_rows(methods=("gru",), runs=3)
    rows += [{**row, "step": 32768} for row in rows if row["task"] == "ProofOfMemory-v0" and row["step"] == 24576]
    write_csv(tmp_path / "r" / "episodes.csv", rows, EPISODE_COLUMNS)
    episodes = results.read_episodes(tmp_path / "r")
    with warnings.catch_warnings():
        warnings.simplefilter("error", ResultsWarning)
        matrices = scoring.score_matrices(episodes, "last")
    gru = matrices["gru"]
    ends = {task: set(at.ravel().tolist()) for task, at in zip(gru.tasks, gru.steps, strict=True)}
    assert ends == {"ProofOfMemory-v0": {32768}, "MortarMayhem-Grid-v0": {24576}}


def test_ragged_tasks_aggregate_but_refuse_a_matrix(tmp_path: Path) -> None:
    rows = episode_rows(methods=("gru",), runs=3)
    rows = [row for row in rows if row["run"] != "gru-ProofOfMemory-v0-2"]
    write_csv(tmp_path / "r" / "episodes.csv", rows, EPISODE_COLUMNS)
    episodes = results.read_episodes(tmp_path / "r")
    with pytest.raises(ValueError, match="different numbers of runs per task \\(MortarMayhem-Grid-v0: 3, Proof"):
        scoring.score_matrices(episodes)["gru"].matrix()
    overall = [row for row in scoring.aggregate(episodes, reps=100) if row["task"] == "all"]
    assert [row["runs"] for row in overall] == [5, 5, 5]


def test_run_summary_and_summarize(results_dir: Path) -> None:
    rows = episode_rows()
    episodes = results.read_episodes(results_dir)
    summary = scoring.run_summary(episodes)
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
    document = scoring.summarize(episodes, reps=100)
    assert json.loads(json.dumps(document)) == document
    assert document["runs"] == summary and len(document["aggregate"]) == 18
    assert document["aggregate_of"]["confidence"] == 0.95


def test_training_curves(tmp_path: Path) -> None:
    loaded = results.read_results(write_results(tmp_path / "r"))
    curves = scoring.training_curves(loaded.training, points=10, smoothing=0.1)
    assert set(curves) == {(m, t) for m in ("gru", "ppo") for t in ("MortarMayhem-Grid-v0", "ProofOfMemory-v0")}
    gru = curves[("gru", "ProofOfMemory-v0")]
    assert gru.columns[0].shape == (3, 10) and gru.episodes is None
    assert gru.checkpoints[0] == 1024 and gru.checkpoints[-1] == 29 * 1024  # the last finite update is the 29th
    point = scoring.estimate(gru, "ProofOfMemory-v0", reps=100)
    assert [row["step"] for row in point] == gru.checkpoints.tolist() and point[0]["episodes"] is None
    assert point[-1]["iqm"] > point[0]["iqm"] + 0.5, "the synthetic return rises"
    rows = training_rows(methods=("gru",), tasks={"ProofOfMemory-v0": "ProofOfMemory-v0"})
    rows = [row for row in rows if not (row["run"].endswith("-1") and row["step"] > 20 * 1024)]
    write_csv(tmp_path / "t" / "training.csv", rows, results.TRAINING_COLUMNS)
    with pytest.warns(ResultsWarning, match="logs end at different steps"):
        cut = scoring.training_curves(results.read_training(tmp_path / "t"), points=10)
    assert cut[("gru", "ProofOfMemory-v0")].checkpoints[-1] == 19 * 1024


def test_moving_average_keeps_means_at_the_edges() -> None:
    values = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    np.testing.assert_allclose(scoring._moving_average(values, 3), [1.5, 2.0, 3.0, 4.0, 4.5])
    np.testing.assert_array_equal(scoring._moving_average(values, 1), values)


def test_format_table() -> None:
    text = scoring.format_table([{"method": "gru", "iqm": 0.5, "episodes": None}, {"method": "ppo", "iqm": 0.25}])
    assert text.splitlines() == ["method     iqm  episodes", "   gru  0.5000         -", "   ppo  0.2500         -"]
    assert scoring.format_table([]) == "(no rows)"


# ------------------------------------------------------------------ C7: one (method, task) cell is one experiment
QUICKSTART = ROOT / "configs" / "quickstart.yaml"  # ProofOfMemory-v0, delay 16
POM_GRU = ROOT / "configs" / "proof_of_memory" / "gru.yaml"  # ProofOfMemory-v0, delay 4 (the default)


def test_default_task_names_tell_option_sets_apart() -> None:
    """The quickstart (delay 16) and configs/proof_of_memory/gru.yaml (delay 4) were one task "ProofOfMemory-v0"."""
    assert load_config(QUICKSTART).task == "ProofOfMemory-v0+delay=16"
    assert load_config(POM_GRU).task == "ProofOfMemory-v0", "default options keep the plain id (older records)"
    assert task_name("ProofOfMemory-v0", {}) == task_name("ProofOfMemory-v0", {"delay": 4}) == "ProofOfMemory-v0"
    assert task_name("ProofOfMemory-v0", {"delay": 16, "reward_correct": 1}) == "ProofOfMemory-v0+delay=16"
    name = task_name("MortarMayhem-Grid-v0", {"visual_feedback": False, "command_count": [1, 2]})
    assert name == "MortarMayhem-Grid-v0+command_count=1_2+visual_feedback=false"  # sorted by key
    assert task_name("ProofOfMemory-v0", {"reward_wrong": -1}) == "ProofOfMemory-v0+reward_wrong=-1.0"
    assert load_config(QUICKSTART, ["run.task=mine"]).task == "mine", "a given run.task wins"
    many = {"max_steps": 300, "agent_speed": 2.5, "agent_health": 100, "num_coins": [2], "coins_visible": True}
    long = task_name("SearingSpotlights-v0", many)
    assert len(long) <= MAX_TASK_NAME and re.fullmatch(r"SearingSpotlights-v0\+options=[0-9a-f]{12}", long)
    assert task_name("SearingSpotlights-v0", dict(reversed(many.items()))) == long, "independent of the key order"
    for task in (load_config(QUICKSTART).task, name, long):
        check_name("task", task)  # a file name (sweeps make it a directory) and a plain CSV field
        assert "," not in task and '"' not in task


def test_config_digest_ignores_seeds_and_bookkeeping_only() -> None:
    base = load_config(QUICKSTART)
    digest = config_digest(base)
    assert re.fullmatch(r"c[0-9a-f]{12}", digest)
    same = [
        "run.seed=5",
        "run.device=cuda",
        "run.torch_threads=2",
        "run.checkpoint_interval=3",
        "run.keep_checkpoints=0",
        "run.progress_bar=false",
        "run.method=other",
        "run.task=other",
        "eval.interval=4",
        "eval.seed=3",
        "eval.seeds=[200000,200009]",
        "eval.repetitions=2",
        "model.helm.seed=9",
        "env.options={delay: 16, reward_correct: 1}",  # the same options written out
    ]
    for override in same:
        assert config_digest(load_config(QUICKSTART, [override])) == digest, override
    different = [
        "ppo.gamma=0.9",
        "env.options={delay: 8}",
        "model.memory_size=32",
        "run.workers=8",
        "run.total_steps=65536",
        "run.precision=bf16",
        "env.train_seeds=[0,9]",
        "env.frame_skip=2",
        "eval.greedy=true",
    ]
    digests = {override: config_digest(load_config(QUICKSTART, [override])) for override in different}
    assert digest not in digests.values() and len(set(digests.values())) == len(different), digests
    assert config_digest(base, greedy=True) == digests["eval.greedy=true"], "as the evaluation played"
    assert set(NOT_IN_DIGEST) >= {"run.seed", "run.device", "run.torch_threads", "run.checkpoint_interval"}


def test_task_names_and_digests_are_the_same_in_another_process() -> None:
    code = (
        "from agents.config import load_config; from agents.analysis.digest import config_digest;"
        f"c = load_config({str(QUICKSTART)!r}); print(c.task, config_digest(c))"
    )
    env = {**os.environ, "PYTHONHASHSEED": "12345"}
    shown = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True, check=True)
    config = load_config(QUICKSTART)
    assert shown.stdout.split() == [config.task, config_digest(config)]


def test_the_seeds_of_a_sweep_cell_share_a_digest() -> None:
    """configs/cpu/mm_grid_1.yaml: 10 methods x 3 seeds; the seeds of one cell agree, the cells differ, and the
    committed runs' saved configs (torch threads set by the sweep) give their cell's digest."""
    panel = load_panel(ROOT / "configs" / "cpu" / "mm_grid_1.yaml", root=ROOT / "results" / "cpu")
    cells = defaultdict(set)
    for run in panel.runs:
        cells[(run.config.method, run.config.task)].add(config_digest(run.config))
    assert len(cells) == 10 and all(len(digests) == 1 for digests in cells.values()), cells
    assert len({digest for digests in cells.values() for digest in digests}) == 10
    for run in panel.runs:
        saved = run.run_dir / "config.yaml"
        if saved.is_file():
            config = load_config(saved)
            assert {config_digest(config)} == cells[(run.config.method, run.config.task)], run.name


def digest_rows(runs: dict[str, str], method: str = "gru", steps: tuple[int, ...] = (10,)) -> list[dict]:
    """Episode rows of one method and task (ProofOfMemory-v0), run name -> digest (a digest per step with '|')."""
    rows = []
    for index, (run, digests) in enumerate(runs.items()):
        for step, digest in zip(steps, digests.split("|") * len(steps), strict=False):
            for seed in range(2):
                rows.append(
                    {
                        **episode_rows(methods=(method,), runs=1, steps=(step,), seeds=1, repetitions=1)[0],
                        "run": run,
                        "seed": 100 + seed,
                        "metric": float((index + seed) % 2),
                        "config_digest": digest,
                    }
                )
    return rows


def test_runs_with_different_configs_in_one_cell_are_refused(tmp_path: Path) -> None:
    rows = digest_rows({"seed0": "caaaaaaaaaaaa", "seed1": "caaaaaaaaaaaa", "other": "cbbbbbbbbbbbb"})
    write_csv(tmp_path / "r" / "episodes.csv", rows, EPISODE_COLUMNS)
    with pytest.raises(ValueError) as err:
        results.read_episodes(tmp_path / "r")
    message = str(err.value)
    assert "method 'gru', task 'ProofOfMemory-v0'" in message and "differ in more than the seed" in message
    assert "caaaaaaaaaaaa: run(s) seed0, seed1" in message and "cbbbbbbbbbbbb: run(s) other" in message
    assert "config.yaml files were not found" in message
    with pytest.raises(ValueError, match="differ in more than the seed"):  # records built in memory, too
        scoring.aggregate(Records({name: np.array([row[name] for row in rows]) for name in rows[0]}))
    # with the runs' saved configs beside the results, the differing keys are named
    for run, overrides in (
        ("seed0", []),
        ("seed1", ["run.seed=1"]),
        ("other", ["ppo.gamma=0.9", "env.options.delay=8"]),
    ):
        (tmp_path / "r" / run).mkdir()
        (tmp_path / "r" / run / "config.yaml").write_text(dump_config(load_config(QUICKSTART, overrides)))
    with pytest.raises(
        ValueError, match="Differing keys: env.options.delay \\(16 in caaaaaaaaaaaa, 8 in cbbbbbbbbbbbb\\); ppo.gamma"
    ):
        results.read_episodes(tmp_path / "r")
    # training logs are checked the same way
    training = training_rows(methods=("gru",), tasks={"T": "ProofOfMemory-v0"}, runs=2, updates=3)
    for row in training:
        row["config_digest"] = "caaaaaaaaaaaa" if row["run"].endswith("0") else "cbbbbbbbbbbbb"
    write_csv(tmp_path / "t" / "training.csv", training, results.TRAINING_COLUMNS)
    with pytest.raises(ValueError, match="training.csv of .*method 'gru', task 'T'"):
        results.read_training(tmp_path / "t")


def test_configs_are_compared_within_a_cell_and_by_each_runs_latest_rows(tmp_path: Path) -> None:
    """Other methods may differ; rows without a digest (older records) are not checked; a run lengthened on resume
    changes its digest midway, and its latest rows count."""
    rows = digest_rows({"seed0": "caaaaaaaaaaaa", "seed1": ""}) + digest_rows({"seed0": "cbbbbbbbbbbbb"}, "ppo")
    write_csv(tmp_path / "a" / "episodes.csv", rows, EPISODE_COLUMNS)
    assert len(scoring.aggregate(results.read_episodes(tmp_path / "a"), reps=50)) == 2
    extended = digest_rows({"seed0": "caaaaaaaaaaaa|cbbbbbbbbbbbb", "seed1": "cbbbbbbbbbbbb"}, steps=(10, 20))
    write_csv(tmp_path / "b" / "episodes.csv", extended, EPISODE_COLUMNS)
    assert len(results.read_episodes(tmp_path / "b")) == len(extended)
    reverted = digest_rows({"seed0": "caaaaaaaaaaaa|cbbbbbbbbbbbb", "seed1": "caaaaaaaaaaaa"}, steps=(10, 20))
    write_csv(tmp_path / "c" / "episodes.csv", reverted, EPISODE_COLUMNS)
    with pytest.raises(ValueError, match="cbbbbbbbbbbbb: run\\(s\\) seed0"):
        results.read_episodes(tmp_path / "c")


@pytest.mark.parametrize("directory", ["results/cpu/mm_grid_1/results", "results/cpu/mm_grid_1_delay4/results"])
def test_committed_records_without_the_new_columns_still_load(directory: str) -> None:
    """The CPU panels' first runs predate the env_options and config_digest columns; the TrXL, LRU, FFM, Mamba and
    Mamba-2 runs added to mm_grid_1 later carry them, one digest per cell. Both kinds load and aggregate side by
    side."""
    loaded = results.read_results(ROOT / directory)
    for table in (loaded.episodes, loaded.training):
        digests = dict.fromkeys(table["method"].tolist(), "")
        for method, digest in zip(table["method"].tolist(), table[results.CONFIG_COLUMN].tolist(), strict=True):
            assert digests.setdefault(method, digest) in ("", digest)
            digests[method] = digest
        later = {"trxl", "lru", "ffm", "mamba", "mamba2"}
        assert {method for method, digest in digests.items() if digest} == (
            later if "delay4" not in directory else set()
        )
    first_runs = [m not in {"trxl", "lru", "ffm", "mamba", "mamba2"} for m in loaded.episodes["method"].tolist()]
    assert {o for o, old in zip(loaded.episodes[results.OPTIONS_COLUMN].tolist(), first_runs, strict=True) if old} == {
        ""
    }
    assert len(scoring.aggregate(loaded.episodes, steps="last", reps=50))


def test_the_committed_example_records_carry_one_experiment_per_cell() -> None:
    """results/examples/ was regenerated with the new columns: every (method, task) cell holds one config digest,
    the five methods five different ones, and the options are the config's."""
    loaded = results.read_results(ROOT / "results" / "examples" / "proof_of_memory")
    cells: dict[tuple[str, str], set[str]] = {}
    for table in (loaded.episodes, loaded.training):
        for method, task, digest in zip(
            table["method"].tolist(), table["task"].tolist(), table[results.CONFIG_COLUMN].tolist(), strict=True
        ):
            cells.setdefault((method, task), set()).add(digest)
    assert len(cells) == 5 and all(len(digests) == 1 and "" not in digests for digests in cells.values())
    assert len({digest for digests in cells.values() for digest in digests}) == 5
    assert set(loaded.episodes[results.OPTIONS_COLUMN].tolist()) == {'{"delay":6}'}


def test_task_options_come_from_the_records_or_the_saved_configs(tmp_path: Path) -> None:
    committed = ROOT / "results" / "cpu" / "mm_grid_1" / "results"
    episodes = results.read_episodes(committed)
    assert results.task_options(episodes, [committed]) == {"mm_grid_1": {"command_count": [1]}}
    assert results.task_options(episodes) == {"mm_grid_1": None}, "no column, no config found: unknown"
    rows = episode_rows(methods=("gru",), runs=2, steps=(10,), seeds=1, repetitions=1)
    for row in rows:
        row["env_options"] = '{"delay":16}' if row["env_id"] == "ProofOfMemory-v0" else "{}"
    write_csv(tmp_path / "r" / "episodes.csv", rows, EPISODE_COLUMNS)
    assert results.task_options(results.read_episodes(tmp_path / "r")) == {
        "MortarMayhem-Grid-v0": {},
        "ProofOfMemory-v0": {"delay": 16},
    }


def test_training_and_evaluation_write_the_task_options_and_digest(tmp_path: Path) -> None:
    overrides = [
        "model.memory_size=8",
        "model.hidden_size=8",
        "run.total_steps=64",
        "run.workers=4",
        "run.worker_steps=16",
        "run.progress_bar=false",
        "run.torch_threads=1",
        "eval.interval=1",
        "eval.seeds=[100000,100001]",
        "eval.repetitions=1",
    ]
    config = load_config(QUICKSTART, overrides)
    Trainer(config, tmp_path / "run").train()
    loaded = results.Results(
        results.read_episodes(tmp_path / "run" / "eval"), results.read_training(tmp_path / "run"), ()
    )
    digest = config_digest(config)
    assert loaded.episodes.names[: len(EPISODE_COLUMNS)] == list(EPISODE_COLUMNS)
    assert set(loaded.episodes["task"].tolist()) == set(loaded.training["task"].tolist()) == {config.task}
    assert set(loaded.episodes["env_options"].tolist()) == {'{"delay":16}'}
    assert set(loaded.episodes["config_digest"].tolist()) == set(loaded.training["config_digest"].tolist()) == {digest}
