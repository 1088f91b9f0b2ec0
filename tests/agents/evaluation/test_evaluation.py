"""Evaluation on novel seeds: records, seeds, checkpoints, in-training evaluation == scripts/evaluate.py, videos."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml
from PIL import Image, ImageSequence

from agents.config import config_from_dict
from agents.evaluation.loop import evaluate
from agents.evaluation.records import RECORD_COLUMNS, parse_seed_range, read_records
from agents.evaluation.videos import EpisodeVideo, labelled_frame
from agents.policy.checkpoint import load_policy
from agents.training.trainer import Trainer
from scripts import evaluate as evaluate_script

TINY = {
    "env": {"id": "ProofOfMemory-v0", "options": {"delay": 2}, "train_seeds": [0, 999]},
    "model": {"memory": "gru", "memory_size": 8, "hidden_size": 8},
    "ppo": {"epochs": 1, "minibatches": 2},
    "run": {
        "total_steps": 4 * 8 * 4,
        "workers": 4,
        "worker_steps": 8,
        "seed": 1,
        "progress_bar": False,
        "torch_threads": 1,
        "checkpoint_interval": 2,
        "keep_checkpoints": 0,
    },
    "eval": {"interval": 2, "seeds": [1000, 1003], "repetitions": 3, "seed": 7},
}


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    directory = tmp_path_factory.mktemp("runs") / "tiny-seed1"
    Trainer(config_from_dict(TINY), directory).train()
    return directory


def test_in_training_records_equal_scripts_evaluate_on_the_same_checkpoints(run_dir: Path, tmp_path: Path) -> None:
    """Every checkpoint x seed x repetition once, seeds disjoint from training, and the in-training evaluation gives
    the very records that scripts/evaluate.py gives for the same checkpoint, seeds and sampling seed."""
    out = tmp_path / "evaluation"
    code = evaluate_script.main(["--run", str(run_dir), "--checkpoints", "all", "--out", str(out), "--no-progress"])
    assert code == 0
    records = read_records(out / "episodes.csv")
    assert len(records) == 2 * 4 * 3  # checkpoints x seeds x repetitions
    assert list(records[0])[: len(RECORD_COLUMNS)] == RECORD_COLUMNS and "success" in records[0]
    assert {(r["step"], r["seed"], r["repetition"]) for r in records} == {
        (step, seed, rep) for step in (64, 128) for seed in range(1000, 1004) for rep in range(3)
    }
    assert all(r["seed"] > TINY["env"]["train_seeds"][1] for r in records)
    assert {r["run"] for r in records} == {"tiny-seed1"} and {r["method"] for r in records} == {"gru"}
    assert all(r["metric"] == r["success"] == r["metric_reference"] for r in records)
    assert read_records(run_dir / "eval" / "episodes.csv") == records
    summary = json.loads((out / "summary.json").read_text())
    assert [(row["step"], row["episodes"]) for row in summary["runs"]] == [(64, 12), (128, 12)]
    assert summary["evaluation"]["git"]["revision"]


def test_default_seeds_overlap_error_and_checkpoint_choice(run_dir: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "e"
    assert evaluate_script.main(["--run", str(run_dir), "--seeds", "990:1002", "--out", str(out)]) == 2
    assert "seeds [990, 1001] overlap the training seeds (env.train_seeds) [0, 999]" in capsys.readouterr().err
    assert not out.exists()  # nothing half-written
    assert evaluate_script.main(["--run", str(run_dir), "--checkpoints", "100", "--out", str(out)]) == 2
    assert "no checkpoint at step 100; its checkpoints are at steps [64, 128]" in capsys.readouterr().err
    args = ["--run", str(run_dir), "--checkpoints", "64", "--seeds", "2000:2002", "--repetitions", "2"]
    assert evaluate_script.main([*args, "--greedy", "--method", "mine", "--out", str(out), "--no-progress"]) == 0
    records = read_records(out / "episodes.csv")
    assert [(r["step"], r["seed"], r["repetition"]) for r in records] == [
        (64, 2000, 0),
        (64, 2000, 1),
        (64, 2001, 0),
        (64, 2001, 1),
    ]
    assert {r["method"] for r in records} == {"mine"}
    # greedy play of the same level is the same episode every time
    assert records[0]["return"] == records[1]["return"] and records[2]["length"] == records[3]["length"]
    with pytest.raises(ValueError, match="LOW:HIGH"):
        parse_seed_range("5-9")


@pytest.mark.parametrize(
    ("text", "expected"), [("100000:100030", [100000, 100029]), ("100000..100029", [100000, 100029]), ("7..7", [7, 7])]
)
def test_seed_ranges_in_both_conventions(text: str, expected: list[int]) -> None:
    assert parse_seed_range(text) == expected


@pytest.mark.parametrize("text", ["5-9", "7:7", "9:5", "9..5", "-1..3", "1..", ":5", "a..b"])
def test_bad_seed_ranges_name_both_conventions(text: str) -> None:
    with pytest.raises(ValueError, match=r"LOW\.\.HIGH \(both ends included.*LOW:HIGH \(HIGH excluded"):
        parse_seed_range(text)


def test_videos_show_the_agent_view_beside_the_ground_truth(run_dir: Path, tmp_path: Path) -> None:
    video = tmp_path / "video"
    args = ["--run", str(run_dir), "--out", str(tmp_path / "e"), "--video", str(video), "--videos", "2"]
    assert evaluate_script.main([*args, "--no-progress"]) == 0
    gifs = sorted(video.glob("*.gif"))
    assert [g.name for g in gifs] == ["tiny-seed1-step128-seed1000-rep0.gif", "tiny-seed1-step128-seed1000-rep1.gif"]
    with Image.open(gifs[0]) as gif:
        width, height = gif.size
        frames = [np.asarray(frame.convert("RGB")) for frame in ImageSequence.Iterator(gif)]
    assert width == 2 * 144 and height > 144  # 36x36 agent view upscaled 4x beside the 144x144 ground truth, + text
    band = (height - 144) // 2
    header, footer = frames[0][:band], [frame[band + 144 :] for frame in frames]
    assert header[:, :144].any() and header[:, 144:].any(), "both views are labelled"
    assert len(frames) > 2 and not np.array_equal(footer[0], footer[-1]), "the step and return below change"


def test_video_frames_carry_step_action_reward_and_running_return(run_dir: Path) -> None:
    """The captions follow the episode (the last one's return is the record's), and the drawn text follows them."""
    policy = load_policy(run_dir)
    recorder = EpisodeVideo(3)
    records = evaluate(policy.model, policy.helm, policy.config, [1000, 1001, 1002], 1, on_frame=recorder)
    for captions, frames, record in zip(recorder.captions, recorder.frames, records, strict=True):
        assert len(captions) == len(frames) == record["length"] + 1  # the first observation, then every step
        assert captions[0] == "step 0   return 0.00"
        assert re.fullmatch(r"step 1   action [01]   reward [+-]\d\.\d\d   return -?\d\.\d\d", captions[1])
        assert captions[-1].endswith(f"return {record['return']:.2f}")
    frame = recorder.frames[0][0]
    before = np.asarray(labelled_frame(frame, EpisodeVideo.VIEWS, "step 3   return 0.00"))
    after = np.asarray(labelled_frame(frame, EpisodeVideo.VIEWS, "step 3   return 1.00"))
    band = (before.shape[0] - frame.shape[0]) // 2
    assert np.array_equal(before[band:-band], frame) and np.array_equal(before[:band], after[:band])
    assert not np.array_equal(before[-band:], after[-band:]), "the running return is drawn"
    assert not np.array_equal(before[:band], np.zeros_like(before[:band])), "the views are named"


def test_a_run_without_its_config_is_refused(tmp_path: Path, capsys) -> None:
    (tmp_path / "config.yaml").write_text(yaml.safe_dump(TINY))
    assert evaluate_script.main(["--run", str(tmp_path / "missing")]) == 2
    assert "is not a run directory" in capsys.readouterr().err
    assert evaluate_script.main(["--run", str(tmp_path)]) == 2
    assert "holds no checkpoint" in capsys.readouterr().err


def _copy_run(run_dir: Path, target: Path, **changes: object) -> Path:
    """A copy of ``run_dir`` at ``target`` whose saved config has ``changes`` ({"section.key": value}) applied."""
    shutil.copytree(run_dir, target)
    config = yaml.safe_load((target / "config.yaml").read_text())
    for dotted, value in changes.items():
        section, key = dotted.split(".")
        config[section][key] = value
    (target / "config.yaml").write_text(yaml.safe_dump(config))
    return target


def test_the_same_run_trained_twice_is_one_run_not_two(run_dir: Path, tmp_path: Path, capsys) -> None:
    """Two directories of one cell with the same seed and config are refused before anything is evaluated, naming
    both, whether they come in one call or the second joins the first's results later."""
    twin = _copy_run(run_dir, tmp_path / "later" / "tiny-seed1")
    out = tmp_path / "both"
    assert evaluate_script.main(["--run", str(run_dir), str(twin), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert f"{run_dir.resolve()} and {twin.resolve()} are the same run" in err and "run.seed 1" in err
    assert not out.exists()
    assert evaluate_script.main(["--run", str(run_dir), "--out", str(out), "--no-progress"]) == 0
    capsys.readouterr()
    assert evaluate_script.main(["--run", str(twin), "--out", str(out), "--no-progress"]) == 2
    assert "are the same run" in capsys.readouterr().err


def test_runs_with_different_configs_are_refused_before_evaluating(run_dir: Path, tmp_path: Path, capsys) -> None:
    """The message names the runs' directories and the keys that differ (not a scratch directory), and comes before
    any evaluation (no records are written)."""
    other = _copy_run(run_dir, tmp_path / "other-seed2", **{"run.seed": 2, "ppo.gamma": 0.9})
    out = tmp_path / "out"
    assert evaluate_script.main(["--run", str(run_dir), str(other), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "differ in more than the seed" in err and str(run_dir.resolve()) in err and str(other.resolve()) in err
    assert "Differing keys: ppo.gamma (0.99 in" in err and "0.9 in" in err
    assert "episodes.csv of" not in err and "not found" not in err  # no scratch directory, both configs read
    assert not out.exists()


def test_all_checkpoints_says_how_many_and_that_older_ones_were_pruned(run_dir: Path, tmp_path: Path, capsys) -> None:
    config = {**TINY, "run": {**TINY["run"], "total_steps": 4 * 8 * 6, "checkpoint_interval": 1, "keep_checkpoints": 2}}
    directory = tmp_path / "pruned-seed1"
    Trainer(config_from_dict({**config, "eval": {**TINY["eval"], "interval": 0}}), directory).train()
    out = tmp_path / "e"
    assert (
        evaluate_script.main(["--run", str(directory), "--checkpoints", "all", "--out", str(out), "--no-progress"]) == 0
    )
    printed = capsys.readouterr().out
    assert (
        "checkpoint(s) at step(s) 160, 192 (2 found; the older ones were pruned by run.keep_checkpoints: 2" in printed
    )
    args = ["--run", str(run_dir), "--checkpoints", "all", "--out", str(tmp_path / "kept"), "--no-progress"]
    assert evaluate_script.main(args) == 0  # keep_checkpoints: 0 kept every one
    assert "checkpoint(s) at step(s) 64, 128 (2 found)" in capsys.readouterr().out
