"""Bar chart of an environment benchmark (scripts/benchmark_envs.py's JSON): steps/s of the reference (one env) and
ours (one env, 16 and 64 slots, make_vec with 64 slots).

    python scripts/plot_benchmarks.py                      # runs/benchmarks/envs.json -> runs/benchmarks/envs.png
    python scripts/plot_benchmarks.py --json results/benchmarks/envs.json --out results/benchmarks/envs.png

The chart goes to ``runs/benchmarks/envs.png`` (git-ignored) unless ``--out`` names another file; the committed chart
is replaced only where ``--out`` names it, and the chart of a partial benchmark (``--quick``, some of the ids, no
memory-gym column) never replaces the chart of a full one. The PNG says which it is in its ``Memory Gym benchmark``
text chunk (a chart without one counts as full).
"""

from __future__ import annotations

import argparse
import io
import json
from pathlib import Path

from agents.runtime.io import SCRATCH, ResultFile, add_out_argument, repo_relative
from scripts.benchmark_envs import DEFAULT_OUT as DEFAULT_JSON
from scripts.benchmark_envs import report_partial

ROOT = Path(__file__).resolve().parents[1]

DEFAULT_OUT = SCRATCH / "benchmarks" / "envs.png"
MARKER = "Memory Gym benchmark"  # PNG text chunk: "full", or "partial: <why>"
SERIES = (  # (label, how to read the value from one id's result)
    ("memory-gym 1.0.2, 1 env", lambda r: r.get("reference_single_steps_per_s")),
    ("ours, 1 env", lambda r: r["single"]["steps_per_s"]),
    ("ours, 16 slots", lambda r: r["b16"]["steps_per_s"]),
    ("ours, 64 slots", lambda r: r["b64"]["steps_per_s"]),
    ("ours, make_vec 64", lambda r: r["vec64"]["steps_per_s"] if "vec64" in r else None),
)


def chart(results: dict, partial: str = "") -> bytes:
    """Grouped log-scale bars, one group per id, as PNG bytes marked full or partial (``partial``: why)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ids = list(results)
    width = 0.8 / len(SERIES)
    fig, ax = plt.subplots(figsize=(12, 4.5))
    for i, (label, value) in enumerate(SERIES):
        heights = [value(results[env_id]) or 0 for env_id in ids]
        ax.bar([x + (i - (len(SERIES) - 1) / 2) * width for x in range(len(ids))], heights, width, label=label)
    for x, env_id in enumerate(ids):  # the batched goal of the issues: 20x the reference's single env
        reference = results[env_id].get("reference_single_steps_per_s")
        if reference:
            ax.hlines(20 * reference, x - 0.45, x + 0.45, colors="black", linestyles="dashed", linewidth=1)
    ax.plot([], [], "k--", linewidth=1, label="goal: 20x memory-gym")
    ax.set_yscale("log")
    ax.set_ylabel("environment steps per second")
    ax.set_xticks(range(len(ids)), [env_id.replace("-v0", "") for env_id in ids], rotation=30, ha="right")
    ax.legend(ncols=6, fontsize=8, loc="upper center", bbox_to_anchor=(0.5, 1.12))
    ax.grid(axis="y", which="both", alpha=0.3)
    fig.tight_layout()
    image = io.BytesIO()
    fig.savefig(image, format="png", dpi=110, metadata={MARKER: f"partial: {partial}" if partial else "full"})
    plt.close(fig)
    return image.getvalue()


def chart_holds_full(path: Path) -> bool:
    """Whether the PNG at ``path`` charts a full benchmark: unless its marker says partial (a chart drawn before the
    marker existed counts as full). A file that is no image holds no table."""
    from PIL import Image

    try:
        with Image.open(path) as image:
            return not str(image.info.get(MARKER, "full")).startswith("partial")
    except (OSError, ValueError):
        return False


def main(argv: list[str] | None = None) -> Path:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument(
        "--json", type=Path, default=DEFAULT_JSON, help=f"the benchmark (default {repo_relative(DEFAULT_JSON)})"
    )
    add_out_argument(parser, DEFAULT_OUT, "the chart")
    args = parser.parse_args(argv)
    try:
        report = json.loads(args.json.read_text())
    except FileNotFoundError:
        parser.error(
            f"--json {args.json}: no such file; run scripts/benchmark_envs.py first, or chart the committed table "
            "with --json results/benchmarks/envs.json"
        )
    partial = report_partial(report)
    target = ResultFile.for_command(parser, args.out, DEFAULT_OUT, chart_holds_full, partial)
    return target.save(chart(report["results"], partial), partial)


if __name__ == "__main__":
    main()
