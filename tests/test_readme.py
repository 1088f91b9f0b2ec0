"""The README's two set-up commands stay true: CI runs the test command verbatim, the main job names real files."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

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


def test_the_quickstart_promises_the_same_duration_everywhere() -> None:
    readme = (ROOT / "README.md").read_text()
    header = (ROOT / "configs" / "quickstart.yaml").read_text().splitlines()[0]
    assert "about a minute" in header and "GRU-PPO on `ProofOfMemory-v0`, about a minute" in readme


def test_what_the_project_says_it_has_exists() -> None:
    """The package description names only baselines that exist, and the error for a grid names a real script."""
    import tomllib

    from agents.config import config_from_dict
    from agents.policy.models import MEMORY_MODULES
    from agents.training.trainer import Trainer

    description = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["description"]
    assert "Transformer-XL" in description and "trxl" in MEMORY_MODULES
    assert all(word in description for word in ("frame stacking", "HELM", "GRU"))
    try:
        Trainer(config_from_dict({"grid": {"run.seed": [1, 2]}}), ROOT / "runs" / "never-created")
    except ValueError as err:
        script = re.search(r"scripts/\w+\.py", str(err)).group(0)
        assert (ROOT / script).is_file(), script
    else:
        raise AssertionError("a config with a grid was accepted by the trainer")


@pytest.mark.slow
def test_the_headless_notebook_command_writes_the_page(tmp_path: Path) -> None:
    """The first hour's nbconvert line runs as written (on the committed example results, into a temporary dir)."""
    import os
    import shlex
    import subprocess
    import sys

    line = next(line for line in first_hour_commands() if "jupyter nbconvert" in line)
    assignment, *command = shlex.split(line)
    assert command[-2] == "--output-dir", command
    command[-1] = str(tmp_path)
    env = {**os.environ, "MEMORY_GYM_RESULTS": "results/examples/proof_of_memory"}
    jupyter = Path(sys.executable).with_name("jupyter")
    subprocess.run([str(jupyter), *command[1:]], cwd=ROOT, env=env, check=True, capture_output=True, timeout=300)
    page = (tmp_path / "plots.html").read_text()
    assert "<img" in page and "Traceback" not in page


def first_hour_commands() -> list[str]:
    """The command lines of the README's first hour (its ``sh`` block), comments left out."""
    text = (ROOT / "README.md").read_text()
    section = text[text.index("## The first hour") :]
    block = re.search(r"```sh\n(.+?)\n```", section, re.S).group(1)
    return [line for line in block.splitlines() if line.strip() and not line.lstrip().startswith("#")]


def fresh_checkout(target: Path) -> Path:
    """The files a fresh clone of this working tree holds (tracked and new, not ignored), copied to ``target``."""
    import shutil
    import subprocess

    listed = subprocess.run(
        ["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
        cwd=ROOT,
        check=True,
        capture_output=True,
    ).stdout.decode()
    for name in filter(None, listed.split("\0")):
        source = ROOT / name
        if source.is_file():
            (target / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(source, target / name)
    return target


@pytest.mark.slow
def test_the_first_hour_runs_as_written_after_the_setup_command(tmp_path: Path) -> None:
    """In a fresh checkout, the set-up command's job, then every line of the first hour in order, each as written
    (in this environment's Python, which the set-up command's install gave): two runs, not one counted twice, every
    checkpoint evaluated, figures, the notebook's page and the GIFs."""
    import csv
    import os
    import subprocess
    import sys

    checkout = fresh_checkout(tmp_path / "checkout")
    main_job = readme_commands()[0].split(" && ")[-1]
    assert main_job == "python scripts/train.py --config configs/quickstart.yaml", main_job
    bin_dir = str(Path(sys.executable).parent)
    env = {**os.environ, "PATH": bin_dir + os.pathsep + os.environ.get("PATH", ""), "MPLBACKEND": "Agg"}
    for command in [main_job, *first_hour_commands()]:
        done = subprocess.run(
            ["bash", "-c", command], cwd=checkout, env=env, capture_output=True, text=True, timeout=900
        )
        assert done.returncode == 0, f"{command}\n{done.stdout[-2000:]}\n{done.stderr[-2000:]}"
    with open(checkout / "runs" / "mine" / "episodes.csv") as handle:
        rows = list(csv.DictReader(handle))
    runs = {(row["method"], row["run"]) for row in rows}
    steps = {row["step"] for row in rows}
    assert {method for method, _ in runs} == {"gru", "ppo"} and len(runs) == 2, runs
    assert len(steps) == 8 and len(rows) == 2 * 8 * 30 * 5
    for path in ("runs/mine/figures/curves.png", "runs/mine/figures/final.png", "runs/mine/plots.html"):
        assert (checkout / path).is_file(), path
    assert len(list((checkout / "runs" / "videos" / "gifs").glob("*.gif"))) >= 2
