"""Frames and planar geometry (mor.sim.geometry): the conventions every other module relies on."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mor.sim.geometry import (
    bearing,
    ego_to_world,
    heading_vector,
    point_in_polygon,
    point_segment_distance,
    segment_segment_distance,
    wrap_angle,
    world_to_ego,
)

coordinate = st.floats(-50.0, 50.0, allow_nan=False, allow_infinity=False)
angle = st.floats(-20.0, 20.0, allow_nan=False, allow_infinity=False)
poses = st.tuples(coordinate, coordinate, angle)
points = st.tuples(coordinate, coordinate)


# ---- frames ----------------------------------------------------------------------------------------------------
@settings(max_examples=200, deadline=None)
@given(pose=poses, point=points)
def test_world_ego_round_trip(pose, point) -> None:
    ego = world_to_ego(point, pose)
    np.testing.assert_allclose(ego_to_world(ego, pose), point, atol=1e-9)
    np.testing.assert_allclose(world_to_ego(ego_to_world(point, pose), pose), point, atol=1e-9)


@settings(max_examples=100, deadline=None)
@given(pose=poses, point=points)
def test_world_to_ego_preserves_distance(pose, point) -> None:
    ego = world_to_ego(point, pose)
    assert np.linalg.norm(ego) == pytest.approx(np.linalg.norm(np.subtract(point, pose[:2])), abs=1e-9)


def test_round_trip_batched() -> None:
    rng = np.random.default_rng(0)
    pts = rng.uniform(-5, 5, size=(4, 7, 2))
    pose = (1.0, -2.0, 2.5)
    assert world_to_ego(pts, pose).shape == (4, 7, 2)
    np.testing.assert_allclose(ego_to_world(world_to_ego(pts, pose), pose), pts, atol=1e-12)


def test_ego_frame_is_x_forward_y_left() -> None:
    # Agent at (1, 2) facing north (+y): a point 1 m north is straight ahead, 1 m west is to its left.
    pose = (1.0, 2.0, np.pi / 2)
    np.testing.assert_allclose(world_to_ego((1.0, 3.0), pose), (1.0, 0.0), atol=1e-12)
    np.testing.assert_allclose(world_to_ego((0.0, 2.0), pose), (0.0, 1.0), atol=1e-12)
    np.testing.assert_allclose(world_to_ego((2.0, 2.0), pose), (0.0, -1.0), atol=1e-12)
    np.testing.assert_allclose(ego_to_world((2.0, 0.0), pose), (1.0, 4.0), atol=1e-12)


def test_heading_vector_and_bearing() -> None:
    np.testing.assert_allclose(heading_vector(0.0), (1.0, 0.0))
    np.testing.assert_allclose(heading_vector(np.pi / 2), (0.0, 1.0), atol=1e-12)
    assert bearing((0.0, 0.0, 0.0), (1.0, 1.0)) == pytest.approx(np.pi / 4)  # left is positive
    assert bearing((0.0, 0.0, 0.0), (1.0, -1.0)) == pytest.approx(-np.pi / 4)
    assert abs(bearing((0.0, 0.0, np.pi), (1.0, 0.0))) == pytest.approx(np.pi)  # straight behind
    assert bearing((2.0, 0.0, np.pi / 2), (2.0, 5.0)) == pytest.approx(0.0, abs=1e-12)


# ---- angles ----------------------------------------------------------------------------------------------------
@settings(max_examples=300, deadline=None)
@given(st.floats(-1e4, 1e4, allow_nan=False, allow_infinity=False))
def test_wrap_angle_range_and_equivalence(value) -> None:
    wrapped = float(wrap_angle(value))
    assert -np.pi <= wrapped < np.pi
    assert np.cos(wrapped) == pytest.approx(np.cos(value), abs=1e-9)
    assert np.sin(wrapped) == pytest.approx(np.sin(value), abs=1e-9)


@pytest.mark.parametrize(
    "value",
    [np.pi, -np.pi, 3 * np.pi, -3 * np.pi, 0.0, -0.0, 1e-300, -1e-300,
     np.nextafter(-np.pi, -10.0), np.nextafter(np.pi, 10.0), np.nextafter(np.pi, 0.0), np.nextafter(-np.pi, 0.0)],
)
def test_wrap_angle_edges_stay_in_half_open_range(value) -> None:
    wrapped = float(wrap_angle(value))
    assert -np.pi <= wrapped < np.pi, f"wrap_angle({value!r}) = {wrapped!r} is outside [-pi, pi)"


def test_wrap_angle_hand_cases() -> None:
    np.testing.assert_allclose(wrap_angle([0.0, np.pi / 2, 3 * np.pi / 2, -3 * np.pi / 2, 2 * np.pi]),
                               [0.0, np.pi / 2, -np.pi / 2, np.pi / 2, 0.0], atol=1e-12)
    assert float(wrap_angle(np.pi)) == pytest.approx(-np.pi)


# ---- distances -------------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("point", "a", "b", "expected"),
    [
        ((0.5, 1.0), (0.0, 0.0), (1.0, 0.0), 1.0),  # above the interior: perpendicular distance
        ((2.0, 0.0), (0.0, 0.0), (1.0, 0.0), 1.0),  # beyond b: distance to b
        ((-3.0, 4.0), (0.0, 0.0), (1.0, 0.0), 5.0),  # before a: distance to a
        ((0.3, 0.0), (0.0, 0.0), (1.0, 0.0), 0.0),  # on the segment
        ((1.0, 1.0), (0.0, 0.0), (2.0, 2.0), 0.0),  # on a diagonal segment
        ((0.0, 2.0), (0.0, 0.0), (2.0, 2.0), np.sqrt(2.0)),
        ((3.0, 4.0), (0.0, 0.0), (0.0, 0.0), 5.0),  # degenerate segment: a point
    ],
)
def test_point_segment_distance_hand_cases(point, a, b, expected) -> None:
    assert float(point_segment_distance(point, a, b)) == pytest.approx(expected, abs=1e-12)


def test_point_segment_distance_broadcasts() -> None:
    starts = np.array([[0.0, 0.0], [0.0, 1.0]])
    ends = np.array([[1.0, 0.0], [1.0, 1.0]])
    np.testing.assert_allclose(point_segment_distance((0.5, 0.25), starts, ends), [0.25, 0.75])
    np.testing.assert_allclose(point_segment_distance([[0.5, -1.0], [2.0, 0.0]], (0.0, 0.0), (1.0, 0.0)), [1.0, 1.0])


@pytest.mark.parametrize(
    ("p1", "p2", "q1", "q2", "expected"),
    [
        ((0, 0), (2, 2), (0, 2), (2, 0), 0.0),  # an X: crossing
        ((0, 0), (1, 0), (0, 1), (1, 1), 1.0),  # parallel, one apart
        ((0, 0), (1, 0), (2, 1), (2, 3), np.sqrt(2.0)),  # endpoint to endpoint
        ((0, 0), (2, 0), (1, 0.5), (1, 3), 0.5),  # T without touching: endpoint to interior
        ((0, 0), (2, 0), (1, 0), (1, 3), 0.0),  # T touching
        ((0, 0), (2, 0), (1, 0), (3, 0), 0.0),  # collinear, overlapping
        ((0, 0), (1, 0), (3, 0), (4, 0), 2.0),  # collinear, apart
        ((0, 0), (0, 0), (3, 4), (3, 4), 5.0),  # two points
        ((-1, -1), (1, 1), (-1, 1.5), (1, 3.5), 2.5 / np.sqrt(2.0)),  # parallel diagonals, overlapping spans
        ((0, 0), (1, 1), (3, 4), (5, 6), np.sqrt(13.0)),  # parallel diagonals, end to end
    ],
)
def test_segment_segment_distance_hand_cases(p1, p2, q1, q2, expected) -> None:
    assert float(segment_segment_distance(p1, p2, q1, q2)) == pytest.approx(expected, abs=1e-12)
    # symmetric in the two segments and in each segment's direction
    assert float(segment_segment_distance(q2, q1, p2, p1)) == pytest.approx(expected, abs=1e-12)


@settings(max_examples=100, deadline=None)
@given(p1=points, p2=points, q1=points, q2=points)
def test_segment_distance_is_at_most_endpoint_distances(p1, p2, q1, q2) -> None:
    d = float(segment_segment_distance(p1, p2, q1, q2))
    bound = min(float(point_segment_distance(p, q1, q2)) for p in (p1, p2))
    assert 0.0 <= d <= bound + 1e-9
    # sampled points on both segments are never closer than the reported distance
    t = np.linspace(0.0, 1.0, 21)[:, None]
    on_p = np.asarray(p1) + t * (np.subtract(p2, p1))
    on_q = np.asarray(q1) + t * (np.subtract(q2, q1))
    sampled = np.min(np.linalg.norm(on_p[:, None, :] - on_q[None, :, :], axis=-1))
    assert d <= sampled + 1e-6


def test_segment_segment_distance_broadcasts_over_walls() -> None:
    walls_a = np.array([[-3.0, -3.0], [3.0, -3.0]])
    walls_b = np.array([[3.0, -3.0], [3.0, 3.0]])
    np.testing.assert_allclose(segment_segment_distance((0.0, 0.0), (2.5, 0.0), walls_a, walls_b), [3.0, 0.5])


# ---- polygons --------------------------------------------------------------------------------------------------
SQUARE = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
L_SHAPE = [(0.0, 0.0), (2.0, 0.0), (2.0, 1.0), (1.0, 1.0), (1.0, 2.0), (0.0, 2.0)]


@pytest.mark.parametrize(
    ("point", "polygon", "inside"),
    [
        ((0.0, 0.0), SQUARE, True),
        ((0.99, -0.99), SQUARE, True),
        ((1.01, 0.0), SQUARE, False),
        ((0.0, -1.5), SQUARE, False),
        ((5.0, 5.0), SQUARE, False),
        ((0.5, 0.5), L_SHAPE, True),
        ((1.5, 0.5), L_SHAPE, True),
        ((0.5, 1.5), L_SHAPE, True),
        ((1.5, 1.5), L_SHAPE, False),  # the notch of a concave polygon
        ((-0.1, 1.0), L_SHAPE, False),
    ],
)
def test_point_in_polygon(point, polygon, inside) -> None:
    assert point_in_polygon(point, polygon) is inside
    # orientation of the vertex list does not matter
    assert point_in_polygon(point, polygon[::-1]) is inside
