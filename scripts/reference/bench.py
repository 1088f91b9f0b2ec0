"""Single-env throughput of the reference package memory-gym==1.0.2 (the paper's Table-2 protocol).

Runs INSIDE the isolated reference venv; normally started by ``scripts.reference.venv.run_reference_bench``.
Protocol per id: one env instance, a constant no-op action (0 or [0, 0]), ``--episodes`` episodes (episode k is
reset with seed k), resets included in the timing, env construction excluded. Every id terminates on its own under
the no-op (MP/MP-Grid/SS by their step limits, Endless-MP after 20 steps without stamina, Endless-SS after 160 steps
without a coin, the MM family at the first failed check); ``--max-total-steps`` (default 100k) is only a safeguard and
cuts the run mid-episode if reached. Prints one JSON line per id: {"id", "steps", "seconds", "steps_per_s",
"episodes"}.

    SDL_VIDEODRIVER=dummy .venv-reference/bin/python -m scripts.reference.bench --ids MortarMayhem-v0  # repo root
"""

from __future__ import annotations

import argparse
import json
import os

import gymnasium as gym
import memory_gym  # noqa: F401  (registers the ids)

from scripts.reference import REFERENCE_IDS
from scripts.reference.protocol import time_constant_action_episodes


def bench(env_id: str, episodes: int = 100, max_total_steps: int = 100_000) -> dict[str, float | int | str]:
    """Time ``episodes`` constant-action episodes (resets included) on one instance of ``env_id``."""
    env = gym.make(env_id, disable_env_checker=True)
    action = 0 if isinstance(env.action_space, gym.spaces.Discrete) else [0, 0]
    return {"id": env_id, **time_constant_action_episodes(env, action, episodes, max_total_steps)}


def main(argv: list[str] | None = None) -> None:
    """CLI: print one JSON line per benchmarked id."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ids", nargs="+", default=REFERENCE_IDS, choices=REFERENCE_IDS)
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--max-total-steps", type=int, default=100_000)
    args = parser.parse_args(argv)
    os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
    for env_id in args.ids:
        print(json.dumps(bench(env_id, args.episodes, args.max_total_steps)), flush=True)


if __name__ == "__main__":
    main()
