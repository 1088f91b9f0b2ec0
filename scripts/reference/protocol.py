"""The single-environment timing protocol, shared by our benchmark and the reference's so that both time the same.

One instance, a constant action, ``episodes`` episodes (episode k is reset with seed k), resets included in the
timing, construction excluded; ``max_total_steps`` is a safeguard that may cut the run mid-episode. Standard library
only: it runs in the project's venv (``scripts/benchmark_envs.py``) and inside the isolated reference venv
(``scripts.reference.bench``).
"""

from __future__ import annotations

import time
from typing import Any


def time_constant_action_episodes(env: Any, action: Any, episodes: int, max_total_steps: int) -> dict[str, Any]:
    """Run the protocol on ``env``: {"steps", "episodes", "seconds", "steps_per_s"}."""
    steps = done_episodes = 0
    start = time.perf_counter()
    for k in range(episodes):
        env.reset(seed=k)
        done = False
        while not done and steps < max_total_steps:
            _, _, terminated, truncated, _ = env.step(action)
            steps += 1
            done = terminated or truncated
        done_episodes += 1
        if steps >= max_total_steps:
            break
    seconds = time.perf_counter() - start
    return {"steps": steps, "episodes": done_episodes, "seconds": seconds, "steps_per_s": steps / seconds}
