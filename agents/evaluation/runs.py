"""Evaluating run directories: checkpoints of several runs on novel seeds, planned and checked before anything runs,
merged into one results directory (``episodes.csv``, ``training.csv``, ``summary.json``), every file written
atomically under the directory's lock.
"""

from __future__ import annotations

import csv
import io
import json
import tempfile
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from agents.analysis.digest import config_digest, describe_differences, experiment_settings
from agents.analysis.results import TRAINING_COLUMNS, read_episodes
from agents.analysis.scores import summarize as summarize_episodes
from agents.config import Config, check_disjoint_seeds
from agents.evaluation.loop import evaluate
from agents.evaluation.records import (
    describe_seeds,
    parse_seed_range,
    read_records,
    records_csv_text,
    seed_list,
    write_records,
)
from agents.evaluation.videos import EpisodeVideo
from agents.policy.checkpoint import checkpoint_update, list_checkpoints, load_policy, run_config
from agents.runtime.devices import check_device
from agents.runtime.faults import active_faults
from agents.runtime.io import atomic_write_bytes, content_record, exclusive_lock, provenance, write_json_atomic
from agents.runtime.preemption import deferred_signals

LOCK_FILE = ".lock"  # in an evaluation's results directory: held while it is read and while it is merged into


def select_checkpoints(run_dir: Path, which: str, batch_size: int) -> list[Path]:
    """``last``, ``all`` or a comma-separated list of environment steps -> checkpoint paths of ``run_dir``."""
    available = list_checkpoints(run_dir)
    if not available:
        raise FileNotFoundError(f"{run_dir} holds no checkpoint (checkpoints/update_*.pt)")
    if which == "last":
        return available[-1:]
    if which == "all":
        return available
    by_step = {checkpoint_update(path) * batch_size: path for path in available}
    chosen = []
    for item in which.split(","):
        try:
            step = int(item)
        except ValueError:
            raise ValueError(f"--checkpoints {which!r} is invalid: expected last, all or STEP,STEP,...") from None
        if step not in by_step:
            raise ValueError(
                f"{run_dir} has no checkpoint at step {step}; its checkpoints are at steps {sorted(by_step)}"
            )
        chosen.append(by_step[step])
    return chosen


def pruned_note(config: Config, found: Sequence[Path]) -> str:
    """What ``--checkpoints all`` should say of a run's ``found`` checkpoints: how many there are, and, when the run
    wrote earlier ones that ``run.keep_checkpoints`` deleted, that they were pruned (their novel-seed points are in
    the run's ``eval/episodes.csv`` when ``eval.interval`` was set)."""
    note = f" ({len(found)} found"
    interval, keep = config.run.checkpoint_interval, config.run.keep_checkpoints
    if keep and len(found) >= keep and interval and checkpoint_update(found[0]) > interval:
        note += (
            f"; the older ones were pruned by run.keep_checkpoints: {keep}, which keeps only the newest; "
            "train with --set run.keep_checkpoints=0 to keep all"
        )
    return note + ")"


def unique_run_names(
    directories: Sequence[Path],
    groups: Sequence[tuple[str, str]],
    taken: Mapping[tuple[str, str, str], str] | None = None,
) -> list[str]:
    """The ``run`` column of each run directory: its own name (``seed1``) unless a run of the same (method, task)
    -- ``groups`` -- shares it, then the shortest path suffix that tells them apart (``a/seed1``, ``b/seed1``).

    A run is identified by (method, task, run) in the records, so sweeps' ``<method>/<task>/seed<k>`` keep
    ``seed<k>``. ``taken`` maps (method, task, name) -> resolved directory for the names a results directory already
    holds: a directory listed there keeps its name, and no other directory gets it."""
    taken = dict(taken or {})
    resolved = [str(Path(directory).resolve()) for directory in directories]
    parts = [Path(path).parts for path in resolved]

    def suffix(index: int, length: int) -> str:
        return Path(*parts[index][-length:]).as_posix()

    names = []
    for i, group in enumerate(groups):
        known = [
            name for (method, task, name), path in taken.items() if (method, task) == group and path == resolved[i]
        ]
        if known:
            names.append(sorted(known, key=len)[0])
            continue
        others = [j for j, other in enumerate(groups) if other == group and j != i]
        for length in range(1, len(parts[i]) + 1):
            name = suffix(i, length)
            clash = any(len(parts[j]) >= length and suffix(j, length) == name for j in others)
            if not clash and taken.get((*group, name), resolved[i]) == resolved[i]:
                break
        names.append(name)
    return names


@dataclass
class _Plan:
    """What is evaluated of one run directory, settled before anything runs (so bad input wastes no time)."""

    directory: Path
    config: Config
    method: str
    task: str
    seeds: list[int]  # inclusive [low, high]
    repetitions: int
    checkpoints: list[Path]
    name: str = ""

    @property
    def steps(self) -> list[int]:
        return [checkpoint_update(path) * self.config.batch_size for path in self.checkpoints]

    def keys(self) -> set[tuple]:
        return {
            (self.method, self.task, self.name, step, seed, repetition)
            for step in self.steps
            for seed in seed_list(self.seeds)
            for repetition in range(self.repetitions)
        }


def _record_key(record: Mapping[str, Any]) -> tuple:
    """What identifies an episode record: its run (method, task, run), checkpoint, seed and repetition."""
    return (
        *(str(record[key]) for key in ("method", "task", "run")),
        *(int(record[key]) for key in ("step", "seed", "repetition")),
    )


def _training_key(row: Mapping[str, Any]) -> tuple:
    return (*(str(row[key]) for key in ("method", "task", "run")), int(float(row["step"])))


def _read_rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as handle:
        return list(csv.DictReader(handle))


def _csv_text(columns: Sequence[str], rows: Sequence[Mapping[str, Any]]) -> str:
    extra = sorted({key for row in rows for key in row} - set(columns))
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=[*columns, *extra], lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return text.getvalue()


def _merge(old: Sequence[dict], new: Sequence[dict], key: Callable[[Mapping[str, Any]], tuple]) -> tuple[list, int]:
    """``old`` rows whose key is not among ``new``'s, then ``new``; and how many old rows were replaced."""
    fresh = {key(row) for row in new}
    kept = [row for row in old if key(row) not in fresh]
    return [*kept, *new], len(old) - len(kept)


def _existing(out: Path) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """The records and the summary a results directory holds already (none for a new directory). The files that
    summary.json vouches for (``files``: size and SHA-256) must be as it recorded them: a truncated or corrupted
    one is refused by name before anything is evaluated."""
    episodes, summary = out / "episodes.csv", out / "summary.json"
    found: dict[str, Any] = {}
    if summary.is_file():
        try:
            found = json.loads(summary.read_text())
        except json.JSONDecodeError as err:
            raise ValueError(
                f"{summary} is not valid JSON ({err}): truncated or corrupted; move it away to evaluate into {out}"
            ) from None
    for name, recorded in found.get("files", {}).items():
        path = out / name
        actual = content_record(path.read_bytes()) if path.is_file() else None
        if actual != recorded:
            size = "missing" if actual is None else f"{actual['bytes']} bytes"
            raise ValueError(
                f"{path} is not what {summary.name} recorded ({recorded['bytes']} bytes, SHA-256 "
                f"{recorded['sha256'][:12]}...; found {size}{', other content' if actual else ''}): it was truncated "
                f"or corrupted, or an evaluation was killed between writing it and {summary.name}; restore it, or "
                f"move {out} away to evaluate anew"
            )
    records = read_records(episodes) if episodes.is_file() else []
    if records:
        read_episodes(out)  # refuses a malformed file by name before anything is evaluated
    return records, found


def _taken(summary: Mapping[str, Any]) -> dict[tuple[str, str, str], str]:
    return {
        (str(entry["method"]), str(entry["task"]), str(entry["run"])): str(entry["directory"])
        for entry in summary.get("run_directories", [])
    }


def evaluate_runs(
    run_dirs: Sequence[Path],
    out: Path,
    *,
    seeds: str | None = None,
    repetitions: int | None = None,
    checkpoints: str = "last",
    greedy: bool = False,
    sampling_seed: int | None = None,
    method: str | None = None,
    task: str | None = None,
    video: Path | None = None,
    videos: int = 3,
    device: str = "cpu",
    progress: bool = False,
    force: bool = False,
    echo: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Evaluate checkpoints of several runs on novel seeds and merge the records into the results directory ``out``;
    returns its new summary. Defaults come from each run's own ``eval`` block.

    * ``episodes.csv``: one row per episode, keyed by (method, task, run, step, seed, repetition). Rows of other runs
      and checkpoints are kept; rows with the key of a new one are replaced only with ``force`` (without it, a
      ValueError before anything is evaluated).
    * ``training.csv``: the runs' ``training.csv`` rows, merged by (method, task, run, step), for the training-seed
      curves of ``scripts/plot.py``.
    * ``summary.json``: :func:`agents.analysis.scores.summarize` over all the merged records, which directory each run
      name stands for (``run_directories``, see :func:`unique_run_names`), this evaluation and the earlier ones.

    Every file is written atomically, after the merged records were checked. ``echo`` receives what is evaluated
    (the inclusive seed range, checkpoints) and what the merge kept and replaced."""
    say = echo or (lambda message: None)
    active_faults()  # a malformed MEMGYM_FAULT is refused before any work (FaultSpecError, a ValueError)
    if repetitions is not None and repetitions < 1:
        raise ValueError(f"repetitions={repetitions} is invalid: expected a whole number >= 1")
    if video is not None and videos < 1:
        raise ValueError(f"videos={videos} is invalid: expected a whole number >= 1 (episodes per checkpoint)")
    check_device(device)
    directories = [Path(run) for run in run_dirs]
    seen: dict[Path, Path] = {}
    for directory in directories:
        if directory.resolve() in seen:
            raise ValueError(f"{seen[directory.resolve()]} and {directory} are the same run directory: give it once")
        seen[directory.resolve()] = directory
    plans = []
    for directory in directories:
        config = run_config(directory)
        seed_range = parse_seed_range(seeds) if seeds else config.eval_seeds
        check_disjoint_seeds(config.env.train_seeds, seed_range)
        plans.append(
            _Plan(
                directory,
                config,
                method or config.method,
                task or config.task,
                seed_range,
                config.eval.repetitions if repetitions is None else repetitions,
                select_checkpoints(directory, checkpoints, config.batch_size),
            )
        )
    _check_cells(out, plans, [], {}, greedy)  # among themselves, before out is created
    with exclusive_lock(out / LOCK_FILE):  # another evaluation into out may be writing: read between its writes
        old_records, old_summary = _existing(out)
    taken = _taken(old_summary)
    names = unique_run_names(directories, [(plan.method, plan.task) for plan in plans], taken)
    for plan, name in zip(plans, names, strict=True):
        plan.name = name
    planned = set().union(*(plan.keys() for plan in plans))
    _check_clashes(out, old_records, planned, force)
    _check_cells(out, plans, old_records, taken, greedy)

    stems = [plan.name.replace("/", "-") for plan in plans]  # GIF names, unique among this evaluation's runs
    stems = [f"{p.method}-{p.task}-{s}" if stems.count(s) > 1 else s for p, s in zip(plans, stems, strict=True)]
    records: list[dict[str, Any]] = []
    training: list[dict[str, Any]] = []
    for plan, stem in zip(plans, stems, strict=True):
        say(
            f"run {plan.name} ({plan.directory}): {describe_seeds(plan.seeds)} x {plan.repetitions} repetitions, "
            f"checkpoint(s) at step(s) {', '.join(map(str, plan.steps))}"
            + (pruned_note(plan.config, plan.checkpoints) if checkpoints == "all" else "")
        )
        for path in plan.checkpoints:
            policy = load_policy(plan.directory, path, device)
            count = len(seed_list(plan.seeds)) * plan.repetitions
            recorder = EpisodeVideo(min(videos, count)) if video else None
            found = evaluate(
                policy.model,
                policy.helm,
                policy.config,
                seed_list(plan.seeds),
                plan.repetitions,
                greedy=greedy,
                sampling_seed=plan.config.eval.seed if sampling_seed is None else sampling_seed,
                step=policy.step,
                run=plan.name,
                device=device,
                progress=progress,
                on_frame=recorder,
            )
            for record in found:
                record["method"], record["task"] = plan.method, plan.task
            records.extend(found)
            if recorder is not None and video is not None:
                recorder.write(video, f"{stem}-step{policy.step}", found)
        log = plan.directory / "training.csv"
        if log.is_file():  # the runs' training logs make the training-seed panel of the curves
            training += [{**row, "run": plan.name, "method": plan.method, "task": plan.task} for row in _read_rows(log)]
        else:
            say(f"note: {plan.directory} has no training.csv: no training-seed curve for run {plan.name}")

    evaluation = {
        "runs": [str(run) for run in run_dirs],
        "names": [plan.name for plan in plans],
        "seeds": seeds,
        "repetitions": repetitions,
        "checkpoints": checkpoints,
        "greedy": greedy,
    }
    # Merged into what out holds now, under its lock: an evaluation that wrote there meanwhile keeps its records
    with exclusive_lock(out / LOCK_FILE):
        return _merge_into(out, plans, records, training, force, say, evaluation)


@dataclass(frozen=True)
class _Member:
    """One run of a (method, task) cell as the pre-evaluation check sees it: its directory, saved config (None when
    that is not found) and config digest."""

    directory: str
    config: Config | None
    digest: str


def _cell_members(
    plans: Sequence[_Plan],
    old_records: Sequence[dict[str, Any]],
    taken: Mapping[tuple[str, str, str], str],
    greedy: bool,
) -> dict[tuple[str, str], list[_Member]]:
    """Every run a results directory will hold after this evaluation, by (method, task): the planned runs and those it
    holds already (their digest from their latest records, their config from their directory where it still exists)."""
    cells: dict[tuple[str, str], dict[str, _Member]] = {}
    for plan in plans:
        directory = str(plan.directory.resolve())
        member = _Member(directory, plan.config, config_digest(plan.config, greedy))
        cells.setdefault((plan.method, plan.task), {})[directory] = member
    latest: dict[tuple[str, str, str], tuple[int, str]] = {}
    for record in old_records:
        digest = str(record.get("config_digest") or "")
        key = (str(record["method"]), str(record["task"]), str(record["run"]))
        if digest and (key not in latest or int(record["step"]) >= latest[key][0]):
            latest[key] = (int(record["step"]), digest)
    for (method, task, name), (_, digest) in latest.items():
        directory = taken.get((method, task, name), name)
        members = cells.setdefault((method, task), {})
        if directory not in members:  # a planned run supersedes its own earlier records
            path = Path(directory) / "config.yaml"
            config = run_config(directory) if path.is_file() else None
            members[directory] = _Member(directory, config, digest)
    return {cell: list(members.values()) for cell, members in cells.items()}


def _check_cells(
    out: Path,
    plans: Sequence[_Plan],
    old_records: Sequence[dict[str, Any]],
    taken: Mapping[tuple[str, str, str], str],
    greedy: bool,
) -> None:
    """Before anything is evaluated: the runs of one (method, task) cell in ``out`` must be seeds of one experiment
    (one config digest), and two directories with the same seed and digest are one run trained twice, which would
    count twice in every interval. Either is refused, naming the directories (and the keys that differ)."""
    for (method, task), members in _cell_members(plans, old_records, taken, greedy).items():
        digests = sorted({member.digest for member in members})
        if len(digests) > 1:
            groups = "; ".join(
                f"{digest}: {', '.join(m.directory for m in members if m.digest == digest)}" for digest in digests
            )
            raise ValueError(
                f"{out}: method {method!r}, task {task!r} would hold runs whose configs differ in more than the seed "
                f"({groups}). {_config_differences(members)} Evaluate them into different --out directories, or "
                "give them different --method/--task names"
            )
        by_seed: dict[int, list[str]] = {}
        for member in members:
            if member.config is not None:
                by_seed.setdefault(member.config.run.seed, []).append(member.directory)
        for seed, directories in sorted(by_seed.items()):
            if len(directories) > 1:
                raise ValueError(
                    f"{out}: {' and '.join(directories)} are the same run (method {method!r}, task {task!r}, "
                    f"run.seed {seed}, config_digest {digests[0]}): trained twice with one seed and config, they "
                    "would count as two runs in every interval. Evaluate one of them, or train another seed "
                    "(--set run.seed=N)"
                )


def _config_differences(members: Sequence[_Member]) -> str:
    """The keys whose values differ between the runs' saved configs (one per digest), as a sentence."""
    settings: dict[str, dict[str, Any]] = {}
    seen: set[str] = set()
    for member in members:
        if member.digest in seen:
            continue
        if member.config is None:
            return f"The config of {member.directory} was not found: compare the runs' config.yaml files."
        seen.add(member.digest)
        settings[member.directory] = experiment_settings(member.config, changed_only=False)
    return describe_differences(settings)


def _check_clashes(out: Path, old_records: Sequence[dict[str, Any]], planned: set[tuple], force: bool) -> None:
    clashes = [record for record in old_records if _record_key(record) in planned]
    if clashes and not force:
        first = dict(zip(("method", "task", "run", "step", "seed", "repetition"), _record_key(clashes[0]), strict=True))
        raise ValueError(
            f"{out / 'episodes.csv'} already holds {len(clashes)} of the records this evaluation would write (e.g. "
            + ", ".join(f"{key}={value}" for key, value in first.items())
            + "): give --force to replace them, or another --out directory"
        )


def _merge_into(
    out: Path,
    plans: Sequence[_Plan],
    records: list[dict[str, Any]],
    training: list[dict[str, Any]],
    force: bool,
    say: Callable[[str], None],
    evaluation: dict[str, Any],
) -> dict[str, Any]:
    """Merge this evaluation's records and training rows into ``out`` (whose lock the caller holds) and write its
    three files together (pre-emption signals wait until they are written); returns the new summary."""
    old_records, old_summary = _existing(out)
    _check_clashes(out, old_records, set().union(*(plan.keys() for plan in plans)), force)
    taken = _taken(old_summary)
    for plan in plans:
        held = taken.get((plan.method, plan.task, plan.name))
        if held is not None and held != str(plan.directory.resolve()):
            raise ValueError(
                f"{out}: while this evaluation ran, another one named {held} run {plan.name} ({plan.method}, "
                f"{plan.task}); evaluate {plan.directory} again to get a name of its own"
            )
    merged, replaced = _merge(old_records, records, _record_key)
    if old_records:
        say(
            f"{out / 'episodes.csv'}: kept {len(old_records) - replaced} earlier record(s), replaced {replaced}, "
            f"added {len(records) - replaced}"
        )
    old_training = _read_rows(out / "training.csv") if (out / "training.csv").is_file() else []
    merged_training, _ = _merge(old_training, training, _training_key)
    with tempfile.TemporaryDirectory() as scratch:  # the merged records are checked before out is touched
        write_records(Path(scratch) / "episodes.csv", merged)
        try:
            summary = summarize_episodes(read_episodes(scratch))
        except ValueError as err:  # named after out, not after the scratch directory the check read
            message = str(err).replace(str(scratch), str(out))
            raise ValueError(f"the records of {out} and of this evaluation do not fit together: {message}") from None
    registry = {**taken, **{(p.method, p.task, p.name): str(p.directory.resolve()) for p in plans}}
    summary["run_directories"] = [
        {"method": key[0], "task": key[1], "run": key[2], "directory": path} for key, path in sorted(registry.items())
    ]
    summary["evaluation"] = {**evaluation, "replaced": replaced, **provenance()}
    earlier = list(old_summary.get("earlier_evaluations", []))
    summary["earlier_evaluations"] = earlier + ([old_summary["evaluation"]] if "evaluation" in old_summary else [])
    episodes_text = records_csv_text(merged).encode()
    training_text = _csv_text(TRAINING_COLUMNS, merged_training).encode() if merged_training else None
    # what summary.json vouches for: a truncated or corrupted episodes.csv / training.csv is refused when read back
    summary["files"] = {"episodes.csv": content_record(episodes_text)}
    if training_text is not None:
        summary["files"]["training.csv"] = content_record(training_text)
    with deferred_signals():
        atomic_write_bytes(out / "episodes.csv", episodes_text)
        if training_text is not None:
            atomic_write_bytes(out / "training.csv", training_text)
        write_json_atomic(out / "summary.json", summary, sort_keys=False)
    return summary
