"""Selecting runs of grids by name (``scripts/sweep.py --only``): the keys, the values, AND within one item, OR across
items, the errors, and the dry run of a selection. (The launchers with --only: tests/scripts/test_sweep_only.py.)"""

from __future__ import annotations

from pathlib import Path

import pytest

from agents.experiments.dry_run import describe
from agents.experiments.planning import SweepError, panel_from_dict, parse_selection, select_runs

TINY = {
    "env": {"id": "ProofOfMemory-v0"},
    "model": {"memory": "gru", "memory_size": 16, "hidden_size": 16, "vector_encoder_size": 8},
    "run": {"total_steps": 128, "workers": 4, "worker_steps": 16, "progress_bar": False},
}
GRID = {
    "method": {"gru": {}, "ppo": {"model.memory": "none"}},
    "task": {"short": {"env.options": {"delay": 2}}, "long": {"env.options": {"delay": 5}}},
    "ppo.gamma": [0.9, 0.99],
    "run.seed": [0, 1],
}


def _panel(name: str = "p", grid: dict | None = None, root: Path = Path("runs")):
    return panel_from_dict({**TINY, "grid": GRID if grid is None else grid}, root=root, name=name)


def _names(panels: list) -> list[str]:
    return [run.name for panel in panels for run in panel.runs]


def test_one_item_keeps_the_runs_that_match_all_its_pairs() -> None:
    (panel,) = select_runs([_panel()], ["method=gru,task=long,seed=1"])
    assert _names([panel]) == ["p/gru+ppo.gamma=0.9/long/seed1", "p/gru+ppo.gamma=0.99/long/seed1"]
    assert panel.selection == ("method=gru,task=long,seed=1",)
    (panel,) = select_runs([_panel()], ["method=ppo,ppo.gamma=0.90,run.seed=0,task=short"])  # 0.90 is the 0.9 run
    assert _names([panel]) == ["p/ppo+ppo.gamma=0.9/short/seed0"]
    assert len(select_runs([_panel()], ["run.method=ppo"])[0].runs) == 8  # run.method / run.task name the bundles


def test_repeated_items_add_their_runs() -> None:
    panels = select_runs([_panel()], ["method=gru,task=short,ppo.gamma=0.9,seed=0", "method=ppo,task=long,seed=1"])
    assert _names(panels) == [  # in the grid's order, each run once
        "p/gru+ppo.gamma=0.9/short/seed0",
        "p/ppo+ppo.gamma=0.9/long/seed1",
        "p/ppo+ppo.gamma=0.99/long/seed1",
    ]
    assert _names(select_runs([_panel()], ["seed=0", "seed=0,method=gru"])) == _names(
        select_runs([_panel()], ["seed=0"])
    )
    everything = [_panel()]
    assert select_runs(everything, []) == everything  # no --only: every run


def test_values_with_commas_and_selection_across_panels() -> None:
    helm = _panel("h", {"model.helm": [{"lm": "random", "random_width": 16}, {}], "run.seed": [0, 1]})
    (panel,) = select_runs([helm], ["model.helm={lm: random, random_width: 16},seed=1"])
    assert [run.config.model.helm.lm for run in panel.runs] == ["random"] and panel.runs[0].config.run.seed == 1
    assert parse_selection("model.helm={lm: random, beta: 2}, seed=0") == {
        "model.helm": "{lm: random, beta: 2}",
        "run.seed": "0",
    }
    # a value that exists in one panel only selects there; the panels left without a run are dropped
    other = _panel("q", {"method": {"lstm": {"model.memory": "lstm"}}, "run.seed": [0]})
    panels = select_runs([_panel(), other], ["method=lstm"])
    assert [panel.name for panel in panels] == ["q"] and _names(panels) == ["q/lstm/ProofOfMemory-v0/seed0"]
    # method, task and run.seed select runs whose grid has no such axis (they are in every run's name)
    assert _names(select_runs([other], ["task=ProofOfMemory-v0,seed=0"])) == ["q/lstm/ProofOfMemory-v0/seed0"]


@pytest.mark.parametrize(
    ("only", "message"),
    [
        (["methd=gru"], "'methd' is not an axis of p; valid keys: method, task, run.seed (seed), ppo.gamma"),
        (["method=lstm"], "no run of p has method=lstm; valid values: gru, ppo"),
        (["seed=7"], "no run of p has run.seed=7; valid values: 0, 1"),
        (["ppo.gamma=0.5"], "no run of p has ppo.gamma=0.5; valid values: 0.9, 0.99"),
        (["method=gru,method=ppo"], "names method twice; one --only selects the runs that match all its pairs"),
        (["seed=0,run.seed=1"], "names run.seed twice"),
        (["method"], "--only method: expected key=value pairs joined by commas"),
        (["method=gru,"], "no run of p has method=gru,; valid values: gru, ppo"),  # the comma is the value's
        (["=gru"], "expected key=value pairs"),
    ],
)
def test_bad_selections_name_the_key_or_value_and_the_valid_ones(only: list[str], message: str) -> None:
    with pytest.raises(SweepError, match="--only") as err:
        select_runs([_panel()], only)
    assert message in str(err.value)


def test_a_selection_that_keeps_no_run_is_an_error() -> None:
    other = _panel("q", {"method": {"lstm": {"model.memory": "lstm"}}, "run.seed": [0]})
    with pytest.raises(SweepError, match="no run of p, q matches all the pairs of one --only"):
        select_runs([_panel(), other], ["method=lstm,task=long"])  # both values exist, never in the same run


def test_the_dry_run_lists_the_selected_runs_only(tmp_path: Path) -> None:
    (panel,) = select_runs([_panel(root=tmp_path)], ["method=ppo,task=short,ppo.gamma=0.99"])
    text = describe([panel])
    assert "panel p: 2 runs selected by --only method=ppo,task=short,ppo.gamma=0.99" in text
    rows = [line.split()[0] for line in text.splitlines() if line.startswith("  p/")]
    assert rows == ["p/ppo+ppo.gamma=0.99/short/seed0", "p/ppo+ppo.gamma=0.99/short/seed1"]
    assert "steps: 256 agent steps in 2 runs" in text and "runs: 0 finished, 0 partial, 2 new, 0 running" in text
    assert "panel p: 1 run selected" in describe(
        select_runs([_panel(root=tmp_path)], ["method=gru,seed=0,task=long,ppo.gamma=0.9"])
    )
