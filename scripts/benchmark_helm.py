"""Per-step time of the HELM branch (agents/policy/helm.py) for a batch of slots, and where it goes.

    python scripts/benchmark_helm.py [--batch 16] [--steps 50] [--repeats 5] [--sizes small gpt2]

For every size, a ``lm="random"`` branch (84x84x3 observations) is stepped ``--steps`` times per round after a
warm-up that fills the memory; the per-step time of :meth:`HelmBranch.step` and of its parts (projection,
retrieval, transformer = the rest) is reported as the best and the median round (the machine may be shared).
Random weights cost what pretrained weights of the same shape cost. Prints a table and writes the record atomically
(with versions, git revision, machine) to ``runs/benchmarks/helm.json`` (git-ignored) unless ``--out`` names another
file; a file under ``results/`` is replaced only where ``--out`` names it, and a run of fewer than the default sizes
never replaces a record of all of them.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from collections.abc import Iterable
from pathlib import Path

import torch

from agents.policy.helm import HelmBranch
from agents.runtime.io import SCRATCH, ResultFile, add_out_argument, json_table, provenance

ROOT = Path(__file__).resolve().parent.parent

# name: (layers, width, heads, vocab, mem_len)
SIZES = {
    "tiny": (2, 128, 4, 4096, 64),
    "small": (2, 256, 4, 8192, 128),
    "small4": (4, 256, 4, 8192, 128),
    "gpt2-small": (12, 768, 12, 50257, 128),
    "pythia-410m": (24, 1024, 16, 50304, 128),
}
DEFAULT_SIZES = ("small", "small4", "gpt2-small")  # the full table
DEFAULT_OUT = SCRATCH / "benchmarks" / "helm.json"


def partial_reasons(sizes: Iterable[str]) -> str:
    """Why a run is not a full table (every default size), empty when it is one."""
    measured = set(sizes) & set(DEFAULT_SIZES)
    return "" if len(measured) == len(DEFAULT_SIZES) else f"{len(measured)} of the {len(DEFAULT_SIZES)} default sizes"


def _per_step(fn, steps: int) -> float:
    start = time.perf_counter()
    for _ in range(steps):
        fn()
    return (time.perf_counter() - start) / steps


def measure(size: str, batch: int, steps: int, repeats: int) -> dict[str, list[float]]:
    layers, width, heads, vocab, mem_len = SIZES[size]
    branch = HelmBranch(
        (84, 84, 3),
        mem_len=mem_len,
        random_layers=layers,
        random_width=width,
        random_heads=heads,
        random_vocab=vocab,
    )
    generator = torch.Generator().manual_seed(0)
    images = torch.randint(0, 256, (batch, 84, 84, 3), dtype=torch.uint8, generator=generator)
    memory = branch.initial_memory(batch, "cpu")
    no_start = torch.zeros(batch, dtype=torch.bool)
    for _ in range(mem_len + 2):  # fill the memory (the attention cost does not depend on it, the mask does)
        branch.step(images, memory, no_start)
    queries = branch.project(images)
    times: dict[str, list[float]] = {"step": [], "projection": [], "retrieval": []}
    with torch.no_grad():
        for _ in range(repeats):
            times["step"].append(_per_step(lambda: branch.step(images, memory, no_start), steps))
            times["projection"].append(_per_step(lambda: branch.project(images), steps))
            times["retrieval"].append(_per_step(lambda: branch.retrieve(queries), steps))
    return times


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--batch", type=int, default=16)
    parser.add_argument("--steps", type=int, default=50)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--sizes", nargs="+", default=list(DEFAULT_SIZES), choices=sorted(SIZES))
    add_out_argument(parser, DEFAULT_OUT, "the record")
    args = parser.parse_args(argv)
    holds_full = json_table(lambda record: partial_reasons(record["results"]))
    target = ResultFile.for_command(parser, args.out, DEFAULT_OUT, holds_full, partial_reasons(args.sizes))
    rows = {}
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads, batch {args.batch}, load {os.getloadavg()}")
    print(
        f"{'size':>11} {'L x d, V, mem':>22} {'step ms':>9} {'(median)':>9} {'proj ms':>8} {'retr ms':>8} {'LM ms':>7}"
    )
    for size in args.sizes:
        times = measure(size, args.batch, args.steps, args.repeats)
        best = {k: min(v) * 1e3 for k, v in times.items()}
        median = statistics.median(times["step"]) * 1e3
        layers, width, _, vocab, mem_len = SIZES[size]
        shape = f"{layers} x {width}, {vocab}, {mem_len}"
        lm_ms = best["step"] - best["projection"] - best["retrieval"]
        print(
            f"{size:>11} {shape:>22} {best['step']:9.2f} {median:9.2f} {best['projection']:8.2f} "
            f"{best['retrieval']:8.2f} {lm_ms:7.2f}"
        )
        rows[size] = {
            "layers": layers,
            "width": width,
            "vocab": vocab,
            "mem_len": mem_len,
            "best_ms": {**best, "transformer": lm_ms},
            "median_step_ms": median,
            "rounds_ms": {key: [t * 1e3 for t in values] for key, values in times.items()},
        }
    setting = {"batch": args.batch, "steps": args.steps, "repeats": args.repeats, "threads": torch.get_num_threads()}
    record = {"setting": setting, "results": rows, **provenance()}
    target.save_json(record, partial_reasons(rows), sort_keys=False)


if __name__ == "__main__":
    main()
