"""Option validation: unknown keys and bad values fail with messages that name the key and the valid choices."""

from __future__ import annotations

import pytest

from envs.options import Option, resolve_options

SPECS = {
    "arena_size": Option(5, "int", 2, 6),
    "agent_speed": Option(3.0, "float", 0, None),
    "visual_feedback": Option(True, "bool"),
    "command_count": Option([10], "int_list", 1, 20),
    "num_coins": Option([1], "int_list", 0, None, allow_empty=True),
}


def test_defaults_and_merge() -> None:
    opts = resolve_options(SPECS, {"arena_size": 3, "command_count": (5, 6)})
    assert opts == {
        "arena_size": 3,
        "agent_speed": 3.0,
        "visual_feedback": True,
        "command_count": [5, 6],
        "num_coins": [1],
    }
    assert resolve_options(SPECS, {"num_coins": []})["num_coins"] == []


def test_merge_copies_lists_so_episodes_do_not_share_state() -> None:
    base = resolve_options(SPECS, None)
    merged = resolve_options(SPECS, None, base=base)
    merged["command_count"].append(3)
    assert base["command_count"] == [10]


def test_unknown_key_names_closest_and_valid_keys() -> None:
    expected = r"unknown option 'arena_sise'.*did you mean 'arena_size'.*valid options: agent_speed"
    with pytest.raises(ValueError, match=expected):
        resolve_options(SPECS, {"arena_sise": 4}, name="MortarMayhem-v0")


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        ("arena_size", 7, r"'arena_size'=7 is invalid: expected an int in \[2, 6\]"),
        ("arena_size", 4.5, r"expected an int in \[2, 6\]"),
        ("arena_size", True, r"expected an int"),
        ("agent_speed", -1, r"expected a finite number in \[0, inf\]"),
        ("agent_speed", "fast", r"expected a finite number"),
        ("visual_feedback", 1, r"expected a bool"),
        ("command_count", 10, r"expected a non-empty list of ints in \[1, 20\]"),
        ("command_count", [], r"non-empty list"),
        ("command_count", [5, 21], r"'command_count'=\[5, 21\] is invalid"),
    ],
)
def test_bad_values_name_key_and_range(key: str, value: object, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        resolve_options(SPECS, {key: value})


def test_option_kind_is_checked() -> None:
    with pytest.raises(ValueError, match="kind"):
        Option(1, "integer")
