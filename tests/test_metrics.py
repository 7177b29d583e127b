"""The paper's metrics (section 3.3) in mor.sim.metrics: Success, % Fixed Strict, % Energy Remaining."""

from __future__ import annotations

import numpy as np
import pytest

from mor.sim.metrics import (
    SUCCESS_RADIUS,
    energy,
    energy_remaining,
    fixed_strict,
    is_fixed,
    rearrange_success,
    target_distances,
)

TARGETS = np.array([[0.0, 0.0], [2.0, 0.0], [0.0, 3.0]])


def test_success_radius_is_one_metre() -> None:
    assert SUCCESS_RADIUS == 1.0


def test_hand_computed_case() -> None:
    # distances 0.5, 5 (3-4-5), 1.5
    positions = np.array([[0.5, 0.0], [5.0, 4.0], [0.0, 1.5]])
    np.testing.assert_allclose(target_distances(positions, TARGETS), [0.5, 5.0, 1.5])
    np.testing.assert_array_equal(is_fixed(positions, TARGETS), [True, False, False])
    assert fixed_strict(positions, TARGETS) == pytest.approx(1.0 / 3.0)
    assert rearrange_success(positions, TARGETS) == 0.0
    assert energy(positions, TARGETS) == pytest.approx(7.0)
    # initial distances 4, 6, 4 -> energy 14 -> half remains
    initial = np.array([[0.0, -4.0], [-4.0, 0.0], [4.0, 3.0]])
    assert energy_remaining(positions, TARGETS, initial) == pytest.approx(0.5)


def test_all_fixed_is_success() -> None:
    positions = TARGETS + np.array([[0.3, 0.0], [0.0, -0.99], [-0.5, 0.5]])
    assert rearrange_success(positions, TARGETS) == 1.0
    assert fixed_strict(positions, TARGETS) == 1.0
    initial = TARGETS + 3.0
    expected = (0.3 + 0.99 + np.sqrt(0.5)) / (3 * 3.0 * np.sqrt(2.0))
    assert energy_remaining(positions, TARGETS, initial) == pytest.approx(expected)


def test_energy_remaining_can_exceed_one() -> None:
    targets = np.array([[0.0, 0.0]])
    assert energy_remaining([[4.0, 0.0]], targets, [[2.0, 0.0]]) == pytest.approx(2.0)
    assert energy_remaining([[0.0, 0.0]], targets, [[2.0, 0.0]]) == 0.0


@pytest.mark.parametrize(
    ("position", "fixed"),
    [
        ((1.0, 0.0), False),  # exactly 1 m: not fixed (strict inequality)
        ((0.0, -1.0), False),
        ((np.nextafter(1.0, 0.0), 0.0), True),
        ((0.999, 0.0), True),
        ((1.001, 0.0), False),
        ((0.0, 0.0), True),
    ],
)
def test_the_one_metre_boundary_is_strict(position, fixed) -> None:
    positions, targets = np.array([position]), np.zeros((1, 2))
    assert bool(is_fixed(positions, targets)[0]) is fixed
    assert fixed_strict(positions, targets) == float(fixed)
    assert rearrange_success(positions, targets) == float(fixed)


def test_one_object_exactly_on_the_boundary_spoils_success() -> None:
    targets = np.array([[1.0, 1.0], [-1.0, -1.0]])
    positions = np.array([[1.0, 1.5], [-1.0, 0.0]])  # 0.5 m and exactly 1 m
    assert rearrange_success(positions, targets) == 0.0
    assert fixed_strict(positions, targets) == 0.5


def test_zero_initial_energy_is_an_error() -> None:
    with pytest.raises(ValueError, match="initial energy"):
        energy_remaining(TARGETS + 1.0, TARGETS, TARGETS)


def test_metrics_accept_lists() -> None:
    assert fixed_strict([[0.0, 0.0], [5.0, 5.0]], [[0.1, 0.0], [0.0, 0.0]]) == 0.5
    assert energy([[3.0, 4.0]], [[0.0, 0.0]]) == 5.0
