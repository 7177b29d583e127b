"""The walled arena: a square (the paper's main world) or an irregular polygon (paper Figure 5)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from mor.sim.geometry import Array

ARENA_SHAPES: tuple[str, ...] = ("square", "polygon")
#: ``Arena.sample_point`` gives up after this many rejected points in a row.
SAMPLE_POINT_TRIES: int = 200

# An irregular hexagon in units of the arena size (side of its bounding square), counter-clockwise,
# starting with the south wall so that wall k of the square and of the polygon face similar directions.
_POLYGON_UNIT: tuple[tuple[float, float], ...] = (
    (-0.30, -0.50),
    (0.50, -0.38),
    (0.42, 0.20),
    (0.05, 0.50),
    (-0.50, 0.32),
    (-0.42, -0.12),
)


@dataclass(frozen=True)
class Arena:
    """A simple polygon of walls; ``vertices`` (k, 2) counter-clockwise, metres.

    Wall k runs from vertex k to vertex k+1; the arena's inside is on its left.
    """

    shape: str
    vertices: tuple[tuple[float, float], ...]

    @classmethod
    def build(cls, shape: str, size: float) -> Arena:
        """The arena ``shape`` ("square" or "polygon") whose bounding square has side ``size`` metres."""
        if shape == "square":
            h = size / 2.0
            return cls("square", ((-h, -h), (h, -h), (h, h), (-h, h)))
        if shape == "polygon":
            return cls("polygon", tuple((x * size, y * size) for x, y in _POLYGON_UNIT))
        raise ValueError(f"unknown arena shape {shape!r}; choose one of {ARENA_SHAPES}")

    @cached_property
    def vertex_array(self) -> Array:
        return np.asarray(self.vertices, dtype=np.float64)

    @property
    def n_walls(self) -> int:
        return len(self.vertices)

    @cached_property
    def wall_starts(self) -> Array:
        """(k, 2) the first end of each wall."""
        return self.vertex_array

    @cached_property
    def wall_ends(self) -> Array:
        """(k, 2) the second end of each wall."""
        return np.roll(self.vertex_array, -1, axis=0)

    def walls(self) -> list[tuple[Array, Array]]:
        """The wall segments [(start (2,), end (2,)), ...] in counter-clockwise order."""
        return list(zip(self.wall_starts, self.wall_ends, strict=True))

    @cached_property
    def half_extent(self) -> float:
        """Half the side of the smallest origin-centred square holding the arena (metres)."""
        return float(np.abs(self.vertex_array).max())

    @cached_property
    def _wall_terms(self) -> tuple[tuple[float, ...], ...]:
        """Per wall, Python floats: start x, y; end y; direction (end - start) x, y; squared length (>= 1e-18)."""
        terms = []
        for (ax, ay), (bx, by) in zip(self.wall_starts.tolist(), self.wall_ends.tolist(), strict=True):
            dx, dy = bx - ax, by - ay
            terms.append((ax, ay, by, dx, dy, max(dx * dx + dy * dy, 1e-18)))
        return tuple(terms)

    def clearance(self, point: Array) -> float:
        """Distance (metres) from ``point`` (2,) to the nearest wall; negative when outside the arena.

        The scalar form of ``geometry.point_segment_distance`` over the walls and ``geometry.point_in_polygon``:
        the same float operations in the same order, so the same bits (a test compares them), without numpy's
        per-call cost on 4-6 walls, which made this the bulk of a reset's rejection sampling.
        """
        px, py = float(point[0]), float(point[1])
        nearest, inside = math.inf, False
        for ax, ay, by, dx, dy, length_sq in self._wall_terms:
            t = min(max(((px - ax) * dx + (py - ay) * dy) / length_sq, 0.0), 1.0)
            ox, oy = px - (ax + t * dx), py - (ay + t * dy)
            nearest = min(nearest, math.sqrt(ox * ox + oy * oy))
            if (ay > py) != (by > py) and px < ax + (py - ay) * dx / dy:
                inside = not inside
        return nearest if inside else -nearest

    def clearances(self, points: Array) -> Array:
        """``clearance`` of many points at once: points (..., 2) -> (...,) metres, the same bits as ``clearance``
        of each point (the same float operations, in the same order, on arrays)."""
        p = np.asarray(points, dtype=np.float64)
        px, py = p[..., 0].copy(), p[..., 1].copy()  # contiguous: long inner loops
        # the walls along a new first axis: (k, 1, ..., 1) against the points' (...)
        ax, ay, by, dx, dy, length_sq = np.array(self._wall_terms).T.reshape(6, -1, *(1,) * px.ndim)
        t = np.minimum(np.maximum(((px - ax) * dx + (py - ay) * dy) / length_sq, 0.0), 1.0)
        ox, oy = px - (ax + t * dx), py - (ay + t * dy)
        nearest = np.sqrt(ox * ox + oy * oy).min(axis=0)
        with np.errstate(divide="ignore", invalid="ignore"):  # dy = 0 only where the wall does not straddle py
            crossing = ((ay > py) != (by > py)) & (px < ax + (py - ay) * dx / dy)
        inside = np.sum(crossing, axis=0) % 2 == 1
        return np.where(inside, nearest, -nearest)

    def contains(self, point: Array, margin: float = 0.0) -> bool:
        """Whether ``point`` is inside with at least ``margin`` metres to every wall."""
        return self.clearance(point) >= margin

    def area(self) -> float:
        """Area in square metres (shoelace formula)."""
        x, y = self.vertex_array.T
        return float(0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))

    @cached_property
    def bounds(self) -> tuple[Array, Array]:
        """(lower-left (2,), upper-right (2,)) corners of the arena's bounding box, metres."""
        return self.vertex_array.min(axis=0), self.vertex_array.max(axis=0)

    def sample_point(
        self, rng: np.random.Generator, margin: float, max_tries: int = SAMPLE_POINT_TRIES
    ) -> Array | None:
        """A uniform point at least ``margin`` from every wall, or None after ``max_tries`` rejections."""
        low, high = self.bounds
        for _ in range(max_tries):
            point = rng.uniform(low, high)
            if self.contains(point, margin):
                return point
        return None
