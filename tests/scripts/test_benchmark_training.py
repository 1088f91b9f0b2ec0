"""The training benchmark measures every requested method in its own process and writes its JSON record."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from agents.runtime.io import ROOT, SCRATCH
from scripts import benchmark_training


@pytest.mark.slow
def test_benchmark_writes_a_complete_record(tmp_path: Path) -> None:
    out = tmp_path / "training.json"
    args = ["--env", "ProofOfMemory-v0", "--workers", "2", "--worker-steps", "16", "--epochs", "1"]
    args += ["--minibatches", "2", "--updates", "1", "--repeats", "1", "--precision", "fp32", "--threads", "1"]
    args += ["--methods", "gru,ppo,stack4", "--sb3", "no", "--out", str(out)]
    ballast = np.ones(200_000_000)  # 1.6 GB resident in this process: a child must not report it as its own peak
    assert benchmark_training.main(args) == 0
    del ballast
    record = json.loads(out.read_text())
    for how in ("median", "best"):
        summary = record["summary"][how]
        methods = summary["methods"]
        assert set(methods) == {"gru", "ppo", "stack4"}
        for row in methods.values():
            assert row["end_to_end"] > 0 and 0 < row["rollout_share"] < 1 and 50 < row["peak_rss_mib"] < 1500
            assert row["helm_share"] == 0.0
            assert row["bound"] > 0 and row["end_to_end_over_bound"] == row["end_to_end"] / row["bound"]
            assert 0 < row["acting_share"] < row["rollout_share"]  # the policy's passes, inside the rollout
            network = 32 / row["bound"] + row["acting_seconds_per_update"]  # training passes + acting passes
            assert row["end_to_end_over_network"] == pytest.approx(row["end_to_end"] * network / 32)
            assert row["end_to_end_over_network"] > row["end_to_end_over_bound"]
        assert methods["stack4"]["over_ppo"] == methods["stack4"]["end_to_end"] / methods["ppo"]["end_to_end"]
        assert methods["stack4"]["bytes_per_step"] > methods["ppo"]["bytes_per_step"]
        assert summary["sb3_recurrent_ppo_steps_per_s"] is None
    assert record["setting"]["batch"] == 32 and record["setting"]["env"] == "ProofOfMemory-v0"
    assert set(record["versions"]) >= {"python", "torch", "numpy", "gymnasium"}
    assert record["git"]["revision"] and record["machine"]["cpu_count"]
    assert not list(tmp_path.glob(".*tmp*"))  # the atomic write left no temporary file


def test_a_partial_run_never_replaces_a_full_table(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert benchmark_training.DEFAULT_OUT == SCRATCH / "benchmarks" / "training.json"  # git-ignored, not results/
    full = tmp_path / "training.json"  # the committed table, copied: every method and SB3
    shutil.copy(ROOT / "results" / "benchmarks" / "training.json", full)
    before = full.read_bytes()
    for partial, why in ((["--methods", "gru,ppo"], "2 of 5 methods"), (["--sb3", "no"], "--sb3 no")):
        with pytest.raises(SystemExit) as exit_:  # refused before anything is measured
            benchmark_training.main([*partial, "--out", str(full)])
        assert exit_.value.code == 2
        err = capsys.readouterr().err
        assert f"{full} holds a full table and this run is partial ({why}" in err and "--out PATH" in err
    assert full.read_bytes() == before and list(tmp_path.iterdir()) == [full]


def test_the_methods_come_from_the_registry() -> None:
    """The full table: GRU-PPO (the default memory) and the agents that are no memory; on request, every other memory
    of the registry and its variants' method names, each from its config file or, without one, GRU-PPO's file with
    model.memory set to it."""
    assert benchmark_training.METHODS == ("gru", "ppo", "stack4", "stack16", "helm")
    assert benchmark_training.EXTRA_METHODS == ("lstm", "trxl", "gtrxl", "lru", "ffm", "mamba", "mamba2")
    config_dir = ROOT / "configs" / "mortar_mayhem_b_grid"
    assert benchmark_training.method_config("gtrxl") == (config_dir / "gtrxl.yaml", [])
    assert benchmark_training.method_config("lstm") == (config_dir / "gru.yaml", ["model.memory=lstm"])
    assert benchmark_training.method_source("lstm") == "configs/mortar_mayhem_b_grid/gru.yaml --set model.memory=lstm"


def test_bad_methods_are_named(capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit) as exit_:
        benchmark_training.main(["--methods", "gru,rwkv", "--sb3", "no"])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert "unknown ['rwkv']; valid methods: gru, ppo, stack4, stack16, helm, lstm, trxl, gtrxl, lru, ffm" in err


@pytest.mark.slow
def test_benchmark_measures_transformer_xl_beside_gru(tmp_path: Path) -> None:
    """--methods gru,trxl,lstm: TrXL (configs/mortar_mayhem_b_grid/trxl.yaml: 3 x 384, window 119) at GRU-PPO's
    batch, with the bytes per step of each memory's records: the GRU's start state (512 floats), TrXL's layer inputs
    (3 x 384 floats) once per step plus the 119-step windows carried into the rollout; the LSTM, which has no file of
    its own, runs GRU-PPO's with model.memory=lstm (its state: hidden and cell, 2 x 512 floats)."""
    out = tmp_path / "training.json"
    args = ["--env", "ProofOfMemory-v0", "--workers", "2", "--worker-steps", "16", "--epochs", "1"]
    args += ["--minibatches", "2", "--updates", "1", "--repeats", "1", "--precision", "fp32", "--threads", "1"]
    args += ["--methods", "gru,trxl,lstm", "--sb3", "no", "--out", str(out)]
    assert benchmark_training.main(args) == 0
    record = json.loads(out.read_text())
    assert record["setting"]["methods"]["lstm"] == "configs/mortar_mayhem_b_grid/gru.yaml --set model.memory=lstm"
    methods = record["summary"]["median"]["methods"]
    assert methods["gru"]["memory_bytes_per_step"] == 512 * 4
    assert methods["lstm"]["memory_bytes_per_step"] == 2 * 512 * 4 and methods["lstm"]["over_gru"] > 0
    assert methods["trxl"]["memory_bytes_per_step"] == 3 * 384 * 4 * (16 + 119) // 16
    assert methods["trxl"]["end_to_end"] > 0 and methods["trxl"]["bound"] > 0 and methods["trxl"]["over_gru"] > 0
