"""Every step of every recorded reference trace must be identical for every implemented Memory Gym id."""

from __future__ import annotations

import pytest

from envs import ENV_IDS
from tests.parity import REFERENCE_IDS, TRACE_ROOT, replay

IMPLEMENTED = [env_id for env_id in REFERENCE_IDS if env_id in ENV_IDS]


def test_every_implemented_id_has_a_trace() -> None:
    missing = [env_id for env_id in IMPLEMENTED if not (TRACE_ROOT / f"{env_id}.json.gz").exists()]
    assert not missing, f"no reference trace for {missing}: run scripts/reference_traces.py --ids ..."


@pytest.mark.parametrize("env_id", IMPLEMENTED)
def test_reference_trace_parity(env_id: str) -> None:
    result = replay(env_id)
    assert result.steps > 0
    assert result.identical == result.steps, (
        f"{env_id}: {result.identical}/{result.steps} steps identical ({result.percent:.2f}%); first mismatches:\n"
        + "\n".join(result.mismatches)
    )
