"""Shared fixtures."""

from __future__ import annotations

import pytest

import envs
from tests.support.dict_env import CORE, ENV_ID


@pytest.fixture
def dict_env(monkeypatch: pytest.MonkeyPatch) -> str:
    """Register the synthetic Dict-observation environment for one test; returns its id."""
    monkeypatch.setitem(envs.ENV_IDS, ENV_ID, (CORE, {}))
    return ENV_ID
