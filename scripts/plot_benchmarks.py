"""Bar chart of results/benchmarks/envs.json: steps/s of the reference (one env) and ours (one env, 16 and 64 slots,
make_vec with 64 slots).

Usage: python scripts/plot_benchmarks.py [--json results/benchmarks/envs.json] [--out results/benchmarks/envs.png]
"""

from __future__ import annotations

import argparse
import io
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from agents.io import atomic_write_bytes  # noqa: E402

SERIES = (  # (label, how to read the value from one id's result)
    ("memory-gym 1.0.2, 1 env", lambda r: r.get("reference_single_steps_per_s")),
    ("ours, 1 env", lambda r: r["single"]["steps_per_s"]),
    ("ours, 16 slots", lambda r: r["b16"]["steps_per_s"]),
    ("ours, 64 slots", lambda r: r["b64"]["steps_per_s"]),
    ("ours, make_vec 64", lambda r: r["vec64"]["steps_per_s"] if "vec64" in r else None),
)


def plot(results: dict, out: Path) -> None:
    """Grouped log-scale bars, one group per id; written atomically."""
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
    fig.savefig(image, format="png", dpi=110)
    atomic_write_bytes(out, image.getvalue())
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--json", type=Path, default=ROOT / "results" / "benchmarks" / "envs.json")
    parser.add_argument("--out", type=Path, default=ROOT / "results" / "benchmarks" / "envs.png")
    args = parser.parse_args()
    plot(json.loads(args.json.read_text())["results"], args.out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
