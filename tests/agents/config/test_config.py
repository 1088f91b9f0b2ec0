"""Config loading: strict keys with suggestions, typed and ranged values, overrides, schedules, shipped configs."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from agents.config import (
    Config,
    ConfigError,
    Schedule,
    config_from_dict,
    config_to_dict,
    dump_config,
    expand_grid,
    load_config,
    read_config_file,
)

CONFIG_ROOT = Path(__file__).resolve().parents[3] / "configs"
CONFIGS = sorted(CONFIG_ROOT.rglob("*.yaml"))


def test_defaults_are_table_6() -> None:
    ppo, run, model = Config().ppo, Config().run, Config().model
    assert (run.workers, run.worker_steps, run.total_steps) == (32, 512, 163_840_000)
    assert (ppo.epochs, ppo.minibatches, ppo.gamma, ppo.gae_lambda) == (3, 8, 0.99, 0.95)
    assert (ppo.value_coef, ppo.max_grad_norm, ppo.clip_range.value(5, 10)) == (0.25, 0.5, 0.2)
    assert (ppo.learning_rate.initial, ppo.learning_rate.final) == (3e-4, 1e-4)
    assert (ppo.entropy_coef.initial, ppo.entropy_coef.final) == (1e-4, 1e-5)
    assert ppo.sequence_length == "max" and model.memory == "gru" and model.memory_size == 512
    assert Config().env.train_seeds == [0, 99_999]


@pytest.mark.parametrize(
    ("raw", "message"),
    [
        ({"ppo": {"gama": 0.9}}, "unknown config key 'ppo.gama' (did you mean 'ppo.gamma'?)"),
        ({"modle": {}}, "unknown config key 'modle' (did you mean 'model'?)"),
        ({"ppo": {"learning_rate": {"inital": 1}}}, "did you mean 'ppo.learning_rate.initial'?"),
        ({"env": {"options": {"dely": 3}}}, "did you mean 'delay'?"),
        ({"env": {"id": "ProofOfMemory-v1"}}, "did you mean 'ProofOfMemory-v0'?"),
        (
            {"model": {"memory": "gur"}},
            "model.memory='gur' is invalid (did you mean 'gru'?); valid choices: none, gru, lstm",
        ),
    ],
)
def test_unknown_names_suggest_the_closest_valid_one(raw: dict, message: str) -> None:
    with pytest.raises(ConfigError) as err:
        config_from_dict(raw)
    assert message in str(err.value)


@pytest.mark.parametrize(
    ("raw", "message"),
    [
        ({"ppo": {"gamma": 1.5}}, "ppo.gamma=1.5 is invalid: expected a number in [0, 1]"),
        ({"ppo": {"gamma": float("nan")}}, "ppo.gamma=nan is invalid"),
        ({"ppo": {"epochs": 0}}, "ppo.epochs=0 is invalid: expected an int in [1, inf]"),
        ({"ppo": {"epochs": 2.5}}, "ppo.epochs=2.5 is invalid: expected an int"),
        ({"ppo": {"epochs": True}}, "ppo.epochs=True is invalid"),
        ({"ppo": {"clip_value_loss": "yes"}}, "expected true or false"),
        ({"ppo": {"sequence_length": 0}}, "ppo.sequence_length=0 is invalid: expected an int >= 1 or 'max'"),
        ({"ppo": {"sequence_length": "longest"}}, "expected an int >= 1 or 'max'"),
        ({"ppo": {"advantage_normalization": "batches"}}, "did you mean 'batch'?"),
        ({"ppo": {"learning_rate": -1.0}}, "ppo.learning_rate.initial=-1.0 is invalid: expected a number in [0, inf]"),
        ({"run": {"device": "gpu"}}, "run.device='gpu' is invalid; valid choices: 'cpu', 'cuda', 'cuda:N'"),
        ({"run": {"precision": "fp16"}}, "valid choices: fp32, bf16"),
        ({"run": {"workers": 4, "worker_steps": 8, "total_steps": 16}}, "run.total_steps=16 is smaller than one batch"),
        ({"env": {"options": {"delay": 0}}}, "option 'delay'=0 is invalid"),
        ({"env": {"train_seeds": [5, 1]}}, "env.train_seeds=[5, 1] is invalid"),
        ({"model": {"memory": "none"}, "ppo": {"sequence_length": 8}}, "needs a memory module"),
        ({"grid": {"ppo.gamma": [0.9, 2.0]}}, "ppo.gamma=2.0 is invalid"),
        ({"grid": {"ppo.gamma": 0.9}}, "grid.ppo.gamma=0.9 is invalid: expected a non-empty list"),
        ({"grid": {"ppo.gamam": [0.9]}}, "did you mean 'ppo.gamma'?"),
        ({"ppo": 3}, "ppo must be a mapping"),
    ],
)
def test_bad_values_name_the_key_and_the_valid_range(raw: dict, message: str) -> None:
    with pytest.raises(ConfigError) as err:
        config_from_dict(raw)
    assert message in str(err.value)


def test_overrides_are_parsed_as_yaml_and_validated() -> None:
    config = config_from_dict(
        {"ppo": {"learning_rate": 1.0e-3}},
        [
            "ppo.gamma=0.995",
            "ppo.sequence_length=16",
            "model.memory=lstm",
            "env.options.delay=8",
            "env.train_seeds=[10, 20]",
            "ppo.learning_rate.final=1e-5",  # YAML 1.1 reads 1e-5 as a string; float fields accept it
            "run.progress_bar=false",
        ],
    )
    assert config.ppo.gamma == 0.995 and config.ppo.sequence_length == 16 and config.model.memory == "lstm"
    assert config.env.options == {"delay": 8} and config.env.train_seeds == [10, 20]
    assert config.ppo.learning_rate == Schedule(1.0e-3, 1e-5, None)  # the constant became the initial value
    assert config.run.progress_bar is False
    for bad, message in [
        ("ppo.gamm=1", "did you mean 'ppo.gamma'?"),
        ("ppo.gamma.x=1", "'ppo.gamma' is a float, it has no sub-keys"),
        ("gamma", "expected KEY=VALUE"),
        ("ppo.epochs=three", "ppo.epochs='three' is invalid"),
    ]:
        with pytest.raises(ConfigError, match=message.replace("(", r"\(").replace("?", r"\?")):
            config_from_dict({}, [bad])


@pytest.mark.parametrize("spelling", ["1e-3", "1.0e-3", "0.001", "1E-3"])
def test_schedules_and_floats_accept_every_usual_spelling(spelling: str) -> None:
    """A plain number is a constant schedule however it is spelt: YAML 1.1 reads ``1e-3`` (no dot) as a string."""
    from_overrides = config_from_dict(
        {}, [f"ppo.learning_rate={spelling}", f"ppo.entropy_coef={spelling}", f"ppo.value_coef={spelling}"]
    )
    from_yaml = load_config_text(
        f"ppo: {{learning_rate: {spelling}, entropy_coef: {spelling}, value_coef: {spelling}}}"
    )
    for config in (from_overrides, from_yaml):
        assert config.ppo.learning_rate == Schedule(1e-3) and config.ppo.entropy_coef == Schedule(1e-3)
        assert config.ppo.value_coef == 1e-3
    # a constant spelt as a string, then given a final value, decays from it
    decaying = config_from_dict({"ppo": {"learning_rate": "1e-3"}}, ["ppo.learning_rate.final=1e-4"])
    assert decaying.ppo.learning_rate == Schedule(1e-3, 1e-4)
    with pytest.raises(ConfigError, match=r"ppo.learning_rate='fast' is invalid: expected a number .* or a mapping"):
        config_from_dict({}, ["ppo.learning_rate=fast"])


@pytest.mark.parametrize("where", ["yaml", "override"])
def test_a_schedule_that_is_neither_a_number_nor_a_mapping_says_so(where: str) -> None:
    """``clip_range: 0.2x`` is a typo of a number: the message names both forms a schedule takes, not only one."""
    with pytest.raises(ConfigError) as err:
        if where == "yaml":
            load_config_text("ppo: {clip_range: 0.2x}")
        else:
            config_from_dict({}, ["ppo.clip_range=0.2x"])
    message = str(err.value)
    assert "ppo.clip_range='0.2x' is invalid: expected a number (a constant) or a mapping" in message
    assert "must be a mapping" not in message


@pytest.mark.parametrize("spelling", ["1e5", "1.0e5", "1E5", "100000.0", "100000", "1.0e+5"])
def test_integer_fields_accept_whole_numbers_in_scientific_notation(spelling: str) -> None:
    """YAML 1.1 reads ``1e5`` and ``1.0e5`` as strings and ``1.0e+5`` as a float: an int field takes them all when
    the value is whole, in a file, in an override and inside a list."""
    from_yaml = load_config_text(f"run: {{total_steps: {spelling}}}\nenv: {{train_seeds: [0, {spelling}]}}")
    from_override = config_from_dict({}, [f"run.total_steps={spelling}", f"env.train_seeds=[0, {spelling}]"])
    for config in (from_yaml, from_override):
        assert config.run.total_steps == 100_000 and type(config.run.total_steps) is int
        assert config.env.train_seeds == [0, 100_000] and type(config.env.train_seeds[1]) is int


@pytest.mark.parametrize("spelling", ["1.5e0", "2.5", "1e-3", "nan", "inf"])
def test_integer_fields_refuse_fractions_naming_the_key(spelling: str) -> None:
    for make in (
        lambda: load_config_text(f"ppo: {{epochs: {spelling}}}"),
        lambda: config_from_dict({}, [f"ppo.epochs={spelling}"]),
    ):
        with pytest.raises(ConfigError, match=r"ppo\.epochs=.* is invalid: expected an int in \[1, inf\]"):
            make()


def test_fields_that_also_take_strings_keep_numeric_looking_strings() -> None:
    """Only plain int fields parse a string as a number: a quoted SLURM time of '90' minutes stays a string, and
    ``sequence_length`` still takes an int, a whole float, or 'max'."""
    from agents.config import grid_slurm

    assert grid_slurm({"slurm": {"time": "90"}}).time == "90"
    assert config_from_dict({"ppo": {"sequence_length": 16.0}}).ppo.sequence_length == 16
    assert config_from_dict({}, ["ppo.sequence_length=max"]).ppo.sequence_length == "max"


def test_rounding_to_whole_updates_is_announced() -> None:
    from agents.config import rounding_notice

    config = config_from_dict({}, ["run.total_steps=3000", "run.workers=4", "run.worker_steps=256"])
    assert config.num_updates == 2
    assert rounding_notice(config) == (
        "run.total_steps=3000 is not a whole number of updates of 1024 steps (run.workers x run.worker_steps = "
        "4 x 256): training 2 updates, 2048 steps"
    )
    assert (
        rounding_notice(config_from_dict({}, ["run.total_steps=3072", "run.workers=4", "run.worker_steps=256"])) is None
    )


def test_a_yaml_syntax_error_names_the_file_line_and_column(tmp_path: Path) -> None:
    path = tmp_path / "broken.yaml"
    path.write_text("run:\n  seed: 1\nppo: {gamma: 0.99\n")
    with pytest.raises(ConfigError) as err:
        load_config(path)
    message = str(err.value)
    assert message.startswith(f"{path}: line 4, column 1: invalid YAML: expected ',' or '}}'"), message
    path.write_text("run:\n  seed: 1\n   workers: 2\n")
    with pytest.raises(ConfigError, match=r"broken\.yaml: line 3, column 11: invalid YAML: mapping values"):
        read_config_file(path)


def load_config_text(text: str):
    return config_from_dict(yaml.safe_load(text))


def test_new_blocks_validate_and_name_the_method() -> None:
    assert Config().method == "gru" and config_from_dict({"model": {"memory": "none"}}).method == "ppo"
    assert config_from_dict({"model": {"memory": "none", "frame_stack": 4}}).method == "stack4"
    assert config_from_dict({"model": {"memory": "none", "helm": {"lm": "random"}}}).method == "helm"
    assert config_from_dict({"run": {"method": "mine", "task": "mmact"}}).method == "mine"
    assert Config().task == "ProofOfMemory-v0"
    assert Config().eval_seeds == [100_000, 100_029]  # the paper's 30 novel seeds after the 100,000 training seeds
    assert config_from_dict({"env": {"train_seeds": [0, 9]}}).eval_seeds == [10, 39]
    for raw, message in [
        (
            {"eval": {"seeds": [5, 7]}},
            "evaluation seeds [5, 7] overlap the training seeds (env.train_seeds) [0, 99999]",
        ),
        ({"eval": {"seeds": [7]}}, "eval.seeds=[7] is invalid: expected [low, high]"),
        ({"model": {"frame_stack": 0}}, "model.frame_stack=0 is invalid"),
        ({"model": {"encoder": "impala"}}, "model.encoder='impala' is invalid; valid choices: nature_cnn"),
        ({"model": {"helm": {"random_width": 30, "random_heads": 4}}}, "expected a multiple of"),
        ({"env": {"frame_skip": 0}}, "env.frame_skip=0 is invalid"),
    ]:
        with pytest.raises(ConfigError) as err:
            config_from_dict(raw)
        assert message in str(err.value)


def test_partial_blocks_keep_the_field_defaults() -> None:
    config = config_from_dict({"ppo": {"learning_rate": {"final": 0.0}}, "run": {"seed": 3}})
    assert config.ppo.learning_rate == Schedule(3e-4, 0.0, None)
    assert config.run.seed == 3 and config.run.workers == 32


def test_linear_schedule() -> None:
    schedule = Schedule(1.0, 0.0)
    assert [schedule.value(u, 4) for u in range(4)] == [1.0, 0.75, 0.5, 0.25]
    assert Schedule(1.0, 0.5, decay_updates=2).value(5, 10) == 0.5  # holds the final value after the decay
    assert Schedule(0.3).value(7, 10) == 0.3


def test_an_extended_schedule_goes_on_from_where_it_was() -> None:
    """Lengthening a run (``extensions``: at update, previous length) makes a whole-run decay go on linearly from
    its current value to ``final`` at the new end: no jump, a finished run's value stays final; ``decay_updates`` and
    constants do not move; without extensions the values are the plain linear ones, bit for bit."""
    schedule = Schedule(1.0, 0.0)
    assert [schedule.value(u, 6, [(2, 4)]) for u in range(6)] == [1.0, 0.75, 0.5, 0.375, 0.25, 0.125]
    twice = [schedule.value(u, 8, [(2, 4), (4, 6)]) for u in range(8)]
    assert twice == [1.0, 0.75, 0.5, 0.375, 0.25, 0.1875, 0.125, 0.0625]
    assert [schedule.value(u, 8, [(4, 4)]) for u in range(3, 8)] == [0.25, 0.0, 0.0, 0.0, 0.0]  # finished at 4
    assert [schedule.value(u, 8, [(2, 4), (2, 6)]) for u in range(2, 4)] == [0.5, 0.5 - 0.5 / 6]  # extended twice at 2
    assert Schedule(1.0, 0.5, decay_updates=4).value(3, 10, [(2, 3)]) == Schedule(1.0, 0.5, 4).value(3, 10)
    assert Schedule(0.3).value(7, 10, [(5, 6)]) == 0.3
    lr = Schedule(3e-4, 1e-4)
    assert all(lr.value(u, 977) == 3e-4 + (1e-4 - 3e-4) * min(u / 977, 1.0) for u in range(980))


def test_dump_and_reload_round_trip(tmp_path: Path) -> None:
    config = config_from_dict({}, ["ppo.sequence_length=8", "env.options.delay=6", "ppo.entropy_coef=0.01"])
    path = tmp_path / "config.yaml"
    path.write_text(dump_config(config))
    assert load_config(path) == config
    assert config_to_dict(load_config(path)) == yaml.safe_load(path.read_text())


def test_missing_file_and_non_mapping(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="does not exist"):
        load_config(tmp_path / "nope.yaml")
    (tmp_path / "list.yaml").write_text("- 1\n- 2\n")
    with pytest.raises(ConfigError, match="expected a mapping"):
        load_config(tmp_path / "list.yaml")


@pytest.mark.parametrize("path", CONFIGS, ids=[str(p.relative_to(CONFIG_ROOT)) for p in CONFIGS])
def test_shipped_configs_load(path: Path) -> None:
    config = load_config(path)
    assert config.num_updates >= 1


def test_mortar_mayhem_b_grid_configs_are_table_6() -> None:
    root = Path(__file__).resolve().parents[3] / "configs" / "mortar_mayhem_b_grid"
    for name, memory in (("gru", "gru"), ("ppo", "none")):
        raw = yaml.safe_load((root / f"{name}.yaml").read_text())
        assert raw["env"]["id"] == "MortarMayhemB-Grid-v0"
        config = config_from_dict({**raw, "env": {}})  # validated without needing the env to be registered
        assert config.model.memory == memory
        assert (config.run.workers, config.run.worker_steps, config.run.total_steps) == (32, 512, 163_840_000)
        assert (config.ppo.epochs, config.ppo.minibatches, config.ppo.gamma, config.ppo.gae_lambda) == (
            3,
            8,
            0.99,
            0.95,
        )
        assert (config.ppo.value_coef, config.ppo.max_grad_norm, config.ppo.clip_range) == (0.25, 0.5, Schedule(0.2))
        assert config.ppo.learning_rate == Schedule(3e-4, 1e-4) and config.ppo.entropy_coef == Schedule(1e-4, 1e-5)
        assert config.model.previous_action and config.model.previous_reward
        assert config.model.hidden_size == 512
        if memory == "gru":
            assert config.model.memory_size == 512 and config.ppo.sequence_length == "max"


def test_cpu_ablation_differs_from_its_panel_by_the_clue_delay_only() -> None:
    """configs/cpu/mm_grid_1_delay4.yaml is the panel's 4-Stack with one change; the two files must not drift."""
    root = CONFIG_ROOT / "cpu"
    panel = {p.choice("method"): p.config for p in expand_grid(read_config_file(root / "mm_grid_1.yaml"))}
    ablation = expand_grid(read_config_file(root / "mm_grid_1_delay4.yaml"))
    assert [p.choice("method") for p in ablation] == ["stack4"] * 3
    for point in ablation:
        expected = config_to_dict(panel["stack4"])
        expected["env"]["options"]["command_show_delay"] = [4]
        expected["run"]["seed"] = point.config.run.seed
        expected["run"]["task"] = "mm_grid_1_delay4"  # the task's label, which names its results
        assert config_to_dict(point.config) == expected


def _blocks(cls: type, prefix: str = "") -> dict[str, type]:
    """Every settings block of a dataclass by its dotted key, the dataclass itself included."""
    import dataclasses
    from typing import get_type_hints

    found = {prefix or "(config)": cls}
    for name, hint in get_type_hints(cls).items():
        if isinstance(hint, type) and dataclasses.is_dataclass(hint):
            found.update(_blocks(hint, f"{prefix}.{name}" if prefix else name))
    return found


def test_every_block_of_the_schema_is_a_settings_block_that_checks_itself() -> None:
    """The loader calls each block's own check: there is no list of block types to keep in step with the schema."""
    from agents.settings import Settings

    blocks = _blocks(Config)
    assert {"env", "env.metric", "model", "model.helm", "model.lru", "ppo.learning_rate", "run.wandb"} <= set(blocks)
    assert all(issubclass(block, Settings) for block in blocks.values()), blocks


def test_the_loader_calls_a_blocks_check_with_its_dotted_key() -> None:
    from dataclasses import dataclass

    from agents.config.building import build
    from agents.settings import Settings, param

    seen = []

    @dataclass
    class Probe(Settings):
        size: int = param(1, "a size", low=1)

        def check(self, prefix: str) -> None:
            seen.append((prefix, self.size))
            if self.size == 3:
                raise ConfigError(f"{prefix}.size=3 is refused by the block itself")

    assert build(Probe, {"size": 2}, prefix="model.probe").size == 2
    assert seen == [("model.probe", 2)]
    with pytest.raises(ConfigError, match=r"^model\.probe\.size=3 is refused by the block itself$"):
        build(Probe, {"size": 3}, prefix="model.probe")


def test_a_grid_excludes_the_cells_its_exclude_entries_match() -> None:
    raw = {
        "grid": {
            "method": {"gru": {"model.memory": "gru"}, "recon": {"ppo.reconstruction_coef": 0.1}},
            "task": {"a": {"env.options": {"delay": 2}}, "b": {"env.options": {"delay": 3}}},
            "run.seed": [0, 1],
            "exclude": [{"method": "recon", "task": ["b"]}, {"method": "gru", "run.seed": 1}],
        },
        "env": {"id": "ProofOfMemory-v0"},
    }
    cells = {(p.choice("method"), p.choice("task"), p.choice("run.seed")) for p in expand_grid(raw)}
    assert cells == {("gru", "a", "0"), ("gru", "b", "0"), ("recon", "a", "0"), ("recon", "a", "1")}
    for exclude, message in (
        ([{"methd": "gru"}], "'methd' is not an axis; the axes: method, task, run.seed"),
        ([{"task": ["c"]}], "task has no c; its labels: a, b"),
        ({"method": "gru"}, "expected a list of mappings"),
    ):
        with pytest.raises(ConfigError, match=message):
            expand_grid({**raw, "grid": {**raw["grid"], "exclude": exclude}})
