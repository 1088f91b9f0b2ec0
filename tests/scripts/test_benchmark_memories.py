"""The memory-module benchmark times every memory's training pass and writes its record (and the curve)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from scripts import benchmark_memories


def test_benchmark_writes_a_record_and_a_curve(tmp_path: Path) -> None:
    out, png = tmp_path / "memories.json", tmp_path / "memories.png"
    args = ["--lengths", "8,20", "--sequences", "2", "--width", "8", "--repeats", "1", "--threads", "1"]
    assert benchmark_memories.main([*args, "--out", str(out), "--plot", str(png)]) == 0
    record = json.loads(out.read_text())
    assert set(record["milliseconds"]) == set(benchmark_memories.MEMORIES)
    for row in record["milliseconds"].values():
        assert set(row) == {"8", "20"} and all(value > 0 for value in row.values())
    speedup = record["speedup_over_gru"]["lru"]["20"]
    assert speedup == record["milliseconds"]["gru"]["20"] / record["milliseconds"]["lru"]["20"]
    assert record["git"]["revision"] and record["setting"]["device"] == "cpu"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # fewer lengths than the defaults: a partial table, which never replaces the full one
    assert benchmark_memories.partial_reasons(list(benchmark_memories.MEMORIES), [8, 20]) == "lengths 8,20"


@pytest.mark.parametrize(
    ("args", "message"),
    [(["--memories", "gru,rwkv"], "unknown ['rwkv']"), (["--lengths", "64,x"], "expected comma-separated integers")],
)
def test_bad_arguments_are_named(args: list[str], message: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        benchmark_memories.main(args)
    assert exit_info.value.code == 2 and message in capsys.readouterr().err
