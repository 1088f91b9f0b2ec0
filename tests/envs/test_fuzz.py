"""Fuzzed environments (Hypothesis): random valid options, seeds and action scripts on every id and face, random
invalid input. The properties live in envs/fuzzing.py; ``HYPOTHESIS_PROFILE=long`` (or
``scripts/fuzz_envs.py``) runs many more cases than CI's bounded, derandomized ``ci`` profile."""

from __future__ import annotations

import pytest

from envs.fuzzing import ALL_IDS, PROPERTIES


@pytest.mark.parametrize("env_id", ALL_IDS)
@pytest.mark.parametrize("prop", list(PROPERTIES))
def test_fuzz(prop: str, env_id: str) -> None:
    PROPERTIES[prop](env_id)
