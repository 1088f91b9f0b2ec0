"""Training throughput of every baseline on MMAct Grid, each beside the bound of its network.

    python scripts/benchmark_training.py [--env MortarMayhemB-Grid-v0] [--workers 16] [--worker-steps 128]
        [--epochs 3] [--minibatches 8] [--updates 4] [--repeats 3] [--precision bf16]
        [--methods gru,ppo,stack4,stack16,helm] [--sb3 auto]
    python scripts/benchmark_training.py --env MortarMayhem-Grid-v0 --precision fp32 --methods gru,trxl,gtrxl --sb3 no
        [--threads 1 --out results/benchmarks/training_trxl.json]  (--threads 0: training_trxl_2threads.json)
    python scripts/benchmark_training.py --precision fp32 --methods gru,lru,ffm,mamba,mamba2 --sb3 no
        [--threads 0 --updates 2 --repeats 3 --out results/benchmarks/training_scan_memories_2threads.json]
        (--threads 1 --updates 2 --repeats 1: training_scan_memories.json)

* end to end, per method (configs/mortar_mayhem_b_grid/<method>.yaml at the benchmark's batch; a memory of the
  registry without a file of its own runs GRU-PPO's file with ``model.memory`` set to it): ``train_update()``
  (rollout in the batched env, GAE, sequence splitting, PPO epochs with optimizer steps), env steps per second, with
  the share of the rollout, the HELM branch's share (its frozen forward passes during the rollout) and the peak
  resident memory of a process that trains only that method (each method runs in its own child process);
* bound, per method: its network, forward + backward only, over the same minibatches of the same batch for the same
  epochs (inputs gathered beforehand, frame stacks rebuilt, no rollout, no optimizer): batch size / time. End to
  end can only approach it; end to end / bound says what the rest of the pipeline (rollout, GAE, gathering and
  stacking, optimizer) costs, so a method's larger network and its machinery are told apart;
* acting, per method: the share of the time in the policy's forward passes while it acts (every decision of the
  rollout, 16 rows at a time by default), and end to end over the network's whole time (the bound's training passes
  plus those acting passes): what the environment, the buffer, GAE, gathering and the optimizer cost. The bound
  leaves acting out, so end to end / bound is also below 1 by acting at small batches, which no pipeline removes;
* memory, for the Transformer-XL methods (``trxl``, ``gtrxl``: 3 blocks x 384, 4 heads, a window of 119): the bytes
  per step of the buffer's memory records (each step's layer inputs, stored once, and the windows carried in), and
  the measurement runs on CUDA as well (``--device cuda``: a few minutes), where the peak is torch's allocator's;
* SB3: stable-baselines3-contrib RecurrentPPO at the same workers x steps, epochs and minibatch size, when
  ``sb3_contrib`` is importable (its own default network: CNN features 256, separate actor/critic LSTMs of 256).

The methods: the full table is GRU-PPO (the default ``model.memory``, the reference of every ``/ GRU`` ratio) and
the agents that are no memory (PPO, 4-Stack, 16-Stack, HELM); ``--methods`` may also name every other memory of the
registry (``agents.memory.MEMORY_SPECS``) and its variants' method names (``gtrxl``), listed by ``--help``.

``--precision`` is the runs' ``run.precision``: bf16 (the default; bfloat16 autocast in the training passes, a
bfloat16 copy of the weights acting, the linear recurrences in fp32) or fp32; every method runs at either.

Methods are measured in turns (``--repeats`` rounds) and reported as medians and as the best round of each (the
least disturbed one), because the machine may be shared; every round records the load average.
Prints a table and writes the record atomically (with versions, git revision, machine) to
``runs/benchmarks/training.json`` (git-ignored) unless ``--out`` names another file. The committed table is replaced
only where ``--out`` names it (``--out results/benchmarks/training.json``), and a partial run (some of the methods,
or no SB3 measurement) never replaces a full table, wherever it is: the Transformer-XL table (fp32, MM Grid) is
committed beside it, as ``results/benchmarks/training_trxl.json`` (one thread) and
``training_trxl_2threads.json`` (both cores, unloaded: the setting of the CleanRL figure it is compared with).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from agents.config import Config, ModelConfig, load_config
from agents.memory import MEMORY_SPECS
from agents.policy.models import log_probs_and_entropy
from agents.runtime.io import SCRATCH, ResultFile, add_out_argument, json_table, provenance
from agents.training.ppo import filled_index
from agents.training.sequences import minibatch_ids, pad_sequences, split_sequences
from agents.training.trainer import Trainer

ROOT = Path(__file__).resolve().parent.parent
CONFIG_DIR = ROOT / "configs" / "mortar_mayhem_b_grid"
REFERENCE = ModelConfig().memory  # GRU-PPO's memory: the paper's baseline, the reference of the speedups
AGENTS = ("ppo", "stack4", "stack16", "helm")  # the paper's agents that are no memory (each has its config file)
METHODS = (REFERENCE, *AGENTS)  # the full table
EXTRA_METHODS = tuple(  # measured on request (--methods), beside GRU-PPO: the registry's other memories and variants
    method
    for spec in MEMORY_SPECS.values()
    if not spec.stateless  # the memory-less agent is PPO, in the full table
    for method in (spec.name, *spec.variants)
    if method not in METHODS
)
DEFAULT_OUT = SCRATCH / "benchmarks" / "training.json"


def partial_reasons(methods: Iterable[str], no_sb3: str) -> str:
    """Why a run is not a full table (every method and SB3's RecurrentPPO), empty when it is one; ``no_sb3`` says
    why SB3 is missing (empty when it is measured)."""
    measured = set(methods) & set(METHODS)
    reasons = [] if len(measured) == len(METHODS) else [f"{len(measured)} of {len(METHODS)} methods"]
    return ", ".join([*reasons, no_sb3] if no_sb3 else reasons)


def record_partial(record: dict) -> str:
    """:func:`partial_reasons` of a written record."""
    sb3 = record["summary"]["median"]["sb3_recurrent_ppo_steps_per_s"] is not None
    return partial_reasons(record["setting"]["methods"], "" if sb3 else "no SB3 RecurrentPPO")


def benchmark_config(args: argparse.Namespace, method: str = REFERENCE) -> Config:
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
        f"run.device={args.device}",
        "run.progress_bar=false",
        "run.checkpoint_interval=0",
    ]
    if method == "helm":  # the CPU-sized random transformer: the paper's pretrained one is a download away
        overrides += [f"model.helm.lm={args.helm_lm}"]
    path, memory = method_config(method)
    return load_config(path, [*memory, *overrides])


def method_config(method: str) -> tuple[Path, list[str]]:
    """The config file of ``method`` and the overrides that make it that method: its own file, else (a memory of
    the registry without one) GRU-PPO's file with ``model.memory`` set to it."""
    path = CONFIG_DIR / f"{method}.yaml"
    if path.is_file():
        return path, []
    if method not in MEMORY_SPECS:  # a variant's settings are in its file (gtrxl.yaml: model.trxl.gating)
        raise FileNotFoundError(f"method {method!r} has no config file {path}")
    return CONFIG_DIR / f"{REFERENCE}.yaml", [f"model.memory={method}"]


def method_source(method: str) -> str:
    """Where a method's config comes from, as the record says it: the file, and its override if any."""
    path, memory = method_config(method)
    return " ".join([str(path.relative_to(ROOT)), *(f"--set {item}" for item in memory)])


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
    episode_steps, actions = buffer.flat(buffer.episode_step), buffer.flat(buffer.actions)
    rng = np.random.default_rng(0)
    epochs = []
    for _ in range(config.ppo.epochs):
        minibatches = []
        for ids in minibatch_ids(len(sequences), config.ppo.minibatches, rng):
            batch = pad_sequences(sequences, ids, device=buffer.device)
            index = batch.step_index
            gathered = buffer.gather(filled_index(index))
            records = buffer.memory_records(batch.start_index, batch.mask.shape[1])
            minibatches.append((gathered, records, batch.mask, episode_steps[index], actions[index]))
        epochs.append(minibatches)
    started = time.perf_counter()
    for minibatches in epochs:
        for gathered, records, mask, steps, minibatch_actions in minibatches:
            with trainer.autocast():
                logits, values, _ = model.evaluate(gathered, records, mask, steps)
            log_probs, entropy = log_probs_and_entropy(logits, minibatch_actions)
            (log_probs.mean() + entropy.mean() + values.square().mean()).backward()
    if buffer.device.type == "cuda":  # the kernels queued must have run
        import torch

        torch.cuda.synchronize(buffer.device)
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


def timed(function: Callable[..., Any], seconds: list[float], synchronize: bool = False) -> Callable[..., Any]:
    """``function``, adding the seconds of each call to ``seconds[0]`` (with ``synchronize``, until the CUDA
    kernels it queued have run: a decision waits for them anyway, for its actions)."""

    def timed_call(*a: object, **kw: object) -> object:
        started = time.perf_counter()
        out = function(*a, **kw)
        if synchronize:
            import torch

            torch.cuda.synchronize()
        seconds[0] += time.perf_counter() - started
        return out

    return timed_call


def measure_method(args: argparse.Namespace, method: str) -> dict[str, float]:
    """One round of ``method`` in this process: end-to-end steps/s over ``args.updates`` updates after a warm-up, the
    rollout's and the HELM branch's shares of the time, the network bound, and this process's peak memory."""
    config = benchmark_config(args, method)
    with tempfile.TemporaryDirectory() as run_dir:
        trainer = Trainer(config, run_dir)
        synchronize = config.run.device.startswith("cuda")
        helm_seconds, acting_seconds = [0.0], [0.0]
        if trainer.helm is not None:  # the branch's frozen forward passes (all of them run in the rollout)
            trainer.helm.step = timed(trainer.helm.step, helm_seconds, synchronize)  # type: ignore[method-assign]
        trainer.rollout_model.step = timed(  # type: ignore[method-assign]
            trainer.rollout_model.step, acting_seconds, synchronize
        )  # the policy's forward passes while acting
        trainer.train_update()  # warm-up: allocations, oneDNN kernel selection
        helm_seconds[0] = acting_seconds[0] = 0.0
        started = time.perf_counter()
        rollout_seconds = 0.0
        for _ in range(args.updates):
            metrics = trainer.train_update()
            rollout_seconds += config.batch_size / metrics["charts/rollout_SPS"]
        seconds = time.perf_counter() - started
        row = {
            "end_to_end": args.updates * config.batch_size / seconds,
            "rollout_share": rollout_seconds / seconds,
            "helm_share": helm_seconds[0] / seconds,
            "acting_share": acting_seconds[0] / seconds,
            "acting_seconds_per_update": acting_seconds[0] / args.updates,
            "parameters": float(sum(p.numel() for p in trainer.model.parameters())),
            "bytes_per_step": float(trainer.buffer.bytes_per_step),
            "memory_bytes_per_step": float(trainer.buffer.memory_bytes_per_step),
        }
        row["bound"] = network_bound(trainer)
    row["peak_rss_mib"] = peak_rss_mib()
    if config.run.device.startswith("cuda"):
        import torch

        row["peak_cuda_mib"] = torch.cuda.max_memory_allocated() / 2**20
    return row


def peak_rss_mib() -> float:
    """This process's peak resident memory. Linux's VmHWM belongs to the process image, so it starts afresh at exec;
    getrusage's ru_maxrss does not (a child would report its parent's peak at fork when that is larger)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024  # kB
    except OSError:
        pass
    scale = 1024 * 1024 if sys.platform == "darwin" else 1024  # bytes on macOS, KiB elsewhere
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / scale


def measure_in_child(args: argparse.Namespace, method: str) -> dict[str, float]:
    """:func:`measure_method` in a fresh process, so that its peak memory is that method's alone."""
    command = [sys.executable, str(Path(__file__).resolve()), *args.forwarded, "--child", method]
    done = subprocess.run(command, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"measuring {method} failed:\n{done.stderr[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


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
    parser.add_argument("--device", default="cpu", help="run.device of every method (cpu, cuda, cuda:N)")
    parser.add_argument(
        "--methods", default=",".join(METHODS), help="comma-separated, from " + ", ".join(METHODS + EXTRA_METHODS)
    )
    parser.add_argument("--helm-lm", default="random", help="model.helm.lm of the HELM run (default: random)")
    parser.add_argument("--sb3", choices=["auto", "yes", "no"], default="auto", help="include SB3 RecurrentPPO")
    parser.add_argument(
        "--child", choices=METHODS + EXTRA_METHODS, help=argparse.SUPPRESS
    )  # one measurement, printed as JSON
    add_out_argument(parser, DEFAULT_OUT, "the record")
    args = parser.parse_args(argv)
    argv = list(sys.argv[1:] if argv is None else argv)
    if args.child:
        print(json.dumps(measure_method(args, args.child)))
        return 0
    methods = [m for m in args.methods.split(",") if m]
    unknown = sorted(set(methods) - set(METHODS + EXTRA_METHODS))
    if unknown or not methods:
        valid = ", ".join(METHODS + EXTRA_METHODS)
        parser.error(f"--methods {args.methods!r}: unknown {unknown}; valid methods: {valid}")
    args.forwarded = [  # what a child needs to measure one method (it writes nothing)
        f"--{name.replace('_', '-')}={getattr(args, name)}"
        for name in (
            "env",
            "workers",
            "worker_steps",
            "epochs",
            "minibatches",
            "updates",
            "precision",
            "threads",
            "device",
        )
    ] + [f"--helm-lm={args.helm_lm}"]
    use_sb3 = args.sb3 == "yes" or (args.sb3 == "auto" and sb3_available())
    no_sb3 = (
        "" if use_sb3 else ("--sb3 no" if args.sb3 == "no" else "no SB3 RecurrentPPO: sb3_contrib is not installed")
    )
    target = ResultFile.for_command(
        parser, args.out, DEFAULT_OUT, json_table(record_partial), partial_reasons(methods, no_sb3)
    )
    sb3 = make_sb3(args) if use_sb3 else None
    if sb3 is not None:
        sb3_throughput(sb3, argparse.Namespace(**{**vars(args), "updates": 1}))  # warm-up
    rounds = []
    for round_number in range(args.repeats):
        row: dict[str, object] = {"loadavg_before": os.getloadavg()[0]}
        for method in methods:
            row[method] = measure_in_child(args, method)
        if sb3 is not None:
            row["sb3"] = sb3_throughput(sb3, args)
        row["loadavg_after"] = os.getloadavg()[0]
        rounds.append(row)
        speeds = ", ".join(f"{m} {row[m]['end_to_end']:.0f}" for m in methods)  # type: ignore[index]
        print(f"round {round_number + 1}: steps/s {speeds}" + (f", sb3 {row['sb3']:.0f}" if sb3 else ""), flush=True)

    summary: dict[str, object] = {}
    for how_name, how in (("median", statistics.median), ("best", max)):
        per_method = {}
        for method in methods:
            values = {key: [r[method][key] for r in rounds] for key in rounds[0][method]}  # type: ignore[index]
            chosen = {
                key: how(v) if key in ("end_to_end", "bound") else statistics.median(v) for key, v in values.items()
            }
            per_method[method] = chosen
        for method, row in per_method.items():
            for reference in ("ppo", REFERENCE):
                if reference in per_method and reference != method:
                    row[f"over_{reference}"] = row["end_to_end"] / per_method[reference]["end_to_end"]
        batch = args.workers * args.worker_steps
        for row in per_method.values():  # below 1 by what the rollout, GAE, gathering and optimizer add
            row["end_to_end_over_bound"] = row["end_to_end"] / row["bound"]
            # the network's whole time per update: the bound's training passes and the acting passes
            network_seconds = batch / row["bound"] + row["acting_seconds_per_update"]
            row["end_to_end_over_network"] = row["end_to_end"] * network_seconds / batch
        sb3_values = [r["sb3"] for r in rounds if "sb3" in r]
        sb3_rate = how(sb3_values) if sb3_values else None
        summary[how_name] = {
            "methods": per_method,
            "sb3_recurrent_ppo_steps_per_s": sb3_rate,
            f"{REFERENCE}_speedup_over_sb3": per_method[REFERENCE]["end_to_end"] / sb3_rate
            if sb3_rate and REFERENCE in per_method
            else None,
        }
    record = {
        "command": " ".join([Path(sys.argv[0]).name, *argv]),
        "setting": {
            "env": args.env,
            "workers": args.workers,
            "worker_steps": args.worker_steps,
            "batch": args.workers * args.worker_steps,
            "epochs": args.epochs,
            "minibatches": args.minibatches,
            "precision": args.precision,
            "device": args.device,
            "methods": {m: method_source(m) for m in methods},
            "helm_lm": args.helm_lm,
            "updates_per_round": args.updates,
        },
        "summary": summary,
        "rounds": rounds,
        **provenance(),
    }
    if sb3 is not None:
        import sb3_contrib

        record["versions"]["sb3_contrib"] = sb3_contrib.__version__
        record["setting"]["sb3_network"] = "RecurrentPPO default for the observation space (LSTM 256, actor/critic)"
    target.save_json(record, record_partial(record), sort_keys=False)

    print(
        f"\n{'method':10s}{'steps/s':>10s}{'best':>10s}{'/ PPO':>8s}{'/ ' + REFERENCE.upper():>8s}"
        f"{'bound':>8s}{'/ bound':>9s}{'rollout':>9s}{'acting':>8s}{'/ +acting':>11s}{'HELM':>7s}{'peak MiB':>10s}"
        f"{'memory B/step':>15s}"
    )
    median, best = summary["median"]["methods"], summary["best"]["methods"]  # type: ignore[index]
    for method in methods:
        m = median[method]
        ratios = [f"{m[key]:8.2f}" if key in m else f"{'-':>8s}" for key in ("over_ppo", f"over_{REFERENCE}")]
        print(
            f"{method:10s}{m['end_to_end']:10.0f}{best[method]['end_to_end']:10.0f}{''.join(ratios)}"
            f"{m['bound']:8.0f}{m['end_to_end_over_bound']:9.2f}{m['rollout_share']:9.0%}{m['acting_share']:8.0%}"
            f"{m['end_to_end_over_network']:11.2f}{m['helm_share']:7.0%}"
            f"{m.get('peak_cuda_mib', m['peak_rss_mib']):10.0f}{m['memory_bytes_per_step']:15,.0f}"
        )
    if summary["median"]["sb3_recurrent_ppo_steps_per_s"]:  # type: ignore[index]
        print(f"SB3 RecurrentPPO {summary['median']['sb3_recurrent_ppo_steps_per_s']:.0f} steps/s")  # type: ignore[index]
    return 0


if __name__ == "__main__":
    sys.exit(main())
