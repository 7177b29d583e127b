"""Planar geometry and the frame conventions (docs/design.md, "Frames and units").

World frame: the arena frame, x east, y north, heading theta counter-clockwise from +x, radians.
Ego frame: x forward, y left, origin at the agent. Units: metres.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]


def wrap_angle(angle: ArrayLike) -> Array:
    """Angle(s) wrapped to [-pi, pi)."""
    wrapped = (np.asarray(angle, dtype=np.float64) + np.pi) % (2.0 * np.pi) - np.pi
    # Rounding can give exactly pi (e.g. for the float just below -pi); fold it to -pi to keep [-pi, pi).
    return wrapped - 2.0 * np.pi * (wrapped >= np.pi)


def heading_vector(theta: ArrayLike) -> Array:
    """Unit vector(s) (..., 2) pointing along heading(s) ``theta`` (...,) radians; (2,) for one heading."""
    return np.stack([np.cos(theta), np.sin(theta)], axis=-1)


def vector_norm(vectors: ArrayLike) -> Array:
    """Euclidean length (...,) of each vector (..., 2): the same bits as ``np.linalg.norm`` of each one alone.

    ``np.linalg.norm(v)`` of one vector is BLAS's dot product (fused multiply-adds), which can differ in the last
    bit from ``np.linalg.norm(v, axis=-1)``; ``np.vecdot`` runs the same BLAS dot per vector, so the rules' batched
    form (``mor.sim.batch_world``) decides exactly as the per-environment form.
    """
    v = np.asarray(vectors, dtype=np.float64)
    return np.sqrt(np.vecdot(v, v))


#: ``shorter_than`` measures with ``vector_norm`` the vectors whose plain length lies this close (relative) to the bound
_BLAS_BAND: float = 1e-12


def shorter_than(dx: ArrayLike, dy: ArrayLike, length: float) -> NDArray[np.bool_]:
    """Whether each vector (dx, dy) (...,) is shorter than ``length``, answering as ``vector_norm(v) < length`` does.

    Computed as sqrt(dx² + dy²) on whole arrays (no BLAS call per vector): it differs from ``vector_norm`` by at
    most a unit in the last place, so only vectors within 1e-12 (relative) of ``length`` are measured again by
    ``vector_norm``.
    """
    dx, dy = np.asarray(dx, dtype=np.float64), np.asarray(dy, dtype=np.float64)
    plain = np.sqrt(dx * dx + dy * dy)
    shorter = plain < length
    close = np.abs(plain - length) <= _BLAS_BAND * length
    if close.any():
        shorter[close] = vector_norm(np.stack([dx[close], dy[close]], axis=-1)) < length
    return shorter


def world_to_ego(points: ArrayLike, agent_pose: ArrayLike) -> Array:
    """World points (..., 2) expressed in the ego frame of ``agent_pose`` = (x, y, theta), (3,) or (..., 3)
    broadcast against the points' leading dimensions."""
    pose = np.asarray(agent_pose, dtype=np.float64)
    delta = np.asarray(points, dtype=np.float64) - pose[..., :2]
    c, s = np.cos(pose[..., 2]), np.sin(pose[..., 2])
    return np.stack([c * delta[..., 0] + s * delta[..., 1], -s * delta[..., 0] + c * delta[..., 1]], axis=-1)


def ego_to_world(points: ArrayLike, agent_pose: ArrayLike) -> Array:
    """Ego-frame points (..., 2) of ``agent_pose`` = (x, y, theta) expressed in the world frame."""
    x, y, theta = np.asarray(agent_pose, dtype=np.float64)
    p = np.asarray(points, dtype=np.float64)
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([x + c * p[..., 0] - s * p[..., 1], y + s * p[..., 0] + c * p[..., 1]], axis=-1)


def bearing(agent_pose: ArrayLike, point: ArrayLike) -> float:
    """Signed angle (radians, left positive) from the agent's heading to ``point``."""
    return float(bearings(agent_pose, point))


def bearings(agent_poses: ArrayLike, points: ArrayLike) -> Array:
    """``bearing`` of points (..., 2) from poses (..., 3) broadcast against them, radians (...,)."""
    ego = world_to_ego(points, agent_poses)
    return np.arctan2(ego[..., 1], ego[..., 0])


def point_segment_distance(points: ArrayLike, seg_a: ArrayLike, seg_b: ArrayLike) -> Array:
    """Distance from points to segments [seg_a, seg_b]; all (..., 2), broadcast against each other."""
    p = np.asarray(points, dtype=np.float64)
    a, b = np.asarray(seg_a, dtype=np.float64), np.asarray(seg_b, dtype=np.float64)
    ab = b - a
    length_sq = np.maximum(np.sum(ab * ab, axis=-1), 1e-18)
    t = np.minimum(np.maximum(np.sum((p - a) * ab, axis=-1) / length_sq, 0.0), 1.0)
    offset = p - (a + t[..., None] * ab)
    return np.sqrt(np.sum(offset * offset, axis=-1))


def _orientation(a: Array, b: Array, c: Array) -> Array:
    return (b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1]) - (b[..., 1] - a[..., 1]) * (c[..., 0] - a[..., 0])


def segment_segment_distance(p1: ArrayLike, p2: ArrayLike, q1: ArrayLike, q2: ArrayLike) -> Array:
    """Shortest distance between segments [p1, p2] and [q1, q2] (0 where they cross); (..., 2), broadcast."""
    p1, p2, q1, q2 = (np.asarray(v, dtype=np.float64) for v in (p1, p2, q1, q2))
    crossing = (_orientation(q1, q2, p1) * _orientation(q1, q2, p2) < 0.0) & (
        _orientation(p1, p2, q1) * _orientation(p1, p2, q2) < 0.0
    )
    nearest = np.minimum(
        np.minimum(point_segment_distance(p1, q1, q2), point_segment_distance(p2, q1, q2)),
        np.minimum(point_segment_distance(q1, p1, p2), point_segment_distance(q2, p1, p2)),
    )
    return np.where(crossing, 0.0, nearest)


def point_in_polygon(point: ArrayLike, vertices: ArrayLike) -> bool:
    """Whether ``point`` (2,) lies strictly inside the simple polygon ``vertices`` (k, 2)."""
    x, y = np.asarray(point, dtype=np.float64)
    v = np.asarray(vertices, dtype=np.float64)
    inside = False
    for (x1, y1), (x2, y2) in zip(v, np.roll(v, -1, axis=0), strict=True):
        if (y1 > y) != (y2 > y) and x < x1 + (y - y1) * (x2 - x1) / (y2 - y1):
            inside = not inside
    return inside
