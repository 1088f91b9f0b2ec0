"""The one rule of what a run that goes on may change (agents.config.resume_may_change): run.total_steps, to
lengthen it, and the settings no record depends on. train.py --resume, the checkpoint check and the sweep's resume
follow it."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from agents.config import Config, config_from_dict, config_to_dict, resume_may_change
from agents.experiments.planning import SweepError, panel_from_dict
from agents.experiments.state import PARTIAL, prepare_run, run_status
from agents.policy.checkpoint import check_checkpoint_config

TINY = {
    "env": {"id": "ProofOfMemory-v0", "options": {"delay": 3}},
    "model": {"memory": "gru", "memory_size": 8, "hidden_size": 8, "vector_encoder_size": 8},
    "run": {"total_steps": 128, "workers": 4, "worker_steps": 16, "progress_bar": False},
}


def _keys(tree: object, prefix: str = "") -> list[str]:
    if not isinstance(tree, dict) or not tree:
        return [prefix]
    return [key for name, value in tree.items() for key in _keys(value, f"{prefix}.{name}" if prefix else name)]


def test_only_the_length_and_the_settings_no_record_depends_on_may_change() -> None:
    """Every other key decides a record: the model, the data, the seeds, the names in the rows, when evaluations
    happen, and the floats themselves (run.device). run.torch_threads changes only the rounding: a resume by hand
    takes it (saying so), a sweep's does not."""
    changeable = {key for key in _keys(config_to_dict(Config())) if resume_may_change(key)}
    assert changeable == {
        "run.total_steps",
        "run.progress_bar",
        "run.checkpoint_interval",
        "run.keep_checkpoints",
        "run.wandb.project",
        "run.wandb.entity",
        "run.wandb.group",
        "run.wandb.mode",
        "env.check_seeding",
        "run.torch_threads",
    }
    assert not resume_may_change("run.torch_threads", rounding=False)
    assert not resume_may_change("run.total_steps", lengthen=False)  # the sweep does not lengthen runs
    assert resume_may_change("run.wandb", lengthen=False)  # a whole neutral block
    assert not any(resume_may_change(key) for key in ("run.device", "run.method", "eval.interval", "grid"))


def test_one_table_says_what_a_resume_may_change_and_what_the_digest_leaves_out() -> None:
    """Every key of the table names a config key or block; a key a resume may change without a new experiment is
    outside the digest, and the length, which a resume may raise, is inside it (a lengthened run is another one)."""
    from agents.config import LENGTH_KEY, NOT_IN_DIGEST, RESULT_NEUTRAL, ROUNDING_ONLY, SETTINGS, in_digest

    tree = config_to_dict(Config())
    keys = set(_keys(tree))
    for key in SETTINGS:
        assert key in keys or any(found.startswith(key + ".") for found in keys) or key == "grid", key
    assert not any(in_digest(key) for key in [*RESULT_NEUTRAL, *ROUNDING_ONLY]) and in_digest(LENGTH_KEY)
    assert not in_digest("run.wandb.project") and not in_digest("run.wandb")  # a block: every key in it
    assert in_digest("run.seed_count") and not in_digest("run.seed")  # a key, not a prefix of a word
    assert set(NOT_IN_DIGEST) == {key for key, setting in SETTINGS.items() if setting.digest_why is not None}


def test_a_checkpoint_loads_under_a_config_yaml_whose_neutral_settings_changed() -> None:
    config = config_from_dict(TINY)
    saved = config_to_dict(config)
    saved["run"]["progress_bar"], saved["run"]["keep_checkpoints"], saved["run"]["wandb"]["project"] = True, 7, "p"
    assert check_checkpoint_config({"config": saved}, config, "update_0000001.pt") is None
    saved["run"]["seed"] = 3
    with pytest.raises(ValueError, match=r"\(differing: run.seed\)"):
        check_checkpoint_config({"config": saved}, config, "update_0000001.pt")


def test_a_sweep_run_that_goes_on_takes_the_grids_neutral_settings_and_refuses_the_others(tmp_path: Path) -> None:
    raw = {**TINY, "grid": {"run.seed": [0]}}
    (run,) = panel_from_dict(raw, root=tmp_path, name="p").runs
    prepare_run(run, torch_threads=1)
    (changed,) = panel_from_dict(
        raw, ["run.progress_bar=true", "run.wandb.mode=offline", "run.keep_checkpoints=0"], root=tmp_path, name="p"
    ).runs
    assert run_status(changed).state == PARTIAL
    prepare_run(changed, torch_threads=2)
    saved = yaml.safe_load((run.run_dir / "config.yaml").read_text())["run"]
    assert (saved["progress_bar"], saved["wandb"]["mode"], saved["keep_checkpoints"]) == (True, "offline", 0)
    assert saved["torch_threads"] == 1  # fixed when the run was created: it changes the floats
    (longer,) = panel_from_dict(raw, ["run.total_steps=256", "run.progress_bar=false"], root=tmp_path, name="p").runs
    with pytest.raises(SweepError, match=r"run.total_steps: saved 128, now 256\)"):  # the only difference named
        run_status(longer)
