"""Reset options of ``SearingSpotlights-v0`` and ``Endless-SearingSpotlights-v0`` (names and defaults of memory-gym
1.0.2, with valid ranges)."""

from __future__ import annotations

from envs.options import Option

# spot_damage <= 1e9 and the spawn intervals <= 1e6: the reference has no bounds; larger values overflowed the int
# arithmetic of the health bar and the spawn schedule (far beyond any meaningful setting).


def _common_options(endless: bool) -> dict[str, Option]:
    return {
        "max_steps": Option(-1 if endless else 256, "int", -1, None, doc="episode length cap; <= 0: no cap"),
        "initial_spawns": Option(3 if endless else 4, "int", 0, 256, doc="spotlights created at reset"),
        "spot_min_radius": Option(7.5, "float", 1, 42, doc="radius = integers(min, max + 1): an int in 7..13"),
        "spot_max_radius": Option(13.75, "float", 1, 42),
        "spot_min_speed": Option(0.0025, "float", 0, 1, doc="curve parameter advance per step"),
        "spot_max_speed": Option(0.0075, "float", 0, 1),
        "spot_damage": Option(1.0, "float", 0, 1e9, doc="health lost per step while a spotlight touches the agent"),
        "visual_feedback": Option(True, "bool", doc="red chessboard on the steps the agent is hit"),
        "black_background": Option(False, "bool", doc="black floor; spotlights get a white 1-px ring"),
        "hide_chessboard": Option(False, "bool", doc="white floor"),
        "light_dim_off_duration": Option(6, "int", 0, None, doc="steps until full darkness; 0: dark at once"),
        "light_threshold": Option(255, "int", 0, 255, doc="darkness alpha stops at the first step above this"),
        "coin_scale": Option(0.375, "float", 0.1, 4.0, doc="coin radius int(10 * scale)"),
        "coins_visible": Option(False, "bool", doc="draw coins above the darkness"),
        "agent_speed": Option(3.0, "float", 0, 84),
        "agent_health": Option(10 if endless else 5, "int", 1, None),
        "agent_scale": Option(0.25, "float", 0.05, 1.0, doc="agent radius int(25 * scale)"),
        "agent_visible": Option(False, "bool", doc="draw the agent above the darkness"),
        "sample_agent_position": Option(True, "bool", doc="False: the agent starts at the centre (42, 42)"),
        "show_last_action": Option(True, "bool", doc="HUD blocks with the previous action"),
        "show_last_positive_reward": Option(True, "bool", doc="HUD block: was the previous reward positive"),
        "reward_inside_spotlight": Option(0.0, "float", doc="per step while hit"),
        "reward_outside_spotlight": Option(0.0, "float", doc="per step while not hit"),
        "reward_death": Option(0.0, "float", doc="when health reaches 0"),
        "reward_coin": Option(0.25, "float", doc="per coin"),
    }


SS_OPTIONS: dict[str, Option] = {
    **_common_options(endless=False),
    "num_spawns": Option(30, "int", 0, 100000, doc="spotlights spawned after reset, at most"),
    "initial_spawn_interval": Option(30, "float", 0, 1e6, doc="spawn interval = int(this + threshold) = 40"),
    "spawn_interval_threshold": Option(10, "float", 0, 1e6),
    "spawn_interval_decay": Option(0.95, "float", 0, 1, doc="accepted; never applied (as in memory-gym)"),
    "num_coins": Option([1], "int_list", 0, 10, allow_empty=True, doc="coin count, drawn from the list"),
    "use_exit": Option(True, "bool", doc="after the coins, the exit must be reached"),
    "exit_scale": Option(0.5, "float", 0.1, 4.0, doc="exit size 20 * scale"),
    "exit_visible": Option(False, "bool", doc="draw the exit above the darkness"),
    "reward_exit": Option(1.0, "float"),
    "reward_max_steps": Option(0.0, "float", doc="accepted; unused (as in memory-gym)"),
}
ESS_OPTIONS: dict[str, Option] = {
    **_common_options(endless=True),
    "steps_per_coin": Option(160, "int", -1, None, doc="steps allowed per coin; <= 0: no limit"),
    "spawn_interval": Option(50, "int", 1, None, doc="a spotlight spawns every this many steps"),
    "coin_show_duration": Option(6, "int", 0, None, doc="a new coin is drawn above the darkness this long"),
}
