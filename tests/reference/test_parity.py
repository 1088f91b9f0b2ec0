"""Every step of every recorded reference trace must be identical, for every id of memory-gym 1.0.2."""

from __future__ import annotations

import pytest

from scripts.reference import REFERENCE_IDS, TRACES_DIR
from scripts.reference.parity import replay, replay_batched


def test_every_reference_id_has_a_trace() -> None:
    missing = [env_id for env_id in REFERENCE_IDS if not (TRACES_DIR / f"{env_id}.json.gz").exists()]
    assert not missing, f"no reference trace for {missing}: run scripts/reference_traces.py --ids ..."


@pytest.mark.parametrize("env_id", REFERENCE_IDS)
def test_reference_trace_parity(env_id: str) -> None:
    result = replay(env_id)
    assert result.steps > 0
    assert result.identical == result.steps, (
        f"{env_id}: {result.identical}/{result.steps} steps identical ({result.percent:.2f}%); first mismatches:\n"
        + "\n".join(result.mismatches)
    )


@pytest.mark.parametrize("env_id", REFERENCE_IDS)
def test_reference_trace_parity_in_one_batch(env_id: str) -> None:
    result = replay_batched(env_id)
    assert result.steps > 0
    assert result.identical == result.steps, (
        f"{env_id} batched: {result.identical}/{result.steps} steps identical; first mismatches:\n"
        + "\n".join(result.mismatches)
    )
