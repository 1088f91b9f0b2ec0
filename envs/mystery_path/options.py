"""Reset options of the Mystery Path variants (names and defaults of memory-gym 1.0.2, with valid ranges)."""

from __future__ import annotations

from envs.options import Option


def option_specs(grid: bool, endless: bool) -> dict[str, Option]:
    """The reference's reset parameters of one variant, with their defaults and valid ranges."""
    scale = Option(0.25, "float", 0.05, 1.0, doc="agent size (body radius int(25 * scale))")
    if grid:
        scale = Option(0.25, "float", 0.05, 1.0, doc="accepted but unused: the grid agent always has scale 0.25")
    # <= 1000: the reference has no bound (and fails above 96 in the endless variant); far faster agents overflowed
    # the int64 positions, and Endless MP generates every segment it crosses (1e6 px: 10^4 levels per step)
    speed = Option(3.0, "float", 0.0, 1000.0, doc="pixels per step (cut to an int per axis)")
    if endless:
        return {
            "max_steps": Option(-1, "int", doc="the episode ends when t == max_steps (<= 0: never)"),
            "agent_scale": scale,
            "agent_speed": speed,
            "show_origin": Option(False, "bool", doc="has no effect (as in memory-gym)"),
            "show_past_path": Option(True, "bool", doc="draw the path tiles behind the agent"),
            "show_background": Option(False, "bool", doc="scrolling ice tiles instead of black"),
            "show_stamina": Option(False, "bool", doc="stamina bar at the right edge"),
            "visual_feedback": Option(True, "bool", doc="red cross on the agent when it falls off"),
            "camera_offset_scale": Option(5.0, "float", 0.0, 5.5, doc="tiles visible behind the agent"),
            "stamina_level": Option(20, "int", 1, None, doc="steps allowed without reaching a fresh tile"),
            "reward_fall_off": Option(0.0, "float"),
            "reward_path_progress": Option(0.1, "float", doc="first visit of each path tile"),
            "reward_step": Option(0.0, "float"),
        }
    specs = {
        "max_steps": Option(128 if grid else 512, "int", doc="the episode ends when t == max_steps"),
        "agent_scale": scale,
        "agent_speed": speed,
        "cardinal_origin_choice": Option(
            [0, 1, 2, 3], "int_list", 0, 3, doc="origin side, sampled: 0 left, 1 right, 2 top, 3 bottom"
        ),
        "show_origin": Option(False, "bool", doc="draw the origin tile (blue)"),
        "show_goal": Option(False, "bool", doc="draw the goal tile (green)"),
        "visual_feedback": Option(True, "bool", doc="red cross on the agent while it is off the path"),
        "reward_goal": Option(1.0, "float"),
        "reward_fall_off": Option(0.0, "float"),
        "reward_path_progress": Option(0.0 if grid else 0.1, "float", doc="first visit of each inner path tile"),
        "reward_step": Option(0.0, "float"),
    }
    if grid:
        del specs["agent_speed"]
    return specs
