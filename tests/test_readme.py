"""The README's two set-up commands stay true: CI runs the test command verbatim, the main job names real files."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def readme_commands() -> list[str]:
    text = (ROOT / "README.md").read_text()
    return re.findall(r"```bash\n(python3 -m venv .+?)\n```", text)


def test_readme_has_exactly_two_setup_commands_and_ci_runs_the_test_one() -> None:
    commands = readme_commands()
    assert len(commands) == 2, commands
    main_job, test_command = commands
    assert "scripts/train.py --config" in main_job and "pytest" in test_command
    assert test_command in (ROOT / ".ci" / "run").read_text()
    config = re.search(r"--config (\S+)", main_job).group(1)
    assert (ROOT / config).is_file(), config
