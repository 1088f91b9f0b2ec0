"""Shared fixtures, and the CI rule that no test may be skipped."""

from __future__ import annotations

import pytest

import envs
from tests.support.dict_env import CORE, ENV_ID


@pytest.fixture
def dict_env(monkeypatch: pytest.MonkeyPatch) -> str:
    """Register the synthetic Dict-observation environment for one test; returns its id."""
    monkeypatch.setitem(envs.ENV_IDS, ENV_ID, (CORE, {}))
    return ENV_ID


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    """In CI (``CI`` set, as CI services do), a skipped test fails the run: a missing dev dependency must not pass
    silently. Locally, skips are listed by ``-ra``."""
    import os

    if not os.environ.get("CI") or exitstatus != 0:
        return
    reporter = session.config.pluginmanager.get_plugin("terminalreporter")
    skipped = reporter.stats.get("skipped", []) if reporter is not None else []
    if skipped:
        names = ", ".join(sorted({getattr(report, "nodeid", "?") or "?" for report in skipped}))
        if reporter is not None:
            reporter.write_line(f"CI: {len(skipped)} test(s) skipped, which CI does not allow: {names}", red=True)
        session.exitstatus = pytest.ExitCode.TESTS_FAILED
