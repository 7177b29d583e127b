"""The paper's evaluation metrics (section 3.3), one implementation for env, oracle and evaluation.

Positions are (n, 2) arrays in metres; an object counts as rearranged ("fixed") when it lies strictly
closer than ``SUCCESS_RADIUS`` to its target.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

SUCCESS_RADIUS: float = 1.0


def target_distances(positions: ArrayLike, targets: ArrayLike) -> NDArray[np.float64]:
    """Euclidean distance (n,) of each object to its target, metres."""
    return np.linalg.norm(np.asarray(positions, float) - np.asarray(targets, float), axis=-1)


def is_fixed(positions: ArrayLike, targets: ArrayLike) -> NDArray[np.bool_]:
    """(n,) whether each object is within ``SUCCESS_RADIUS`` of its target."""
    return target_distances(positions, targets) < SUCCESS_RADIUS


def rearrange_success(positions: ArrayLike, targets: ArrayLike) -> float:
    """1.0 when every object is at its target, else 0.0."""
    return float(np.all(is_fixed(positions, targets)))


def fixed_strict(positions: ArrayLike, targets: ArrayLike) -> float:
    """% Fixed Strict: the fraction of objects at their targets, in [0, 1]."""
    return float(np.mean(is_fixed(positions, targets)))


def energy(positions: ArrayLike, targets: ArrayLike) -> float:
    """Sum of object-to-target distances, metres."""
    return float(np.sum(target_distances(positions, targets)))


def energy_remaining(positions: ArrayLike, targets: ArrayLike, initial_positions: ArrayLike) -> float:
    """% Energy Remaining: energy now over energy at the start (lower is better; may exceed 1)."""
    initial = energy(initial_positions, targets)
    if initial <= 0.0:
        raise ValueError("initial energy is zero: every object started on its target")
    return energy(positions, targets) / initial
