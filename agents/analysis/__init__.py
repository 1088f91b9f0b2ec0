"""The analysis room: from evaluation records to the numbers and figures of a results table.

* :mod:`agents.analysis.metrics`: the task's metric per environment id (success, commands executed, ...), its range
  and chance level;
* :mod:`agents.analysis.digest`: what defines the experiment a run belongs to (the records' ``config_digest``);
* :mod:`agents.analysis.results`: reading ``episodes.csv`` / ``training.csv`` of results directories and checking that
  they fit together (columns, one config per cell);
* :mod:`agents.analysis.stats`: the interquartile mean and stratified-bootstrap intervals (the rliable estimates);
* :mod:`agents.analysis.scores`: run-level scores, IQM aggregates across runs and tasks, summaries, text tables;
* :mod:`agents.analysis.across_tasks`: scores normalised per task and aggregated across tasks (IQM, mean, median,
  optimality gap, probability of improvement, performance profiles, each with its interval);
* :mod:`agents.analysis.plots`: sample-efficiency curves and final performance (matplotlib, imported when drawing),
  and :mod:`agents.analysis.across_tasks_figure`: the figure of the aggregate across tasks.

numpy and the standard library at import time; the config (read for a run's saved settings) is imported where it
is used. The policy room is its sibling: neither imports the other.
"""

from __future__ import annotations

from agents.analysis.digest import config_digest, describe_differences, env_options_text, experiment_settings
from agents.analysis.metrics import METRICS, SPEC_COLUMN, Metric, metric_of, metric_spec, read_metric_spec
from agents.analysis.plots import curves_figure, final_figure, plot_results
from agents.analysis.results import (
    CONFIG_COLUMN,
    EPISODE_COLUMNS,
    OPTIONS_COLUMN,
    TRAINING_COLUMNS,
    Records,
    Results,
    ResultsWarning,
    check_configs,
    read_episodes,
    read_results,
    read_training,
    task_options,
)
from agents.analysis.scores import (
    MethodScores,
    aggregate,
    estimate,
    format_table,
    run_scores,
    run_summary,
    score_curves,
    score_matrices,
    separation,
    summarize,
    training_curves,
)
from agents.analysis.stats import iqm, stratified_bootstrap, stratified_estimates

__all__ = [
    "CONFIG_COLUMN",
    "EPISODE_COLUMNS",
    "METRICS",
    "OPTIONS_COLUMN",
    "SPEC_COLUMN",
    "TRAINING_COLUMNS",
    "Metric",
    "MethodScores",
    "Records",
    "Results",
    "ResultsWarning",
    "aggregate",
    "check_configs",
    "config_digest",
    "curves_figure",
    "describe_differences",
    "env_options_text",
    "estimate",
    "experiment_settings",
    "final_figure",
    "format_table",
    "iqm",
    "metric_of",
    "metric_spec",
    "plot_results",
    "read_episodes",
    "read_metric_spec",
    "read_results",
    "read_training",
    "run_scores",
    "run_summary",
    "score_curves",
    "score_matrices",
    "separation",
    "stratified_bootstrap",
    "stratified_estimates",
    "summarize",
    "task_options",
    "training_curves",
]
