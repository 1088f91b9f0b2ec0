"""The memory modules alone: forward + backward of the training pass over S sequences of L steps, per memory and L.

    python scripts/benchmark_memories.py [--memories gru,lru,ffm,mamba,mamba2] [--lengths 64,128,...,4096]
        [--sequences 16] [--width 128] [--repeats 3] [--threads 0] [--device cpu|cuda]
        [--out results/benchmarks/memories.json] [--plot results/benchmarks/memories.png]

Each memory is built as the trainer builds it (``model.memory`` at ``model.memory_size`` = width, one layer, its
block's defaults), fed random features of that width for S full sequences of L steps from zero start states (the
trainer's ``sequences`` call, with the padding mask and the flat step layout of a minibatch), and timed over
``sum(output ** 2).backward()``: the best of ``--repeats`` after a warm-up (the least disturbed; the machine may be
shared, and every row records the load average). The GRU runs through the project's own path (the packed GRU on the
CPU, cuDNN's on CUDA). ``--device cuda`` takes the same measurement on a GPU in one command.

The table goes to ``runs/benchmarks/memories.json`` (git-ignored) unless ``--out`` names another file; a partial run
(fewer memories or lengths than the defaults) never replaces a full table. ``--plot`` draws the curve.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

import torch

from agents.config import ModelConfig
from agents.memory import build_memory
from agents.runtime.io import SCRATCH, ResultFile, add_out_argument, atomic_write_bytes, json_table, provenance

MEMORIES = ("gru", "lru", "ffm", "mamba", "mamba2")
LENGTHS = (64, 128, 256, 512, 1024, 2048, 4096)
DEFAULT_OUT = SCRATCH / "benchmarks" / "memories.json"


def partial_reasons(memories: list[str], lengths: list[int]) -> str:
    """Why a run is not the full table (every memory at every length), empty when it is."""
    reasons = []
    if set(memories) != set(MEMORIES):
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
    parser.add_argument("--memories", default=",".join(MEMORIES), help="comma-separated model.memory names")
    parser.add_argument("--lengths", default=",".join(map(str, LENGTHS)), help="comma-separated sequence lengths")
    parser.add_argument("--sequences", type=int, default=16, help="sequences per pass (S)")
    parser.add_argument("--width", type=int, default=128, help="model.memory_size of every memory")
    parser.add_argument("--repeats", type=int, default=3, help="timed passes after a warm-up (the best is kept)")
    parser.add_argument("--threads", type=int, default=0, help="torch threads (0: torch's default)")
    parser.add_argument("--device", default="cpu", help="cpu, cuda or cuda:N")
    parser.add_argument("--plot", type=Path, help="also draw the curve to this PNG")
    add_out_argument(parser, DEFAULT_OUT, "the record")
    args = parser.parse_args(argv)
    memories = [m for m in args.memories.split(",") if m]
    try:
        lengths = [int(length) for length in args.lengths.split(",") if length]
    except ValueError:
        parser.error(f"--lengths {args.lengths!r}: expected comma-separated integers")
    unknown = sorted(set(memories) - set(MEMORIES))
    if unknown or not memories:
        parser.error(f"--memories {args.memories!r}: unknown {unknown}; valid memories: {', '.join(MEMORIES)}")
    if not lengths or min(lengths) < 1:
        parser.error(f"--lengths {args.lengths!r}: expected integers >= 1")
    if args.device != "cpu" and not torch.cuda.is_available():
        parser.error(f"--device {args.device}: CUDA is not available here")
    target = ResultFile.for_command(
        parser, args.out, DEFAULT_OUT, json_table(record_partial), partial_reasons(memories, lengths)
    )
    if args.threads:
        torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    milliseconds: dict[str, dict[str, float]] = {}
    load: dict[str, float] = {}
    for memory_name in memories:
        config = ModelConfig(memory=memory_name, memory_size=args.width, memory_layers=1)
        # Mamba-2's heads of 64 channels at width >= 32; fewer channels where 64 does not divide the inner width
        config.mamba2.head_dim = math.gcd(config.mamba2.head_dim, config.mamba2.expand * args.width)
        memory = build_memory(config, args.width).to(args.device)
        milliseconds[memory_name] = {}
        for length in lengths:
            seconds = forward_backward_seconds(memory, args.width, args.sequences, length, args.repeats, args.device)
            milliseconds[memory_name][str(length)] = 1000 * seconds
            print(f"{memory_name:6s} L={length:5d}  {1000 * seconds:9.1f} ms", flush=True)
        load[memory_name] = os.getloadavg()[0]
    speedup = {
        name: {length: milliseconds["gru"][length] / value for length, value in row.items()}
        for name, row in milliseconds.items()
        if name != "gru" and "gru" in milliseconds
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
        "speedup_over_gru": speedup,
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
