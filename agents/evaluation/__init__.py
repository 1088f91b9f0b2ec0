"""The evaluation room: a policy scored on novel seeds, one record per episode.

* :mod:`agents.evaluation.loop`: :func:`evaluate`, one policy on every seed x repetition at once, through the actor;
* :mod:`agents.evaluation.records`: the record files (CSV, numbers parsed back) and seed ranges;
* :mod:`agents.evaluation.runs`: :func:`evaluate_runs`, checkpoints of run directories planned, checked, evaluated
  and merged into one results directory;
* :mod:`agents.evaluation.videos`: GIFs of episodes, drawn by a frame hook of the loop.

It stands on the policy (the actor, checkpoints) and the analysis (metrics, digests, summaries); training calls it
during a run, the experiments at a panel's end.
"""

from __future__ import annotations

from agents.evaluation.loop import FrameHook, evaluate
from agents.evaluation.records import (
    RECORD_COLUMNS,
    describe_seeds,
    parse_seed_range,
    read_records,
    record_means,
    records_csv_text,
    seed_list,
    write_records,
)
from agents.evaluation.runs import evaluate_runs, pruned_note, select_checkpoints, unique_run_names
from agents.evaluation.videos import EpisodeVideo, labelled_frame

__all__ = [
    "RECORD_COLUMNS",
    "EpisodeVideo",
    "FrameHook",
    "describe_seeds",
    "evaluate",
    "evaluate_runs",
    "labelled_frame",
    "parse_seed_range",
    "pruned_note",
    "read_records",
    "record_means",
    "records_csv_text",
    "seed_list",
    "select_checkpoints",
    "unique_run_names",
    "write_records",
]
