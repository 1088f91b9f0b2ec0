"""The memory-module benchmark times every memory's training pass and writes its record (and the curve)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from scripts import benchmark_memories


def test_the_memories_come_from_the_registry() -> None:
    """Every memory that starts its sequences from stored states, in the registry's order: not the memory-less one,
    not the Transformer-XL (its training pass reads a window of records before each sequence)."""
    assert benchmark_memories.default_memories() == ("gru", "lstm", "lru", "ffm", "mamba", "mamba2")
    assert benchmark_memories.REFERENCE == "gru"


def test_benchmark_writes_a_record_and_a_curve(tmp_path: Path) -> None:
    out, png = tmp_path / "memories.json", tmp_path / "memories.png"
    args = ["--lengths", "8,20", "--sequences", "2", "--width", "8", "--repeats", "1", "--threads", "1"]
    args += ["--set", "model.mamba2.head_dim=4"]  # Mamba-2's heads must divide its inner width, 2 x 8
    assert benchmark_memories.main([*args, "--out", str(out), "--plot", str(png)]) == 0
    record = json.loads(out.read_text())
    assert list(record["milliseconds"]) == list(benchmark_memories.default_memories())
    for row in record["milliseconds"].values():
        assert set(row) == {"8", "20"} and all(value > 0 for value in row.values())
    speedup = record["speedup_over_gru"]["lru"]["20"]
    assert speedup == record["milliseconds"]["gru"]["20"] / record["milliseconds"]["lru"]["20"]
    assert record["git"]["revision"] and record["setting"]["device"] == "cpu"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # fewer lengths than the defaults: a partial table, which never replaces the full one
    assert benchmark_memories.partial_reasons(list(benchmark_memories.default_memories()), [8, 20]) == "lengths 8,20"


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--memories", "gru,rwkv"], "unknown ['rwkv']; valid memories: gru, lstm, lru, ffm, mamba, mamba2"),
        (["--memories", "trxl"], "unknown ['trxl']"),  # a window memory: this benchmark feeds start states only
        (["--lengths", "64,x"], "expected comma-separated integers"),
        (  # a block that does not fit the width is named, with the way to set it
            ["--memories", "mamba2", "--width", "8"],
            "--memories mamba2 at --width 8: model.mamba2.head_dim=64 is invalid: expected a divisor",
        ),
        (["--memories", "gru", "--set", "model.lru.r_min=2"], "model.lru.r_min=2"),
    ],
)
def test_bad_arguments_are_named(args: list[str], message: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        benchmark_memories.main(args)
    assert exit_info.value.code == 2 and message in capsys.readouterr().err
