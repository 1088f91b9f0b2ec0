"""End-to-end training throughput of GRU-PPO beside the throughput bound of its network on this machine.

    python scripts/benchmark_training.py [--env MortarMayhemB-Grid-v0] [--workers 16] [--worker-steps 128]
        [--epochs 3] [--minibatches 8] [--updates 4] [--repeats 3] [--precision bf16] [--sb3 auto]

* end to end: ``Trainer.train_update()`` (rollout in the batched env, GAE, sequence splitting, PPO epochs with
  optimizer steps) on the paper's GRU network (configs/mortar_mayhem_b_grid/gru.yaml), env steps per second;
* bound: the same network, forward + backward only, over the same minibatches of the same batch for the same
  epochs (inputs gathered beforehand, no rollout, no optimizer): batch size / time. End to end can only approach it;
* SB3: stable-baselines3-contrib RecurrentPPO at the same workers x steps, epochs and minibatch size, when
  ``sb3_contrib`` is importable (its own default network: CNN features 256, separate actor/critic LSTMs of 256).

The three are measured in turns (``--repeats`` rounds) and reported as medians and as the best round of each
(the least disturbed one), because the machine may be shared; every round records the load average.
Prints a table and writes ``results/benchmarks/training.json`` atomically (with versions, git revision, machine).
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # run from a checkout without installing

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

from agents.config import Config, load_config  # noqa: E402
from agents.io import git_revision, machine_info, versions, write_json_atomic  # noqa: E402
from agents.models import log_probs_and_entropy  # noqa: E402
from agents.ppo import filled_index  # noqa: E402
from agents.sequences import minibatch_ids, pad_sequences, split_sequences  # noqa: E402
from agents.trainer import Trainer  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


def benchmark_config(args: argparse.Namespace) -> Config:
    batch = args.workers * args.worker_steps
    overrides = [
        f"env.id={args.env}",
        f"run.workers={args.workers}",
        f"run.worker_steps={args.worker_steps}",
        f"run.total_steps={batch * (args.updates + 1) * (args.repeats + 1)}",
        f"ppo.epochs={args.epochs}",
        f"ppo.minibatches={args.minibatches}",
        f"run.precision={args.precision}",
        f"run.torch_threads={args.threads}",
        "run.progress_bar=false",
        "run.checkpoint_interval=0",
    ]
    return load_config(ROOT / "configs" / "mortar_mayhem_b_grid" / "gru.yaml", overrides)


def end_to_end(trainer: Trainer, updates: int) -> float:
    """Env steps per second over ``updates`` full updates."""
    started = time.perf_counter()
    for _ in range(updates):
        trainer.train_update()
    return updates * trainer.config.batch_size / (time.perf_counter() - started)


def network_bound(trainer: Trainer) -> float:
    """Env steps per second if an update cost only the network's forward + backward passes over its minibatches."""
    config, buffer, model = trainer.config, trainer.buffer, trainer.model
    sequences = split_sequences(buffer.terminated_numpy(), trainer.sequence_length)
    states, actions = buffer.flat(buffer.memory_states), buffer.flat(buffer.actions)
    rng = np.random.default_rng(0)
    epochs = []
    for _ in range(config.ppo.epochs):
        minibatches = []
        for ids in minibatch_ids(len(sequences), config.ppo.minibatches, rng):
            batch = pad_sequences(sequences, ids, device=buffer.device)
            index = batch.step_index
            gathered = buffer.gather(filled_index(index))
            minibatches.append((gathered, states[batch.start_index], batch.mask, actions[index]))
        epochs.append(minibatches)
    started = time.perf_counter()
    for minibatches in epochs:
        for gathered, start_states, mask, minibatch_actions in minibatches:
            with trainer.autocast():
                logits, values = model.evaluate(gathered, start_states, mask)
            log_probs, entropy = log_probs_and_entropy(logits, minibatch_actions)
            (log_probs.mean() + entropy.mean() + values.square().mean()).backward()
    seconds = time.perf_counter() - started
    model.zero_grad(set_to_none=True)
    return config.batch_size / seconds


def sb3_available() -> bool:
    return importlib.util.find_spec("sb3_contrib") is not None


def make_sb3(args: argparse.Namespace) -> object:
    from sb3_contrib import RecurrentPPO
    from stable_baselines3.common.env_util import make_vec_env

    import envs  # noqa: F401  (registers the ids with gymnasium)

    venv = make_vec_env(args.env, n_envs=args.workers, seed=0)
    policy = "MultiInputLstmPolicy" if isinstance(venv.observation_space, gym.spaces.Dict) else "CnnLstmPolicy"
    batch = args.workers * args.worker_steps
    return RecurrentPPO(
        policy,
        venv,
        n_steps=args.worker_steps,
        batch_size=batch // args.minibatches,
        n_epochs=args.epochs,
        seed=0,
        device="cpu",
        verbose=0,
    )


def sb3_throughput(model: object, args: argparse.Namespace) -> float:
    batch = args.workers * args.worker_steps
    started = time.perf_counter()
    model.learn(batch * args.updates, reset_num_timesteps=False)  # type: ignore[attr-defined]
    return batch * args.updates / (time.perf_counter() - started)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", default="MortarMayhemB-Grid-v0")
    parser.add_argument("--workers", type=int, default=16)
    parser.add_argument("--worker-steps", type=int, default=128)
    parser.add_argument("--epochs", type=int, default=3)
    parser.add_argument("--minibatches", type=int, default=8)
    parser.add_argument("--updates", type=int, default=4, help="timed updates per round (after one warm-up)")
    parser.add_argument("--repeats", type=int, default=3, help="measurement rounds (medians are reported)")
    parser.add_argument("--precision", choices=["fp32", "bf16"], default="bf16")
    parser.add_argument("--threads", type=int, default=0, help="torch threads (0: one per core)")
    parser.add_argument("--sb3", choices=["auto", "yes", "no"], default="auto", help="include SB3 RecurrentPPO")
    parser.add_argument("--out", default=str(ROOT / "results" / "benchmarks" / "training.json"))
    args = parser.parse_args(argv)
    use_sb3 = args.sb3 == "yes" or (args.sb3 == "auto" and sb3_available())

    config = benchmark_config(args)
    with tempfile.TemporaryDirectory() as run_dir:
        trainer = Trainer(config, run_dir)
        trainer.train_update()  # warm-up: allocations, oneDNN kernel selection
        sb3 = make_sb3(args) if use_sb3 else None
        if sb3 is not None:
            sb3_throughput(sb3, argparse.Namespace(**{**vars(args), "updates": 1}))  # warm-up
        rounds = []
        for round_number in range(args.repeats):
            row = {"loadavg_before": os.getloadavg()[0]}
            row["end_to_end"] = end_to_end(trainer, args.updates)
            row["bound"] = network_bound(trainer)
            if sb3 is not None:
                row["sb3"] = sb3_throughput(sb3, args)
            row["loadavg_after"] = os.getloadavg()[0]
            rounds.append(row)
            print(f"round {round_number + 1}: " + ", ".join(f"{k} {v:.1f}" for k, v in row.items()), flush=True)

    def aggregate(key: str, how: Callable[[list[float]], float]) -> float | None:
        values = [r[key] for r in rounds if key in r]
        return how(values) if values else None

    summary: dict[str, float | None] = {}
    for how_name, how in (("median", statistics.median), ("best", max)):
        end, bound, sb3_rate = (aggregate(k, how) for k in ("end_to_end", "bound", "sb3"))
        summary[f"{how_name}_end_to_end_steps_per_s"] = end
        summary[f"{how_name}_bound_steps_per_s"] = bound
        summary[f"{how_name}_end_to_end_over_bound"] = end / bound
        summary[f"{how_name}_sb3_recurrent_ppo_steps_per_s"] = sb3_rate
        summary[f"{how_name}_speedup_over_sb3"] = end / sb3_rate if sb3_rate else None
    record = {
        "command": " ".join([Path(sys.argv[0]).name, *(argv if argv is not None else sys.argv[1:])]),
        "setting": {
            "env": args.env,
            "workers": args.workers,
            "worker_steps": args.worker_steps,
            "batch": args.workers * args.worker_steps,
            "epochs": args.epochs,
            "minibatches": args.minibatches,
            "precision": args.precision,
            "network": "configs/mortar_mayhem_b_grid/gru.yaml (Nature CNN + vector encoder -> GRU 512 -> 512 FCs)",
            "parameters": sum(p.numel() for p in trainer.model.parameters()),
            "updates_per_round": args.updates,
        },
        "summary": summary,
        "rounds": rounds,
        "versions": versions(),
        "git": git_revision(),
        "machine": machine_info(),
    }
    if sb3 is not None:
        import sb3_contrib

        record["versions"]["sb3_contrib"] = sb3_contrib.__version__
        record["setting"]["sb3_network"] = "RecurrentPPO default for the observation space (LSTM 256, actor/critic)"
    out = Path(args.out)
    write_json_atomic(out, record, sort_keys=False)

    rows = [
        ("end to end (ours), steps/s", "end_to_end_steps_per_s"),
        ("network bound, steps/s", "bound_steps_per_s"),
        ("end to end / bound", "end_to_end_over_bound"),
        ("SB3 RecurrentPPO, steps/s", "sb3_recurrent_ppo_steps_per_s"),
        ("speedup over SB3", "speedup_over_sb3"),
    ]
    print(f"\n{'':30s}{'median':>10s}{'best':>10s}")
    for label, key in rows:
        median_value, best_value = summary[f"median_{key}"], summary[f"best_{key}"]
        if median_value is not None:
            print(f"{label:30s}{median_value:10.2f}{best_value:10.2f}")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
