"""``mor.sim.step_profile``: every part of a rendered step is timed, and the parts add up to the whole."""

from __future__ import annotations

from mor.sim.step_profile import PARTS, step_profile


def test_step_profile_times_every_part() -> None:
    profile = step_profile("MOR/Pick-v0", 30, 0, {"image_size": 16})
    for clock in ("cpu_us", "wall_us"):
        times = profile[clock]
        assert set(times) == {*PARTS, "whole_rendered_step", "other"}
        assert all(value >= 0.0 for value in times.values())
        assert sum(times[p] for p in PARTS) + times["other"] >= times["whole_rendered_step"] - 0.5  # rounding
        assert times["step_without_render"] > 0.0
    # rendering adds CPU work; on the wall clock a loaded machine may stall either loop longer, so order CPU time only
    assert profile["cpu_us"]["whole_rendered_step"] > profile["cpu_us"]["step_without_render"]
    assert 0.0 < profile["render_share_cpu"] < 1.0
