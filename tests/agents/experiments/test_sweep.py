"""Grids and sweeps without training: the paper panels' expansion, names, override order, errors, run states, the
disk estimate and the dry run. (Training, killing, resuming and SLURM: tests/scripts/test_sweep_script.py.)"""

from __future__ import annotations

import re
from collections import Counter
from pathlib import Path

import pytest

from agents.config import ConfigError, config_from_dict, expand_grid, slurm_minutes
from agents.experiments.dry_run import describe, disk_estimate
from agents.experiments.planning import SweepError, load_panel, panel_from_dict
from agents.experiments.state import FINISHED, NEW, PARTIAL, RUNNING, prepare_run, run_lock, run_status, statuses
from scripts import sweep as sweep_script

PAPER = Path(__file__).resolve().parents[3] / "configs" / "paper"
FIGURES = {"fig4": 75, "fig5": 20 + 25, "fig6": 20}
TINY = {
    "env": {"id": "ProofOfMemory-v0", "options": {"delay": 3}},
    "model": {"memory": "gru", "memory_size": 16, "hidden_size": 16, "vector_encoder_size": 8},
    "run": {"total_steps": 128, "workers": 4, "worker_steps": 16, "progress_bar": False},
}


@pytest.fixture(scope="module")
def paper_panels() -> dict[str, object]:
    return {path.stem: load_panel(path, root="runs") for path in sorted(PAPER.glob("fig*.yaml"))}  # the ICLR paper


def test_the_jmlr_grids_compare_gru_and_transformer_xl_with_cleanrl_settings() -> None:
    """configs/paper/jmlr_*.yaml: 5 seeds per (method, task); TrXL with CleanRL's settings and per-task windows,
    reconstruction where the grid says; GRU-PPO with the ICLR paper's Table 6."""
    finite, endless = (load_panel(PAPER / f"jmlr_{name}.yaml", root="runs") for name in ("finite", "endless"))
    assert len(finite.runs) == 75 and len(endless.runs) == 30
    windows = {"mm": 275, "mm_grid": 119, "mp": 256, "mp_grid": 96, "ss": 256}
    for run in [*finite.runs, *endless.runs]:
        config = run.config
        assert config.method in ("gru", "trxl", "trxl_recon") and config.model.memory == config.method[:4].rstrip("_")
        if config.model.memory == "trxl":
            trxl, ppo = config.model.trxl, config.ppo
            assert (trxl.layers, trxl.heads, trxl.dim) == (3, 4, 384)
            assert trxl.memory_length == windows.get(config.task, 256)
            assert (ppo.gamma, ppo.clip_range.initial, ppo.value_coef, ppo.max_grad_norm) == (0.995, 0.1, 0.5, 0.25)
            expected = 0.1 if config.method == "trxl_recon" or config.task == "endless_ss" else 0.0
            assert ppo.reconstruction_coef == expected
            normalised = "minibatch" if config.task == "mm_grid" else "none"
            assert ppo.advantage_normalization == normalised
        else:
            assert (config.ppo.gamma, config.ppo.clip_range.initial, config.model.memory_size) == (0.99, 0.2, 512)
    assert {run.config.env.id for run in endless.runs} == {
        "Endless-MortarMayhem-v0",
        "Endless-MysteryPath-v0",
        "Endless-SearingSpotlights-v0",
    }


def test_paper_figures_have_the_papers_run_counts(paper_panels: dict) -> None:
    per_figure = Counter()
    for name, panel in paper_panels.items():
        per_figure[name.split("_")[0]] += len(panel.runs)
    assert dict(per_figure) == FIGURES
    assert {name: len(panel.runs) for name, panel in paper_panels.items() if name.startswith("fig5")} == {
        "fig5_mortar_mayhem": 20,
        "fig5_mystery_path": 25,
    }


def test_paper_runs_are_named_and_configured_as_table_6(paper_panels: dict) -> None:
    names = [run.name for panel in paper_panels.values() for run in panel.runs]
    assert len(set(names)) == len(names) == sum(FIGURES.values())
    for name, panel in paper_panels.items():
        for run in panel.runs:
            config = run.config  # validated when the panel was loaded
            assert re.fullmatch(rf"{name}/[a-z0-9_]+/[a-z0-9_]+/seed[0-4]", run.name), run.name
            assert run.run_dir == Path("runs", *run.name.split("/"))
            assert run.name.split("/")[1:3] == [config.method, config.task]
            assert (config.run.workers, config.run.worker_steps, config.num_updates) == (32, 512, 10_000)
            assert run.steps == 163_840_000
            assert (config.ppo.epochs, config.ppo.minibatches, config.ppo.gamma, config.ppo.gae_lambda) == (
                3,
                8,
                0.99,
                0.95,
            )
            assert (config.ppo.value_coef, config.ppo.max_grad_norm, config.ppo.clip_range.initial) == (0.25, 0.5, 0.2)
            assert (config.ppo.learning_rate.initial, config.ppo.learning_rate.final) == (3e-4, 1e-4)
            assert (config.ppo.entropy_coef.initial, config.ppo.entropy_coef.final) == (1e-4, 1e-5)
            assert config.env.train_seeds == [0, 99_999] and config.eval_seeds == [100_000, 100_029]
            assert (config.eval.repetitions, config.eval.greedy, config.eval.interval) == (5, False, 100)
            assert config.run.keep_checkpoints == 1 and config.run.torch_threads == 0
            assert config.model.hidden_size == 512 and config.model.memory_size == 512
            spotlights, mystery = config.env.id == "SearingSpotlights-v0", config.env.id.startswith("MysteryPath")
            assert config.env.frame_skip == (2 if spotlights else 1)
            if config.model.memory == "gru":
                assert config.ppo.sequence_length == (128 if spotlights or mystery else "max")
            if config.model.helm.enabled:
                assert config.model.helm.beta == 1000.0
            assert run.config.env.options, "every task writes its options out"


def test_paper_panels_sweep_the_papers_methods_and_tasks(paper_panels: dict) -> None:
    def axes(name: str) -> tuple[set, set]:
        runs = paper_panels[name].runs
        return {run.config.method for run in runs}, {run.config.task for run in runs}

    fig4 = {"ppo", "gru", "stack4", "stack16", "helm"}
    assert axes("fig4_mmact_grid") == (fig4, {"mmact_grid"})
    assert axes("fig4_mp_grid") == (fig4, {"mp_grid_hidden_goal"})
    assert axes("fig4_searing_spotlights") == (fig4, {"searing_spotlights"})
    assert axes("fig5_mortar_mayhem") == ({"gru"}, {"mmact_grid", "mmact", "mm_grid", "mm"})
    assert axes("fig5_mystery_path") == (
        {"gru"},
        {"mp_grid", "mp_grid_hidden_goal", "mp_grid_hidden_both", "mp", "mp_dense"},
    )
    assert axes("fig6_spotlight_perturbation") == ({"ppo", "gru"}, {"ss_lit", "ss_lit_no_spotlights"})
    by_name = {run.name: run.config for panel in paper_panels.values() for run in panel.runs}
    stack16 = by_name["fig4_mmact_grid/stack16/mmact_grid/seed0"].model
    assert (stack16.memory, stack16.frame_stack, stack16.grayscale) == ("none", 16, True)
    mm = by_name["fig5_mortar_mayhem/gru/mm/seed0"].env.options
    assert (mm["command_count"], mm["explosion_duration"], mm["explosion_delay"], mm["agent_speed"]) == (
        [5],
        [6],
        [18],
        2.5,
    )
    assert by_name["fig5_mystery_path/gru/mp_dense/seed0"].env.options["reward_path_progress"] == 0.03
    goal_hidden = by_name["fig4_mp_grid/gru/mp_grid_hidden_goal/seed0"].env.options
    assert (goal_hidden["show_origin"], goal_hidden["show_goal"]) == (True, False)
    dark = by_name["fig6_spotlight_perturbation/ppo/ss_lit_no_spotlights/seed3"].env.options
    assert (dark["light_threshold"], dark["initial_spawns"], dark["num_spawns"]) == (0, 0, 0)


def test_override_order_base_bundles_plain_axes_then_set() -> None:
    raw = {
        **TINY,
        "ppo": {"gamma": 0.90, "gae_lambda": 0.90, "epochs": 1},
        "grid": {
            "task": {"t": {"ppo.gamma": 0.92, "ppo.gae_lambda": 0.92, "ppo.epochs": 2}},  # listed first: applied first
            "method": {"m": {"ppo.gamma": 0.91, "ppo.gae_lambda": 0.91}},
            "ppo.gamma": [0.93],
            "run.seed": [4],
        },
    }
    (point,) = expand_grid(raw)
    assert point.config.ppo.gamma == 0.93  # a plain axis beats every bundle
    assert point.config.ppo.gae_lambda == 0.91  # the later axis' bundle beats the earlier one
    assert point.config.ppo.epochs == 2  # a bundle beats the base
    assert point.config.run.seed == 4 and (point.config.method, point.config.task) == ("m", "t")
    assert [choice for choice, _ in point.choices] == ["task", "method", "ppo.gamma", "run.seed"]
    (point,) = expand_grid(raw, ["ppo.gamma=0.95", "ppo.gae_lambda=0.95"])
    assert (point.config.ppo.gamma, point.config.ppo.gae_lambda) == (0.95, 0.95)  # --set comes last
    (point,) = expand_grid(raw, ["run.method=mine"])
    assert point.config.method == "mine"
    points = expand_grid(raw, ["grid.run.seed=[1, 2]"])  # --set grid.AXIS replaces an axis before the expansion
    assert [p.config.run.seed for p in points] == [1, 2]
    assert len(expand_grid({**TINY, "grid": {"run.seed": [0, 1, 2]}})) == 3


def test_plain_axes_sweep_whole_blocks() -> None:
    raw = {**TINY, "model": {**TINY["model"], "helm": {"beta": 5.0}}, "grid": {"model.helm": [{"lm": "random"}, {}]}}
    helms = [point.config.model.helm for point in expand_grid(raw)]
    assert [(h.lm, h.beta) for h in helms] == [("random", 1000.0), ("none", 1000.0)]  # the block is replaced


def test_grid_errors_name_the_point_axis_bundle_and_key() -> None:
    def error(grid: dict, *overrides: str) -> str:
        with pytest.raises(ConfigError) as err:
            config_from_dict({**TINY, "grid": grid}, list(overrides))
        return str(err.value)

    message = error({"method": {"stack4": {"model.memory": "none", "model.frame_stak": 4}}})
    assert "grid.method.stack4" in message and "'model.frame_stak' (did you mean 'model.frame_stack'?)" in message
    message = error({"method": {"ppo": {"model.memory": "none"}}, "ppo.sequence_length": [16]})
    assert "grid point (method=ppo, ppo.sequence_length=16)" in message and "needs a memory module" in message
    assert "grid.method.ppo sets run.method=ppo, model.memory=none" in message
    assert "grid.ppo.sequence_length sets ppo.sequence_length=16" in message
    message = error({"task": {"t": {"env.id": "MortarMayhemB-Grid-v0", "env.options": {"delay": 3}}}})
    assert "grid point (task=t)" in message and "option" in message and "delay" in message
    assert "valid choices" in error({"method": {"x": {"model.memory": "lstmx"}}})
    assert "expected a dotted config key" in error({"seeds": [0, 1]})
    assert "expected a mapping of names to bundles" in error({"method": ["gru"]})
    assert "cannot name a directory" in error({"method": {"results": {}}})
    assert "cannot name a directory" in error({"task": {"a/b": {}}})
    assert "lists the value 0 more than once" in error({"run.seed": [0, 0]})
    assert "write the time limit as a quoted string" in error({"slurm": {"time": 86400}})
    assert "did you mean 'grid.slurm.partition'?" in error({"slurm": {"partiton": "gpu"}})
    assert "grid.run.seedz" in error({"run.seed": [0]}, "grid.run.seedz=[1]")


def test_slurm_time_limits() -> None:
    assert [slurm_minutes(t) for t in ("90", "1:30:00", "2-00:00:00", "1-12", "00:05:00", "10:30")] == [
        90,
        90,
        2880,
        2160,
        5,
        11,
    ]
    with pytest.raises(ConfigError, match="expected minutes or"):
        slurm_minutes("soon")


def test_run_names_and_panels() -> None:
    panel = panel_from_dict({**TINY, "grid": {"run.seed": [0, 1], "ppo.gamma": [0.9, 0.99], "panel": "p1"}})
    assert [run.name for run in panel.runs] == [  # another plain axis than run.seed is part of the method's name
        "p1/gru+ppo.gamma=0.9/ProofOfMemory-v0+delay=3/seed0",
        "p1/gru+ppo.gamma=0.99/ProofOfMemory-v0+delay=3/seed0",
        "p1/gru+ppo.gamma=0.9/ProofOfMemory-v0+delay=3/seed1",
        "p1/gru+ppo.gamma=0.99/ProofOfMemory-v0+delay=3/seed1",
    ]
    single = panel_from_dict(TINY, name="solo")  # a config without a grid is one run
    assert [run.name for run in single.runs] == ["solo/gru/ProofOfMemory-v0+delay=3/seed0"]
    with pytest.raises(ConfigError, match="both make the run"):  # values that differ only in unsafe characters
        panel_from_dict({**TINY, "grid": {"model.helm.lm": ["a b", "a_b"]}}, name="p")
    with pytest.raises(ConfigError, match="grid.panel"):
        panel_from_dict(TINY)


def test_plain_axes_never_pool_different_experiments_in_one_cell() -> None:
    """The records' (method, task) cell of a sweep run holds the runs of its seeds only: an env.* axis extends the
    task's name, any other plain axis the method's, so the panel's results never refuse (or pool) them."""
    from agents.analysis.digest import config_digest
    from agents.experiments.planning import run_coordinates

    grid = {"method": {"gru": {}}, "task": {"pom": {}}, "run.seed": [0, 1], "ppo.gamma": [0.9, 0.99]}
    panel = panel_from_dict({**TINY, "grid": {**grid, "env.options.delay": [2, 4]}}, name="p")
    cells: dict[tuple[str, str], set[str]] = {}
    for run in panel.runs:
        cells.setdefault((run.config.method, run.config.task), set()).add(config_digest(run.config))
    assert sorted(cells) == [
        (f"gru+ppo.gamma={gamma}", f"pom+env.options.delay={delay}") for gamma in (0.9, 0.99) for delay in (2, 4)
    ]
    assert all(len(digests) == 1 for digests in cells.values())  # the two seeds of a cell: one experiment
    first = panel.runs[0]
    assert first.name == "p/gru+ppo.gamma=0.9/pom+env.options.delay=2/seed0"
    assert run_coordinates(first)["method"] == "gru"  # --only still selects by the bundle's name
    plain = panel_from_dict({**TINY, "grid": grid | {"ppo.gamma": [0.9]}}, name="q")
    assert {run.config.method for run in plain.runs} == {"gru+ppo.gamma=0.9"}
    named = panel_from_dict({**TINY, "grid": {"method": {"gru": {}}, "run.seed": [0]}}, name="r")
    assert named.runs[0].config.method == "gru" and named.runs[0].name == "r/gru/ProofOfMemory-v0+delay=3/seed0"


def test_states_mismatches_and_locks(tmp_path: Path) -> None:
    raw = {**TINY, "grid": {"method": {"gru": {}, "ppo": {"model.memory": "none"}}}}
    panel = panel_from_dict(raw, root=tmp_path, name="p")
    gru, ppo = panel.runs
    assert [s.state for s in statuses(panel.runs)] == [NEW, NEW]
    prepare_run(gru, torch_threads=3)
    assert "torch_threads: 3" in (gru.run_dir / "config.yaml").read_text()
    assert run_status(gru).state == PARTIAL  # created, no checkpoint yet
    (gru.run_dir / "checkpoints").mkdir()
    (gru.run_dir / "checkpoints" / "update_0000001.pt").touch()
    assert (run_status(gru).state, run_status(gru).update) == (PARTIAL, 1)
    (gru.run_dir / "checkpoints" / f"update_{gru.config.num_updates:07d}.pt").touch()
    assert run_status(gru).state == FINISHED
    with run_lock(gru.run_dir) as held:
        assert held and run_status(gru).state == RUNNING
        with run_lock(gru.run_dir) as second:
            assert not second
    assert run_status(gru).state == FINISHED
    changed = panel_from_dict(raw, ["ppo.gamma=0.5", "run.torch_threads=0"], root=tmp_path, name="p")
    with pytest.raises(SweepError) as err:
        statuses(changed.runs)
    assert "p/gru/ProofOfMemory-v0+delay=3/seed0" in str(err.value)
    assert "ppo.gamma: saved 0.99, now 0.5" in str(err.value)
    assert "torch_threads" not in str(err.value)  # fixed by the launcher, not a difference
    explicit = panel_from_dict(raw, ["run.torch_threads=2"], root=tmp_path, name="p")
    assert run_status(explicit.runs[0]).state == FINISHED  # it trains no more: its thread count is no difference
    (gru.run_dir / "checkpoints" / f"update_{gru.config.num_updates:07d}.pt").unlink()
    with pytest.raises(SweepError, match="run.torch_threads: saved 3, now 2"):  # a partial run would train on
        run_status(explicit.runs[0])
    assert run_status(explicit.runs[1]).state == NEW


def test_disk_estimate_of_a_paper_gru_run(paper_panels: dict) -> None:
    run = next(r for r in paper_panels["fig4_mmact_grid"].runs if r.config.method == "gru")
    estimate = disk_estimate(run.config)
    assert 6_000_000 < estimate.parameters < 7_500_000
    assert estimate.checkpoint_bytes == 12 * estimate.parameters + 100_000  # weights + AdamW's two moments
    assert 75e6 < estimate.checkpoint_bytes < 95e6 and estimate.kept == 1
    assert estimate.run_bytes < 150e6  # bounded: one checkpoint and the records


def test_dry_run_prints_the_runs_steps_disk_and_states(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    config = PAPER / "fig4_mmact_grid.yaml"
    assert sweep_script.main([str(config), "--dry-run", "--root", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    rows = [line for line in out.splitlines() if line.startswith("  fig4_mmact_grid/")]
    assert len(rows) == 25 and all(" new " in row for row in rows)
    assert "fig4_mmact_grid/stack16/mmact_grid/seed4" in out and "model.frame_stack=16" in out
    assert "steps: 4,096,000,000 agent steps in 25 runs" in out
    assert re.search(r"disk per gru run: checkpoint 8\d\.\d MB", out) and "disk for the panel:" in out
    assert "runs: 0 finished, 0 partial, 25 new, 0 running" in out
    assert not any(tmp_path.iterdir())  # a dry run writes nothing
    panel = load_panel(config, root=tmp_path)
    prepare_run(panel.runs[0])
    assert "runs: 0 finished, 1 partial, 24 new, 0 running" in describe([panel])
    assert sweep_script.main([str(config), "--dry-run", "--set", "ppo.gamma=2"]) == 2


def test_tasks_in_progress_counts_each_tasks_finished_runs(tmp_path: Path) -> None:
    from agents.experiments.panel import tasks_in_progress
    from agents.experiments.state import RunStatus

    panel = panel_from_dict(
        {
            "env": {"id": "ProofOfMemory-v0"},
            "grid": {"panel": "p", "task": {"a": {}, "b": {"env.options": {"delay": 2}}}, "run.seed": [0, 1]},
        },
        root=tmp_path,
    )
    found = [
        RunStatus(run, FINISHED if "/a/" in run.name or run.name.endswith("b/seed0") else NEW, 0) for run in panel.runs
    ]
    assert tasks_in_progress(found) == {"b": "1 of 2 runs finished"}
    assert tasks_in_progress([RunStatus(run, FINISHED, 0) for run in panel.runs]) == {}
