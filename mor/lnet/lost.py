"""Lost beliefs: an object's stated belief as a Gaussian that is wrong with a calibrated probability.

The tracker's object beliefs are Gaussians, but their errors are a narrow core and a long tail: a belief that
followed a same-coloured object, or that a gated-out sighting never corrected, is metres off while it states
centimetres (docs/assumptions.md). No multiplier of a Gaussian covers both, so the calibration may add a *lost*
component (``lnet.calibration.lost_objects``): with probability w (per group of objects, fitted on validation)
the object is anywhere in the arena,

    p(x) = (1 - w) N(x; mean, cov) + w / area        (x in the arena; the Gaussian part is not truncated),

the outlier model of robust estimation. Its k-sigma-equivalent region is its highest-density region holding the
2-D Gaussian's k-sigma mass (39.3%, 86.5%, 98.9%). Within the arena that region is an ellipse of the Gaussian
(the uniform part is flat there), so the truth, at Mahalanobis distance d, is counted inside the region of mass
p when ``region_mass`` = (1 - w) (1 - exp(-d^2 / 2)) + w |E_d & arena| / area <= p, E_d the ellipse through the
truth. The Gaussian's mass beyond the walls is counted as if inside E_d (beyond the walls the region is a smaller
ellipse), so ``region_mass`` can only over-state the region's mass: a truth counted inside is inside, and the
coverage is conservative. E_d does not change when the Gaussian is scaled (the truth's
Mahalanobis distance scales with it), so ``arena_shares`` is computed once per set of predictions.

Shapes: N frames, K object slots; R rows (flattened frames and slots), M arena points. Positions in metres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mor.sim.arena import Arena
from mor.sim.geometry import point_in_polygon

_EM_ITERATIONS = 300
_CHUNK = 1024


@dataclass(frozen=True)
class ArenaShares:
    """For a set of predictions: the arena's area (m^2) and, per frame and slot (N, K), the share of the arena
    inside the ellipse of the object's Gaussian that passes through the truth (0 where not computed)."""

    area: float
    share: np.ndarray

    def select(self, rows: np.ndarray) -> ArenaShares:
        """The shares of the frames ``rows`` (as ``Predictions.select``)."""
        return ArenaShares(self.area, self.share[rows])


def arena_grid(arena: Arena, spacing: float) -> np.ndarray:
    """(M, 2) the centres (m) of the cells of a square grid (side ``spacing``, m; ``StatedParams.arena_grid_spacing``,
    0.1 m by default: 3,600 points in a 6 m square) that lie inside ``arena``."""
    low, high = arena.bounds
    xs, ys = (np.arange(lo + spacing / 2, hi, spacing) for lo, hi in zip(low, high, strict=True))
    points = np.stack(np.meshgrid(xs, ys, indexing="ij"), -1).reshape(-1, 2)
    return points[[point_in_polygon(point, arena.vertex_array) for point in points]]


def _squared_distance(points: np.ndarray, mean: np.ndarray, tril: np.ndarray) -> np.ndarray:
    """Squared Mahalanobis distances (R, M) of points (R or 1, M, 2) under R Gaussians: mean (R, 2), lower
    Cholesky factor tril (R, 2, 2)."""
    z0 = (points[..., 0] - mean[:, None, 0]) / tril[:, 0, 0, None]
    z1 = (points[..., 1] - mean[:, None, 1] - tril[:, 1, 0, None] * z0) / tril[:, 1, 1, None]
    return z0 * z0 + z1 * z1


def arena_shares(truth: np.ndarray, mean: np.ndarray, tril: np.ndarray, rows: np.ndarray, arena: Arena,
                 spacing: float) -> ArenaShares:
    """``ArenaShares`` of Gaussians (mean (N, K, 2) m, tril (N, K, 2, 2), any scale) and the truth (N, K, 2) m,
    computed where ``rows`` (N, K) is True, counting the points of the arena grid of ``spacing`` metres."""
    grid = arena_grid(arena, spacing)
    index = np.flatnonzero(rows)
    flat = lambda a: a.reshape(-1, *a.shape[2:])[index].astype(np.float64)  # noqa: E731
    truth, mean, tril = flat(truth), flat(mean), flat(tril)
    shares = np.zeros(rows.size)
    for start in range(0, len(index), _CHUNK):
        part = slice(start, start + _CHUNK)
        through = _squared_distance(truth[part, None], mean[part], tril[part])          # (R, 1)
        shares[index[part]] = (_squared_distance(grid[None], mean[part], tril[part]) <= through).mean(1)
    return ArenaShares(arena.area(), shares.reshape(rows.shape))


def log_sqrt_det(tril: np.ndarray) -> np.ndarray:
    """log sqrt(det cov) of lower Cholesky factors (..., 2, 2)."""
    return np.log(np.abs(tril[..., 0, 0])) + np.log(np.abs(tril[..., 1, 1]))


def region_mass(d2: np.ndarray, weight: np.ndarray | float, share: np.ndarray) -> np.ndarray:
    """The mass of the stated belief's highest-density region that just reaches the truth (or a little more, see
    the module docstring): the truth is counted inside the k-sigma-equivalent region when this is <= the k-sigma
    mass. d2: the truth's squared Mahalanobis
    distance under the (calibrated) Gaussian; weight: the lost probability w; share: ``ArenaShares.share``."""
    return (1.0 - weight) * (1.0 - np.exp(-0.5 * d2)) + weight * share


def log_density(d2: np.ndarray, half_log_det: np.ndarray, weight: np.ndarray | float, area: float) -> np.ndarray:
    """log p(truth) of the stated belief; d2 as in ``region_mass``; half_log_det: ``log_sqrt_det`` of the
    (calibrated) Gaussian; area: the arena's (m^2)."""
    gaussian = -0.5 * d2 - math.log(2.0 * math.pi) - half_log_det
    with np.errstate(divide="ignore"):  # w = 0 or 1: one term is log 0 = -inf, which logaddexp absorbs
        return np.logaddexp(np.log1p(-np.asarray(weight, np.float64)) + gaussian,
                            np.log(np.asarray(weight, np.float64)) - math.log(area))


def fit_nll(d2: np.ndarray, half_log_det: np.ndarray, area: float) -> tuple[float, float]:
    """(scale s, lost weight w) that maximize the likelihood of rows (R,) of the uncalibrated Gaussians
    (squared Mahalanobis d2, half_log_det) under ``(1 - w) N(s^2 cov) + w / area``, by expectation-maximization
    from (the Gaussian's own optimum, 0.1)."""
    scale2, weight = max(float(d2.mean()) / 2.0, 1e-12), 0.1
    for _ in range(_EM_ITERATIONS):
        gaussian = np.exp(-0.5 * d2 / scale2 - math.log(2.0 * math.pi * scale2) - half_log_det)
        owned = (1.0 - weight) * gaussian / ((1.0 - weight) * gaussian + weight / area)  # P(not lost | row)
        weight = float(1.0 - owned.mean())
        scale2 = max(float((owned * d2).sum() / (2.0 * max(owned.sum(), 1e-12))), 1e-12)
    return math.sqrt(scale2), weight

