"""The baselines on a gymnasium environment brought by the user (tests/support/tiny_env.py, reached as
"module:EnvId"): its spaces, per-slot seeding, training and evaluation end to end, resume, and POPGym."""

from __future__ import annotations

import shutil
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch

import envs
from agents.analysis.metrics import metric_of
from agents.analysis.plots import curves_figure, final_figure
from agents.analysis.results import read_episodes
from agents.config import ConfigError, config_from_dict, task_name
from agents.evaluation.loop import evaluate
from agents.evaluation.records import seed_list, write_records
from agents.memory import MEMORY_MODULES
from agents.training.trainer import Trainer
from envs.gymnasium_core import GymnasiumCore, SeedingError, UnsupportedSpaceError
from tests.support.interrupt import kill_after
from tests.support.tiny_env import ENV_ID, TinyMemoryEnv

TINY = {
    "env": {"id": ENV_ID, "make_kwargs": {"delay": 2}},
    "model": {"encoder": "mlp", "mlp_sizes": [32], "memory": "gru", "memory_size": 32, "hidden_size": 32},
    "ppo": {"epochs": 3, "minibatches": 4, "learning_rate": 1.0e-3, "entropy_coef": 1.0e-3},
    "run": {
        "total_steps": 16 * 32 * 4,
        "workers": 16,
        "worker_steps": 32,
        "seed": 1,
        "progress_bar": False,
        "torch_threads": 1,
    },
    "eval": {"seeds": [100000, 100019], "repetitions": 2},
}
HELM = ("model.helm.lm=random", "model.helm.mem_len=3", "model.helm.random_layers=1", "model.helm.random_width=16")
HELM = (*HELM, "model.helm.random_heads=2", "model.helm.random_vocab=32")
SUCCESS = ("env.metric.key=success", "env.metric.label=Success Rate", "env.metric.low=0", "env.metric.high=1")


def _config(*overrides: str):
    return config_from_dict(TINY, list(overrides))


def _core(num_envs: int = 4, **make_kwargs) -> GymnasiumCore:
    core = envs.make_core(ENV_ID, num_envs, make_kwargs=make_kwargs)
    assert isinstance(core, GymnasiumCore)
    return core


def _cue(observation: np.ndarray) -> np.ndarray:
    """The cue a first TinyMemory observation shows (vector form)."""
    return np.argmax(observation[:, :2], axis=1)


# ------------------------------------------------------------------------------------------------------- seeding
def test_slots_reset_with_their_seeds_reproduce_a_single_env_and_each_other() -> None:
    core = _core(4)
    seeds = [11, 12, 13, 14]
    core.reset_slots(range(4), seeds)
    first = core.observations()["vector_observation"]
    single = TinyMemoryEnv()
    expected = np.stack([single.reset(seed=seed)[0] for seed in seeds])
    np.testing.assert_array_equal(first, expected)
    assert len(set(_cue(np.stack([single.reset(seed=s)[0] for s in range(40)])).tolist())) == 2  # seeds matter
    core.step(np.zeros(4, dtype=np.int64))
    core.reset_slots([2], [11])  # slot 2 alone, with slot 0's seed: slot 0's first observation, the others go on
    now = core.observations()["vector_observation"]
    np.testing.assert_array_equal(now[2], first[0])
    np.testing.assert_array_equal(now[[0, 1, 3]], np.tile([0, 0, 1], (3, 1)))


def test_async_copies_give_what_sync_copies_give() -> None:
    sync, parallel = _core(3), envs.make_core(ENV_ID, 3, vectorization="async")
    try:
        for core in (sync, parallel):
            core.reset_slots(range(3), [5, 6, 7])
        np.testing.assert_array_equal(
            sync.observations()["vector_observation"], parallel.observations()["vector_observation"]
        )
    finally:
        parallel.close()


def test_an_environment_that_ignores_seeds_is_refused_or_reported() -> None:
    with pytest.raises(SeedingError, match=r"ignores the seed of reset: slot 0 was reset with seed=3.*check_seeding"):
        _core(2, ignore_seed=True).reset_slots([0, 1], [3, 4])
    lenient = envs.make_core(ENV_ID, 2, make_kwargs={"ignore_seed": True}, check_seeding=False)
    with pytest.warns(UserWarning, match="unreproducible episodes"):
        lenient.reset_slots([0, 1], [3, 4])


def test_episode_ends_give_final_infos_and_finished_slots_need_a_reset() -> None:
    core = _core(2)
    core.reset_slots([0, 1], [1, 2])
    cues = _cue(core.observations()["vector_observation"])
    for _ in range(2):
        rewards, ended, finals = core.step(np.zeros(2, dtype=np.int64))
        assert not ended.any() and not finals
    rewards, ended, finals = core.step(cues)  # action k is Discrete(2, start=1)'s k + 1: the env's offset is added
    assert ended.all() and rewards.tolist() == [1.0, 1.0]
    assert finals[0] == {"reward": 1.0, "length": 3, "truncated": 0, "success": 1, "cue": int(cues[0])}
    with pytest.raises(gym.error.ResetNeeded, match="slot 0"):
        core.step(np.zeros(1, dtype=np.int64), idx=np.array([0]))
    core.reset_slots([0], [1])
    core.step(np.zeros(1, dtype=np.int64), idx=np.array([0]))  # slot 1 waits: it has no episode in progress
    core.reset_slots([1], [2])
    with pytest.raises(RuntimeError, match="slot 1 .* is in an episode but not stepped"):
        core.step(np.zeros(1, dtype=np.int64), idx=np.array([0]))


def test_time_limits_end_episodes_as_truncated() -> None:
    core = _core(1, delay=50)  # registered with max_episode_steps=20
    assert core.max_episode_steps.tolist() == [20]
    core.reset_slots([0], [0])
    ends = [core.step(np.zeros(1, dtype=np.int64)) for _ in range(20)]
    assert [bool(ended[0]) for _, ended, _ in ends] == [False] * 19 + [True]
    assert ends[-1][2][0]["truncated"] == 1 and ends[-1][2][0]["length"] == 20


def test_wrappers_apply_in_order_with_their_arguments() -> None:
    wrappers = [  # the first is innermost: the statistics see the episodes the time limit cuts
        {"path": "gymnasium.wrappers:TimeLimit", "kwargs": {"max_episode_steps": 4}},
        "gymnasium.wrappers:RecordEpisodeStatistics",
    ]
    core = envs.make_core(ENV_ID, 1, make_kwargs={"delay": 50}, wrappers=wrappers)
    core.reset_slots([0], [0])
    ends = [core.step(np.zeros(1, dtype=np.int64)) for _ in range(4)]
    assert [bool(ended[0]) for _, ended, _ in ends] == [False] * 3 + [True]
    final = ends[-1][2][0]
    assert final["truncated"] == 1 and final["length"] == 4
    assert final["episode.l"] == 4 and final["episode.r"] == 0.0  # RecordEpisodeStatistics' nested info
    own = envs.make_core("ProofOfMemory-v0", 2, wrappers=wrappers)  # one of this project's ids, wrapped
    assert (
        isinstance(own, GymnasiumCore)
        and own.single_observation_space == envs.make_core("ProofOfMemory-v0").single_observation_space
    )
    with pytest.raises(ValueError, match="wrapper 'gymnasium.wrappers:Nope' cannot be imported"):
        envs.make_core(ENV_ID, 1, wrappers=["gymnasium.wrappers:Nope"])
    with pytest.raises(ValueError, match="wrapper 7 is invalid: expected an import path"):
        envs.make_core(ENV_ID, 1, wrappers=[7])


# -------------------------------------------------------------------------------------------------------- spaces
def test_observation_spaces_become_image_and_vector_inputs() -> None:
    discrete = _core(2, observation="discrete")
    assert discrete.single_observation_space["vector_observation"].shape == (3,)
    discrete.reset_slots([0, 1], [11, 12])
    vector = _core(2)
    vector.reset_slots([0, 1], [11, 12])
    np.testing.assert_array_equal(  # the one-hot code of the Discrete(3) observation is the vector env's vector
        discrete.observations()["vector_observation"], vector.observations()["vector_observation"]
    )

    hwc, chw = (
        _core(2, observation="image"),
        envs.make_core(ENV_ID, 2, make_kwargs={"observation": "image_chw"}, image_layout="chw"),
    )
    assert hwc.single_observation_space == chw.single_observation_space == gym.spaces.Box(0, 255, (36, 36, 3), np.uint8)
    for core in (hwc, chw):
        core.reset_slots([0, 1], [11, 12])
    np.testing.assert_array_equal(hwc.observations(), chw.observations())
    np.testing.assert_array_equal(hwc.agent_frame(1), hwc.observations()[1])

    mixed = _core(2, observation="dict")  # an image, a Box and a Discrete part
    space = mixed.single_observation_space
    assert space["visual_observation"].shape == (36, 36, 3) and space["vector_observation"].shape == (3 + 4,)
    mixed.reset_slots([0, 1], [11, 12])
    observation = mixed.observations()
    np.testing.assert_array_equal(observation["visual_observation"], hwc.observations())
    np.testing.assert_array_equal(observation["vector_observation"][:, :3], vector.observations()["vector_observation"])
    np.testing.assert_array_equal(observation["vector_observation"][:, 3:], np.tile([1, 0, 0, 0], (2, 1)))


def test_unsupported_spaces_are_named() -> None:
    with pytest.raises(UnsupportedSpaceError, match=r"unsupported observation space Text\("):
        _core(1, observation="text")
    with pytest.raises(UnsupportedSpaceError, match=r"unsupported action space Box\(.*continuous actions"):
        _core(1, action="box")
    with pytest.raises(ConfigError, match=r"env: .*unsupported action space Box\(-1.0, 1.0, \(1,\), float32\)"):
        _config("env.make_kwargs.action=box")
    with pytest.raises(ConfigError, match=r"env.id='nope:Nope-v0' is unknown.*No module named 'nope'"):
        _config("env.id=nope:Nope-v0")
    with pytest.raises(ValueError, match="model.encoder=nature_cnn needs an image observation.*model.encoder: mlp"):
        Trainer(_config("model.encoder=nature_cnn"), "unused")


def test_configs_name_gymnasium_tasks_and_metrics() -> None:
    assert task_name(ENV_ID) == "TinyMemory-v0"
    assert task_name("ALE/Pong-v5", {"mode": 2}) == "ALE_Pong-v5+mode=2"
    assert metric_of(ENV_ID).name == "return"  # an id the table does not know is scored by its return
    config = _config(*SUCCESS)
    metric = metric_of(config.env.id, config.env.metric)
    assert (metric.name, metric.label, metric.low, metric.high) == ("success", "Success Rate", 0.0, 1.0)
    assert metric.value({"success": 1}) == 1.0
    with pytest.raises(ValueError, match="env.metric.key='success' is not in the final info of .*: cue, reward"):
        metric.value({"reward": 0.0, "cue": 1})
    with pytest.raises(ConfigError, match="env.vectorization='threads' is invalid; valid choices: sync, async"):
        _config("env.vectorization=threads")


# ---------------------------------------------------------------------------------------- training, evaluation
def _novel_seed_success(trainer: Trainer) -> list[dict]:
    config = trainer.config
    return evaluate(trainer.model, None, config, seed_list(config.eval_seeds), config.eval.repetitions, sampling_seed=7)


@pytest.mark.slow
def test_gru_ppo_learns_the_tiny_env_and_is_evaluated_on_novel_seeds(tmp_path: Path) -> None:
    """Trained end to end (4k steps, ~3 s): GRU-PPO solves the cue task on novel seeds, which memory-less PPO cannot
    (chance: 0.5); the records carry the configured metric and the evaluation reproduces."""
    trainer = Trainer(_config(*SUCCESS, "run.total_steps=8192", "eval.interval=8"), tmp_path / "gru")
    history = trainer.train()
    assert history[-1]["eval/metric"] == 1.0
    records = _novel_seed_success(trainer)
    assert {r["seed"] for r in records} == set(range(100000, 100020)) and len(records) == 40
    assert all(r["metric"] == r["success"] == r["return"] for r in records)
    assert np.mean([r["metric"] for r in records]) >= 0.9  # actions sampled, as the paper evaluates
    assert records == _novel_seed_success(trainer)
    memoryless = Trainer(_config(*SUCCESS, "run.total_steps=8192", "model.memory=none"), tmp_path / "ppo")
    memoryless.train()
    assert 0.3 < np.mean([r["metric"] for r in _novel_seed_success(memoryless)]) < 0.7


def test_plots_label_and_scale_the_configured_metric(tmp_path: Path) -> None:
    """The records carry env.metric's label and range (metric_spec), which the figures use; a gymnasium id without
    env.metric is labelled by its return."""
    for overrides, label, scaled in ((SUCCESS, "Success Rate", True), ((), "Return", False)):
        trainer = Trainer(_config(*overrides, "run.total_steps=512"), tmp_path / "run")
        records = evaluate(trainer.model, None, trainer.config, [100000, 100001], 2, run="seed1")
        write_records(tmp_path / label / "episodes.csv", records)
        episodes = read_episodes(tmp_path / label)
        axes = final_figure(episodes, reps=50).axes[0]
        assert axes.get_xlabel() == label
        low, high = axes.get_xlim()
        assert (low < 0.0 and high > 1.0) == scaled  # the whole range [0, 1], padded; else fitted to the intervals
        assert curves_figure(episodes, reps=50).axes[0].get_ylabel() == label


@pytest.mark.parametrize(
    "overrides",
    [
        ("model.memory=none", "model.frame_stack=4"),  # frame stacking of vector observations
        ("model.memory=lstm", "model.previous_action=true", "model.previous_reward=true", "ppo.sequence_length=4"),
        ("env.make_kwargs.observation=dict", "model.encoder=nature_cnn", "model.frame_stack=2", "model.grayscale=true"),
        ("env.make_kwargs.observation=image_chw", "env.image_layout=chw", "model.encoder=nature_cnn"),
        ("env.make_kwargs.action=multi_discrete", "env.vectorization=async", "run.workers=2", "run.worker_steps=8"),
        ("env.frame_skip=2", "model.memory=gru"),
        ("env.make_kwargs.observation=image", "model.encoder=nature_cnn", "model.memory=none", *HELM),
    ],
)
@pytest.mark.slow
def test_the_baselines_train_on_every_kind_of_space(tmp_path: Path, overrides: tuple[str, ...]) -> None:
    config = _config("run.total_steps=256", "run.worker_steps=16", "eval.interval=1", *overrides)
    trainer = Trainer(config, tmp_path / "run")
    history = trainer.train()
    assert len(history) == config.num_updates and all(np.isfinite(m["losses/value_loss"]) for m in history)
    assert "eval/return" in history[-1] and history[-1]["charts/episodes"] > 0
    for core in (trainer.core, trainer._eval_core):  # the async copies' subprocesses end here, not at exit
        core.close()


@pytest.mark.parametrize("memory", sorted(MEMORY_MODULES))
def test_every_memory_trains_on_a_gymnasium_environment(tmp_path: Path, memory: str) -> None:
    small = ("model.trxl.layers=1", "model.trxl.dim=16", "model.trxl.heads=2", "model.trxl.memory_length=4")
    length = "ppo.sequence_length=max" if memory == "none" else "ppo.sequence_length=4"
    config = _config("run.total_steps=512", "run.worker_steps=16", f"model.memory={memory}", length, *small)
    history = Trainer(config, tmp_path / "run").train()
    assert len(history) == 2 and all(np.isfinite(m["losses/policy_loss"]) for m in history)


@pytest.mark.slow
def test_resume_starts_new_episodes_and_is_deterministic(tmp_path: Path) -> None:
    """A gymnasium environment's state is not in the checkpoint: a resumed run starts every slot on its next seed.
    Two resumes of the same checkpoint end with the same weights and logs."""
    config = _config("run.total_steps=3072", "run.checkpoint_interval=2", "eval.interval=3")
    killed = Trainer(config, tmp_path / "a")
    kill_after(killed, 3)
    with pytest.raises(KeyboardInterrupt):
        killed.train()
    shutil.copytree(tmp_path / "a", tmp_path / "b")
    resumed = [Trainer.resume(tmp_path / name) for name in ("a", "b")]
    assert [trainer.update for trainer in resumed] == [2, 2]
    assert all(trainer.actor.memory.episode_step.eq(0).all() for trainer in resumed)  # new episodes everywhere
    for trainer in resumed:
        trainer.train()
    for x, y in zip(resumed[0].model.parameters(), resumed[1].model.parameters(), strict=True):
        assert torch.equal(x, y)
    for name in ("training.csv", "eval/episodes.csv"):
        rows = [[row.split(",", 1)[1] for row in (tmp_path / run / name).read_text().splitlines()] for run in "ab"]
        assert rows[0] == rows[1], name  # all but the run column (the directory's name)


# --------------------------------------------------------------------------------------------------------- POPGym
def test_popgym_trains_a_few_updates(tmp_path: Path) -> None:
    pytest.importorskip("popgym", reason="POPGym is an optional extra: pip install -e '.[popgym]'")
    config = _config(
        "env.id=popgym:popgym-RepeatPreviousEasy-v0", "env.make_kwargs={}", "run.total_steps=1024", "eval.interval=2"
    )
    assert config.task == "popgym-RepeatPreviousEasy-v0"
    history = Trainer(config, tmp_path / "run").train()
    assert len(history) == 2 and history[-1]["charts/episodic_length"] == 51.0
    assert -1.0 <= history[-1]["eval/metric"] <= 1.0
