"""A panel's results: every finished run's last checkpoint evaluated on the novel seeds, and the panel's records,
summary and plots written into ``<root>/<panel>/results``.
"""

from __future__ import annotations

import csv
import io
from collections import Counter
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from agents.experiments.planning import Echo, Panel, SweepError, SweepRun
from agents.experiments.state import FINISHED, RunStatus, statuses
from agents.policy.checkpoint import checkpoint_update, finished_update, latest_checkpoint
from agents.runtime.io import atomic_write_text, exclusive_lock, provenance, write_json_atomic

FINAL_EVALUATION = "evaluation"  # <run>/evaluation: the final evaluation, as scripts/evaluate.py writes it
RESULTS_LOCK = ".lock"  # in the results directory: held while a process evaluates the panel and writes its results


def final_evaluation(run: SweepRun, device: str = "cpu") -> list[dict[str, Any]]:
    """The records of the run's last checkpoint on its novel seeds (the run's ``eval`` block: seeds, repetitions,
    sampling seed), kept in ``<run>/evaluation/`` as ``scripts/evaluate.py`` writes them and reused when they are of
    that checkpoint."""
    from agents.evaluation.records import read_records, seed_list
    from agents.evaluation.runs import evaluate_runs

    latest = latest_checkpoint(run.run_dir)
    update = checkpoint_update(latest) if latest is not None else finished_update(run.run_dir)
    if update is None:
        raise SweepError(f"{run.name}: no checkpoint to evaluate")
    step = update * run.config.batch_size
    out = run.run_dir / FINAL_EVALUATION
    path = out / "episodes.csv"
    # The directory may also hold a user's own evaluations (scripts/evaluate.py writes here by default, perhaps with
    # other seeds or checkpoints): those rows are kept, and only the protocol's records of this checkpoint count.
    seeds = set(seed_list(run.config.eval_seeds))
    repetitions = run.config.eval.repetitions

    def protocol_records() -> list[dict[str, Any]]:
        return [
            record
            for record in (read_records(path) if path.is_file() else [])
            if record["step"] == step and record["seed"] in seeds and record["repetition"] < repetitions
        ]

    records = protocol_records()
    if len(records) == len(seeds) * repetitions:
        return records
    if latest is None:
        raise SweepError(f"{run.name}: finished, but neither its checkpoint nor its final evaluation is here")
    evaluate_runs([run.run_dir], out, device=device, force=True)
    return protocol_records()


def evaluate_panel(panel: Panel, *, device: str = "cpu", plots: bool = True, echo: Echo = print) -> Path:
    """Evaluate every finished run's last checkpoint on the novel seeds and write the panel's results directory
    (``<root>/<panel>/results``):

    * ``episodes.csv``: every run's in-training evaluation records (``<run>/eval/episodes.csv``) up to its last step,
      then the final evaluation of its last checkpoint, which takes the place of the in-training records of that
      step (same seeds, repetitions and sampling seed); the ``run`` column holds the run's name;
    * ``training.csv``: the runs' ``training.csv`` one after the other, ``run`` as above;
    * ``summary.json``: :func:`agents.analysis.scores.summarize` of those records (per run and step the means; per
      method and task, at every step the runs share, the IQM across runs with its 95% stratified-bootstrap interval),
      the runs not finished yet, the protocol and provenance; for a panel of several tasks also ``across_tasks``
      (:func:`agents.analysis.across_tasks.across_tasks`: normalised final scores aggregated across the tasks);
    * ``plots/``: the curves and final-performance figures of :func:`agents.analysis.plots.plot_results`, and for
      several tasks ``across_tasks.png/.pdf``.

    Runs not finished are left out (and listed: by name, or per task when many). Two processes that evaluate one
    panel at once (two sweeps on one root finishing together) take turns, and each reads the runs' states in its turn,
    so the one that writes last has seen every run the other saw finished. Returns the results directory."""
    _check_some_finished(panel, statuses(panel.runs))
    with exclusive_lock(panel.results_dir / RESULTS_LOCK):
        return _evaluate_finished(panel, device=device, plots=plots, echo=echo)


def _check_some_finished(panel: Panel, found: Sequence[RunStatus]) -> None:
    if not any(s.state == FINISHED for s in found):
        raise SweepError(f"{panel.name}: no finished run to evaluate ({len(found)} not finished)")


def _evaluate_finished(panel: Panel, *, device: str, plots: bool, echo: Echo) -> Path:
    """:func:`evaluate_panel`'s work, with the panel's results lock held."""
    from agents.analysis.across_tasks import across_tasks
    from agents.analysis.results import TRAINING_COLUMNS, read_episodes
    from agents.analysis.scores import summarize
    from agents.evaluation.records import read_records, write_records

    found = statuses(panel.runs)
    _check_some_finished(panel, found)
    finished = [s.run for s in found if s.state == FINISHED]
    unfinished = [s.run.name for s in found if s.state != FINISHED]
    records: list[dict[str, Any]] = []
    rows: list[dict[str, Any]] = []
    for index, run in enumerate(finished, 1):
        echo(f"[{index}/{len(finished)}] final evaluation: {run.name}")
        final = [{**record, "run": run.name} for record in final_evaluation(run, device)]
        last = max(record["step"] for record in final)
        in_training = run.run_dir / "eval" / "episodes.csv"
        if in_training.is_file():
            records += [{**r, "run": run.name} for r in read_records(in_training) if r["step"] < last]
        records += final
        rows += [{**row, "run": run.name} for row in _read_csv(run.run_dir / "training.csv")]
    out = panel.results_dir
    write_records(out / "episodes.csv", records)
    atomic_write_text(out / "training.csv", _csv_text(TRAINING_COLUMNS, rows))
    first = finished[0].config
    episodes = read_episodes(out)
    summary = {
        "panel": panel.name,
        "config": str(panel.source) if panel.source else None,
        "overrides": list(panel.overrides),
        "unfinished": unfinished,
        **summarize(episodes),
        "evaluation": {
            "seeds": first.eval_seeds,
            "repetitions": first.eval.repetitions,
            "greedy": first.eval.greedy,
            "checkpoints": "last",
            "in_training_interval": first.eval.interval,
            **provenance(),
        },
    }
    in_progress = tasks_in_progress(found)
    spanning = across_tasks(episodes, in_progress=in_progress)  # None for a panel of one task
    if spanning is not None:
        summary["across_tasks"] = spanning
    write_json_atomic(out / "summary.json", summary, sort_keys=False)
    if plots:
        _plot(out, echo)
    if unfinished:
        left_out = _named_briefly(unfinished, in_progress)
        echo(f"{panel.name}: {len(unfinished)} run(s) not finished and left out: {left_out}")
    echo(f"{panel.name}: results in {out}")
    return out


# Up to this many unfinished runs are named one by one; more (a one-run sweep or check on a fresh root) by task
NAMED_ONE_BY_ONE = 8


def _named_briefly(unfinished: Sequence[str], in_progress: Mapping[str, str]) -> str:
    """The unfinished runs by name, or, when there are many, per task (:func:`tasks_in_progress`; every name is in
    ``summary.json``)."""
    if len(unfinished) <= NAMED_ONE_BY_ONE:
        return ", ".join(unfinished)
    by_task = "; ".join(f"{task}: {finished}" for task, finished in in_progress.items())
    return f'{by_task} (named in summary.json\'s "unfinished")'


def tasks_in_progress(found: Sequence[RunStatus]) -> dict[str, str]:
    """Task -> "k of n runs finished" for every task of the panel with a run not finished yet."""
    total = Counter(status.run.config.task for status in found)
    done = Counter(status.run.config.task for status in found if status.state == FINISHED)
    return {task: f"{done[task]} of {count} runs finished" for task, count in total.items() if done[task] < count}


def _plot(results_dir: Path, echo: Echo) -> None:
    """The panel's curves and final-performance charts (``agents.analysis.plots``) into ``results/plots``. A failure is
    reported, not raised: the records are written, and ``scripts/plot.py`` can draw them again."""
    try:
        from agents.analysis import plots
    except ImportError as err:
        echo(f"plots: skipped ({err}); the records are in {results_dir}")
        return
    try:
        from agents.analysis.across_tasks_figure import plot_across_tasks

        paths = plots.plot_results([results_dir], results_dir / "plots")
        paths += plot_across_tasks([results_dir], results_dir / "plots")
    except Exception as err:  # noqa: BLE001 (whatever goes wrong in a figure must not hide the results)
        echo(f"plots: failed ({type(err).__name__}: {err}); retry: python scripts/plot.py {results_dir}")
        return
    echo("plots: " + ", ".join(str(path) for path in paths))


def _read_csv(path: Path) -> list[dict[str, str]]:
    if not path.is_file():
        return []
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))


def _csv_text(columns: Sequence[str], rows: Sequence[dict[str, Any]]) -> str:
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=list(columns), lineterminator="\n", extrasaction="ignore")
    writer.writeheader()
    writer.writerows(rows)
    return text.getvalue()
