"""``mor bench sim``'s parallel figure: total steps over wall-clock time."""

from __future__ import annotations

import pytest

from mor.sim.bench import combined_steps_per_second


def test_parallel_rate_is_total_steps_over_wall_clock() -> None:
    # One worker takes 1 s, the other 2 s for 100 steps each: 200 steps in 2 s, not 100/s + 50/s.
    assert combined_steps_per_second(100, [(10.0, 11.0), (10.0, 12.0)]) == pytest.approx(100.0)
    # Staggered starts count from the first start.
    assert combined_steps_per_second(100, [(0.0, 1.0), (1.0, 2.0)]) == pytest.approx(100.0)
    assert combined_steps_per_second(100, [(5.0, 7.0)]) == pytest.approx(50.0)
