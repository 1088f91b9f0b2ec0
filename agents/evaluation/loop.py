"""Scoring a policy on novel seeds: every seed x repetition played at once in one batched core, through the actor.

Slot ``i`` plays seed ``seeds[i // repetitions]``; repetitions of a seed differ only by the sampled actions (the
paper samples; ``greedy`` takes the argmax). Each finished episode becomes one record
(:data:`agents.evaluation.records.RECORD_COLUMNS`, then the environment's own end-of-episode metrics). The trainer
calls :func:`evaluate` during training and ``scripts/evaluate.py`` calls it on saved checkpoints
(:func:`agents.evaluation.runs.evaluate_runs`): with the same weights, seeds and sampling seed both give the same
records. What watches the episodes (a GIF recorder, :mod:`agents.evaluation.videos`) is a hook, ``on_frame``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import torch

from agents.analysis.digest import config_digest, env_options_text
from agents.analysis.metrics import METRICS, SPEC_COLUMN, metric_of, metric_spec
from agents.config import Config
from agents.evaluation.records import is_record_number, record_number
from agents.policy.actor import Actor, Outcome
from agents.policy.models import ActorCritic

# called with the actor once before the first decision (outcome None) and after every decision with its outcome
FrameHook = Callable[[Actor, Outcome | None], None]


def evaluate(
    model: ActorCritic,
    helm: Any,
    config: Config,
    seeds: Sequence[int],
    repetitions: int,
    *,
    greedy: bool = False,
    sampling_seed: int = 0,
    step: int = 0,
    run: str = "",
    device: torch.device | str = "cpu",
    progress: bool = False,
    on_frame: FrameHook | None = None,
    core: Any = None,
) -> list[dict[str, Any]]:
    """Play ``repetitions`` episodes of every seed with ``model`` and return one record per episode, ordered by
    seed then repetition. ``core``: a batched core with ``len(seeds) * repetitions`` slots to reuse."""
    slots = len(seeds) * repetitions
    if core is None:
        core = config.env.make_core(slots)
    elif core.num_envs != slots:
        raise ValueError(f"the core has {core.num_envs} slots, the evaluation needs {slots}")
    generator = torch.Generator(device=device)
    generator.manual_seed(sampling_seed)
    actor = Actor(core, model, config, generator, helm, device)
    slot_seeds = [int(seed) for seed in seeds for _ in range(repetitions)]
    actor.start(slot_seeds)
    finals: dict[int, dict[str, Any]] = {}
    bar = _progress(slots, progress)
    if on_frame is not None:
        on_frame(actor, None)
    while actor.active.any():
        outcome = actor.advance(actor.decide(greedy))
        finals.update(outcome.finals)
        if bar is not None and outcome.finals:
            bar.update(len(outcome.finals))
        if on_frame is not None:
            on_frame(actor, outcome)
    if bar is not None:
        bar.close()
    metric = metric_of(config.env.id, config.env.metric)
    spec = {} if METRICS.get(config.env.id) is metric else {SPEC_COLUMN: metric_spec(metric)}  # plots read it
    options, digest = (
        env_options_text(config),
        config_digest(config, greedy),
    )  # the columns agents.analysis.results checks
    records = []
    for slot in range(slots):
        info = finals[slot]
        extra = {key: record_number(value) for key, value in sorted(info.items()) if key not in ("reward", "length")}
        records.append(
            {
                "run": run,
                "method": config.method,
                "task": config.task,
                "env_id": config.env.id,
                "step": step,
                "seed": slot_seeds[slot],
                "repetition": slot % repetitions,
                "return": float(info["reward"]),
                "length": int(info["length"]),
                "metric": float(metric.value(info)),
                "metric_reference": float(metric.reference(info)),
                "env_options": options,
                "config_digest": digest,
                **spec,
                **{key: value for key, value in extra.items() if is_record_number(value)},
            }
        )
    return records


def _progress(total: int, enabled: bool) -> Any:
    if not enabled:
        return None
    from tqdm import tqdm

    return tqdm(total=total, unit="episode", dynamic_ncols=True, leave=False)
