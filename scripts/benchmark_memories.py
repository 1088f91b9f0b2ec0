"""The memory modules alone: forward + backward of the training pass over S sequences of L steps, per memory and L.

    python scripts/benchmark_memories.py [--memories gru,lru,ffm,mamba,mamba2] [--lengths 64,128,...,4096]
        [--sequences 16] [--width 128] [--repeats 3] [--threads 0] [--device cpu|cuda] [--set KEY=VALUE ...]
        [--out results/benchmarks/memories.json] [--plot results/benchmarks/memories.png]

The memories: by default every memory of the registry (``agents.memory.MEMORY_SPECS``, in its order) whose training
pass starts from a stored state per sequence, which this benchmark feeds (the memory-less one and a window memory,
whose training pass reads the records before each sequence, are left out). Each is built as the trainer builds it
(``model.memory`` at ``model.memory_size`` = width, one layer, its block's defaults and ``--set`` overrides such as
``model.mamba2.head_dim=16``, validated as a config is: a block that does not fit the width is an error naming the
key), fed random features of that width for S full sequences of L steps from zero start states (the trainer's
``sequences`` call, with the padding mask and the flat step layout of a minibatch), and timed over
``sum(output ** 2).backward()``: the best of ``--repeats`` after a warm-up (the least disturbed; the machine may be
shared, and every row records the load average). Speedups are over the default ``model.memory`` (the GRU), which
runs through the project's own path (the packed GRU on the CPU, cuDNN's on CUDA). ``--device cuda`` takes the same
measurement on a GPU in one command.

The table goes to ``runs/benchmarks/memories.json`` (git-ignored) unless ``--out`` names another file; a partial run
(fewer memories or lengths than the defaults) never replaces a full table. ``--plot`` draws the curve.
"""

from __future__ import annotations

import argparse
import functools
import os
import sys
import time
from pathlib import Path

import torch

from agents.config import ConfigError, ModelConfig, config_from_dict
from agents.memory import MEMORY_SPECS, build_memory
from agents.runtime.io import SCRATCH, ResultFile, add_out_argument, atomic_write_bytes, json_table, provenance

REFERENCE = ModelConfig().memory  # the speedups are over the default memory (the GRU of GRU-PPO)
LENGTHS = (64, 128, 256, 512, 1024, 2048, 4096)
WIDTH = 128
DEFAULT_OUT = SCRATCH / "benchmarks" / "memories.json"


def memory_config(name: str, width: int, overrides: list[str]) -> ModelConfig:
    """The model block of ``name`` at ``width``, one layer, its block's defaults and ``overrides``, validated."""
    raw = {"model": {"memory": name, "memory_size": width, "memory_layers": 1}}
    return config_from_dict(raw, overrides).model


@functools.cache
def default_memories() -> tuple[str, ...]:
    """The registry's memories whose training pass starts from a stored state per sequence (``history`` None), in
    its order: each is built at the default width to tell (a window memory sets ``history``), on the meta device
    (shapes only: nothing is allocated)."""
    found = []
    for name, spec in MEMORY_SPECS.items():
        if not spec.stateless:
            with torch.device("meta"):
                memory = build_memory(memory_config(name, WIDTH, []), WIDTH)
            found += [name] if memory.history is None else []
    return tuple(found)


def partial_reasons(memories: list[str], lengths: list[int]) -> str:
    """Why a run is not the full table (every memory at every length), empty when it is."""
    reasons = []
    if set(memories) != set(default_memories()):
        reasons.append(f"memories {','.join(memories)}")
    if set(lengths) != set(LENGTHS):
        reasons.append(f"lengths {','.join(map(str, lengths))}")
    return ", ".join(reasons)


def record_partial(record: dict) -> str:
    return partial_reasons(record["setting"]["memories"], record["setting"]["lengths"])


def forward_backward_seconds(
    memory: torch.nn.Module, width: int, sequences: int, length: int, repeats: int, device: str
) -> float:
    """The best time of one training pass (forward + backward) over ``sequences`` x ``length`` steps of ``width``
    features."""
    features = torch.randn(sequences * length, width, device=device)
    mask = torch.ones(sequences, length, dtype=torch.bool, device=device)
    records = memory.initial_state(sequences, device)
    best = float("inf")
    for attempt in range(repeats + 1):  # the first is a warm-up
        memory.zero_grad(set_to_none=True)
        if device.startswith("cuda"):
            torch.cuda.synchronize(device)
        started = time.perf_counter()
        memory.sequences(features, records, mask).square().sum().backward()
        if device.startswith("cuda"):
            torch.cuda.synchronize(device)
        if attempt:
            best = min(best, time.perf_counter() - started)
    return best


def plot(record: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    setting = record["setting"]
    figure, axis = plt.subplots(figsize=(6, 4))
    for memory, row in record["milliseconds"].items():
        lengths = [int(length) for length in row]
        axis.plot(lengths, list(row.values()), marker="o", label=memory)
    axis.set(
        xscale="log",
        yscale="log",
        xlabel="sequence length L",
        ylabel="forward + backward (ms)",
        title=f"memory module alone: {setting['sequences']} x L steps, width {setting['width']} ({setting['device']})",
    )
    axis.grid(True, which="both", alpha=0.3)
    axis.legend()
    figure.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    from io import BytesIO

    buffer = BytesIO()
    figure.savefig(buffer, format="png", dpi=120)
    atomic_write_bytes(path, buffer.getvalue())
    plt.close(figure)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument(
        "--memories", default="", help="comma-separated model.memory names (default: every one this benchmark feeds)"
    )
    parser.add_argument("--lengths", default=",".join(map(str, LENGTHS)), help="comma-separated sequence lengths")
    parser.add_argument("--sequences", type=int, default=16, help="sequences per pass (S)")
    parser.add_argument("--width", type=int, default=WIDTH, help="model.memory_size of every memory")
    parser.add_argument("--repeats", type=int, default=3, help="timed passes after a warm-up (the best is kept)")
    parser.add_argument("--threads", type=int, default=0, help="torch threads (0: torch's default)")
    parser.add_argument("--device", default="cpu", help="cpu, cuda or cuda:N")
    parser.add_argument("--plot", type=Path, help="also draw the curve to this PNG")
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="a config override of every memory's model block, e.g. model.mamba2.head_dim=16 (repeatable)",
    )
    add_out_argument(parser, DEFAULT_OUT, "the record")
    args = parser.parse_args(argv)
    if args.threads:
        torch.set_num_threads(args.threads)
    memories = [m for m in (args.memories or ",".join(default_memories())).split(",") if m]
    try:
        lengths = [int(length) for length in args.lengths.split(",") if length]
    except ValueError:
        parser.error(f"--lengths {args.lengths!r}: expected comma-separated integers")
    valid = default_memories()
    unknown = sorted(set(memories) - set(valid))
    if unknown or not memories:
        parser.error(f"--memories {args.memories!r}: unknown {unknown}; valid memories: {', '.join(valid)}")
    if not lengths or min(lengths) < 1:
        parser.error(f"--lengths {args.lengths!r}: expected integers >= 1")
    if args.device != "cpu" and not torch.cuda.is_available():
        parser.error(f"--device {args.device}: CUDA is not available here")
    configs = {}
    for memory_name in memories:  # every setting checked before anything is measured
        try:
            configs[memory_name] = memory_config(memory_name, args.width, args.set)
        except ConfigError as err:
            parser.error(f"--memories {memory_name} at --width {args.width}: {err} (set it with --set KEY=VALUE)")
    target = ResultFile.for_command(
        parser, args.out, DEFAULT_OUT, json_table(record_partial), partial_reasons(memories, lengths)
    )
    torch.manual_seed(0)
    milliseconds: dict[str, dict[str, float]] = {}
    load: dict[str, float] = {}
    for memory_name in memories:
        memory = build_memory(configs[memory_name], args.width).to(args.device)
        milliseconds[memory_name] = {}
        for length in lengths:
            seconds = forward_backward_seconds(memory, args.width, args.sequences, length, args.repeats, args.device)
            milliseconds[memory_name][str(length)] = 1000 * seconds
            print(f"{memory_name:6s} L={length:5d}  {1000 * seconds:9.1f} ms", flush=True)
        load[memory_name] = os.getloadavg()[0]
    speedup = {
        name: {length: milliseconds[REFERENCE][length] / value for length, value in row.items()}
        for name, row in milliseconds.items()
        if name != REFERENCE and REFERENCE in milliseconds
    }
    record = {
        "setting": {
            "memories": memories,
            "lengths": lengths,
            "sequences": args.sequences,
            "width": args.width,
            "repeats": args.repeats,
            "threads": torch.get_num_threads(),
            "device": args.device,
            "measure": "best time of memory.sequences(...).square().sum().backward() over S full sequences of L steps",
        },
        "milliseconds": milliseconds,
        f"speedup_over_{REFERENCE}": speedup,
        "loadavg_after_each_memory": load,
        **provenance(),
    }
    target.save_json(record, record_partial(record), sort_keys=False)
    if args.plot:
        plot(record, args.plot)
        print(f"wrote {args.plot}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
