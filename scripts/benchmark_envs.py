"""Environment throughput: steps per second of every registered Memory Gym id, ours and (when available) the
reference memory-gym==1.0.2, side by side in one run.

(a) single: one env through ``gymnasium.make`` (env checker off, as in the reference run), a constant no-op action,
    ``--episodes`` episodes (episode k reset with seed k), resets included in the timing, construction excluded: the
    protocol of the paper's Table 2 and of ``scripts.reference.bench``. Every id ends its no-op episodes by itself
    (the Mortar Mayhem family at the first failed check, Mystery Path / Searing Spotlights at their step limits,
    Endless Mystery Path when the stamina runs out, Endless Searing Spotlights after 160 steps without a coin); the
    longest, MysteryPath-v0, runs 512 steps per episode. ``--max-total-steps`` (default 100k, as in the reference
    run) caps a run and cuts it mid-episode if ever reached.
(b) batched: the native core with 16 and 64 slots driven directly, as the trainer does: ``core.step`` on all slots
    with a constant no-op action, one ``core.reset_slots`` of the finished slots with fresh seeds, and a copy of all
    observations, for ``--batched-steps`` slot-steps after a short warm-up.
(c) vector: what ``gymnasium.make_vec(id, num_envs=64)`` users get: ``step`` with a constant no-op action, the
    vector env's own NEXT_STEP autoreset (finished slots continue their generators), observations and infos as
    returned, for ``--batched-steps`` slot-steps after the same warm-up.

Each measurement is repeated ``--repeats`` times, ours and the reference's (a) interleaved, and the best run is
kept on both sides: the machine is shared, and the best run is the one least disturbed by other load.
Ratios: ours/reference for (a), and (b, 64 slots)/reference (a) and (c)/reference (a).

The report goes to ``runs/benchmarks/envs.json`` (git-ignored) unless ``--out`` names another file; the committed
table is replaced only where ``--out`` names it, and a partial run (``--quick``, some of the ids, or no memory-gym
column) never replaces a full table, wherever it is:

    python scripts/benchmark_envs.py --repeats 3 --out results/benchmarks/envs.json   # the committed table
    python scripts/benchmark_envs.py --ids MortarMayhem-v0 --quick --no-reference     # a smoke run, into runs/
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from agents.runtime.io import SCRATCH, ResultFile, add_out_argument, json_table, provenance
from envs import make_core
from scripts.reference import REFERENCE_IDS  # (the ids measured: those memory-gym has)
from scripts.reference.protocol import time_constant_action_episodes

ROOT = Path(__file__).resolve().parents[1]

SLOT_COUNTS = (16, 64)
DEFAULT_OUT = SCRATCH / "benchmarks" / "envs.json"


def partial_reasons(quick: bool, ids: Iterable[str], no_reference: str) -> str:
    """Why a run is not a full table (every id, not ``--quick``, the memory-gym column), empty when it is one;
    ``no_reference`` says why the memory-gym column is missing (empty when it is there)."""
    measured = set(ids) & set(REFERENCE_IDS)
    reasons = ["--quick"] if quick else []
    if len(measured) < len(REFERENCE_IDS):
        reasons.append(f"{len(measured)} of {len(REFERENCE_IDS)} ids")
    return ", ".join([*reasons, no_reference] if no_reference else reasons)


def report_partial(report: dict[str, Any]) -> str:
    """:func:`partial_reasons` of a written report."""
    rows = report["results"]
    reference = all(row["reference_single_steps_per_s"] for row in rows.values())
    return partial_reasons(report["protocol"]["quick"], rows, "" if reference else "no memory-gym column")


def noop_action(space: gym.Space) -> Any:
    return 0 if isinstance(space, gym.spaces.Discrete) else np.zeros(space.shape, dtype=space.dtype)


def bench_single(env_id: str, episodes: int, max_total_steps: int) -> dict[str, Any]:
    """(a): one env, constant action, ``episodes`` seeded episodes including their resets."""
    env = gym.make(env_id, disable_env_checker=True)
    result = time_constant_action_episodes(env, noop_action(env.action_space), episodes, max_total_steps)
    env.close()
    return result


def bench_batched(env_id: str, num_envs: int, slot_steps: int) -> dict[str, Any]:
    """(b): the core with ``num_envs`` slots: step, reset finished slots with new seeds, fetch the observations."""
    core = make_core(env_id, num_envs=num_envs)
    actions = np.stack([np.asarray(noop_action(core.single_action_space))] * num_envs)
    core.reset_slots(range(num_envs), list(range(num_envs)))
    next_seed = num_envs

    def run(steps: int) -> tuple[int, int]:
        nonlocal next_seed
        done_steps = episodes = 0
        while done_steps < steps:
            _, terminated, _ = core.step(actions)
            if terminated.any():
                done = np.flatnonzero(terminated)
                core.reset_slots(done, list(range(next_seed, next_seed + done.size)))
                next_seed += done.size
                episodes += done.size
            core.observations()
            done_steps += num_envs
        return done_steps, episodes

    run(min(slot_steps // 10, 20 * num_envs))  # warm-up: caches, sprite sheets, first allocations
    start = time.perf_counter()
    steps, episodes = run(slot_steps)
    seconds = time.perf_counter() - start
    return {"steps": steps, "episodes": episodes, "seconds": seconds, "steps_per_s": steps / seconds}


def bench_vector(env_id: str, num_envs: int, slot_steps: int) -> dict[str, Any]:
    """(c): ``gymnasium.make_vec`` with ``num_envs`` slots, its own NEXT_STEP autoreset, a constant no-op action."""
    vec = gym.make_vec(env_id, num_envs=num_envs)
    actions = np.stack([np.asarray(noop_action(vec.single_action_space))] * num_envs)
    vec.reset(seed=0)

    def run(steps: int) -> tuple[int, int]:
        done_steps = episodes = 0
        while done_steps < steps:
            _, _, terminated, truncated, _ = vec.step(actions)
            episodes += int(np.count_nonzero(terminated | truncated))
            done_steps += num_envs
        return done_steps, episodes

    run(min(slot_steps // 10, 20 * num_envs))  # warm-up, as for (b)
    start = time.perf_counter()
    steps, episodes = run(slot_steps)
    seconds = time.perf_counter() - start
    vec.close()
    return {"steps": steps, "episodes": episodes, "seconds": seconds, "steps_per_s": steps / seconds}


def reference_single(env_id: str, episodes: int) -> float | None:
    """(a) of the reference package, run in its isolated venv (None when that venv does not exist)."""
    from scripts.reference.venv import run_reference_bench

    result = run_reference_bench([env_id], episodes=episodes)
    return None if result is None else result.get(env_id)


def main(argv: list[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument(
        "--ids", nargs="+", default=REFERENCE_IDS, choices=REFERENCE_IDS, metavar="ID", help="default: every id"
    )
    parser.add_argument("--episodes", type=int, default=100, help="(a): episodes per id")
    parser.add_argument("--max-total-steps", type=int, default=100_000, help="(a): cap on the steps of one run")
    parser.add_argument("--batched-steps", type=int, default=64_000, help="(b): slot-steps per measurement")
    parser.add_argument("--repeats", type=int, default=3, help="runs per measurement; the best is kept")
    parser.add_argument("--quick", action="store_true", help="smoke run: 3 episodes, 1024 slot-steps, 1 repeat")
    parser.add_argument("--no-reference", action="store_true", help="do not run the reference package")
    add_out_argument(parser, DEFAULT_OUT, "the report")
    args = parser.parse_args(argv)
    if args.quick:
        args.episodes, args.batched_steps, args.repeats = 3, 1024, 1
    partial = partial_reasons(args.quick, args.ids, _missing_reference(args.no_reference))
    target = ResultFile.for_command(parser, args.out, DEFAULT_OUT, json_table(report_partial), partial)

    rows: dict[str, Any] = {}
    header = (
        f"{'id':30s} {'ours (a)':>10s} {'ref (a)':>10s} {'ratio':>6s} {'b16':>10s} {'b64':>10s} {'b64/ref':>8s} "
        f"{'vec64':>10s} {'vec64/ref':>9s}"
    )
    print(header)
    for env_id in args.ids:
        singles, references, batched_runs = [], [], []
        for _ in range(max(args.repeats, 1)):
            singles.append(bench_single(env_id, args.episodes, args.max_total_steps))
            if not args.no_reference:
                references.append(reference_single(env_id, args.episodes))
            runs = {f"b{n}": bench_batched(env_id, n, args.batched_steps) for n in SLOT_COUNTS}
            runs["vec64"] = bench_vector(env_id, 64, args.batched_steps)
            batched_runs.append(runs)
        single = max(singles, key=lambda run: run["steps_per_s"])
        batched = {
            key: max((runs[key] for runs in batched_runs), key=lambda r: r["steps_per_s"]) for key in batched_runs[0]
        }
        reference = max((r for r in references if r is not None), default=None)
        row: dict[str, Any] = {
            "single": single,
            **batched,
            "reference_single_steps_per_s": reference,
            "runs_steps_per_s": {
                "single": [run["steps_per_s"] for run in singles],
                "reference_single": references,
                **{key: [runs[key]["steps_per_s"] for runs in batched_runs] for key in batched_runs[0]},
            },
        }
        if reference:
            row["ratio_single"] = single["steps_per_s"] / reference
            row["ratio_b64_over_reference_single"] = batched["b64"]["steps_per_s"] / reference
            row["ratio_vec64_over_reference_single"] = batched["vec64"]["steps_per_s"] / reference
        rows[env_id] = row

        def fmt(value: float | None, width: int = 10, spec: str = ".0f") -> str:
            return f"{value:{width}{spec}}" if value is not None else f"{'-':>{width}s}"

        print(
            f"{env_id:30s} {fmt(single['steps_per_s'])} {fmt(reference)} {fmt(row.get('ratio_single'), 6, '.2f')} "
            f"{fmt(batched['b16']['steps_per_s'])} {fmt(batched['b64']['steps_per_s'])} "
            f"{fmt(row.get('ratio_b64_over_reference_single'), 8, '.1f')} {fmt(batched['vec64']['steps_per_s'])} "
            f"{fmt(row.get('ratio_vec64_over_reference_single'), 9, '.1f')}",
            flush=True,
        )
    report = {
        **provenance(),
        "protocol": {
            "single": "gymnasium.make, constant no-op action, episode k reset with seed k, resets timed",
            "batched": "core.step on all slots (constant no-op), finished slots reset with fresh seeds, "
            "observations copied; after a warm-up",
            "vector": "gymnasium.make_vec with 64 slots, constant no-op action, its own NEXT_STEP autoreset "
            "(generators continue), observations and infos as returned; after a warm-up",
            "episodes": args.episodes,
            "max_total_steps": args.max_total_steps,
            "batched_slot_steps": args.batched_steps,
            "quick": args.quick,
            "repeats": args.repeats,
            "best_of_repeats": True,
            "command": " ".join([Path(sys.argv[0]).name, *(argv if argv is not None else sys.argv[1:])]),
        },
        "results": rows,
    }
    target.save_json(report, report_partial(report))
    return report


def _missing_reference(no_reference: bool) -> str:
    """Why this run will have no memory-gym column (empty when it will)."""
    from scripts.reference.venv import reference_python, reference_venv_path

    if no_reference:
        return "--no-reference"
    if reference_python() is None:
        return f"no memory-gym column: no reference venv at {reference_venv_path()}"
    return ""


if __name__ == "__main__":
    main()
