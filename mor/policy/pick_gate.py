"""The PICK gate: a Pick skill with uncertainty may PICK only where its belief gives the target at least a set
probability of lying where PICK takes it (within ``PICK_RANGE`` and inside the camera's field of view).

PICK ends a Pick episode, so a PICK at a target believed in reach but not there is a failure that an honest
covariance would foresee (docs/assumptions.md, "The PICK gate, off": trained with it, ``lnet`` PICKed wrongly less
and drove into things more, and picked no better). The probability is read from the policy's own
observation vector (``mor.policy.features``): the goal's polar position from the believed agent, the goal's and the
agent's ego-frame uncertainty triples and the heading's σ. The relative position is taken as Gaussian with the sum of
the two covariances, the heading error as an independent Gaussian; the probability is the share of a fixed set of
``GATE_SAMPLES`` standard-normal draws (seed 0) that land in reach and view, so the same vector always gives the same
answer. The gate is ``policy.observation.pick_gate_probability`` (0: off); only the L-Net variants with uncertainty
read it (``ObservationLayout.gate``), and a policy records it in its signature, so it plays with the gate it was
trained with.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from mor.sim.geometry import wrap_angle
from mor.sim.rules import CAMERA_FOV, PICK_RANGE, Action

#: standard-normal draws per vector: (x, y, heading) each
GATE_SAMPLES: int = 256
_DRAWS = np.random.default_rng(0).standard_normal((GATE_SAMPLES, 3))
#: the entries of a Pick vector the gate reads, in this order
GATE_FEATURES: tuple[str, ...] = (
    "goal_distance", "goal_cos_bearing", "goal_sin_bearing", "goal_sigma_forward", "goal_sigma_left",
    "goal_correlation", "agent_sigma_forward", "agent_sigma_left", "agent_correlation", "heading_sigma")


def _covariance(sigma_forward: NDArray, sigma_left: NDArray, correlation: NDArray) -> NDArray:
    """(N,) each -> (N, 2, 2) the ego-frame covariance of an uncertainty triple."""
    cross = correlation * sigma_forward * sigma_left
    return np.stack([np.stack([sigma_forward**2, cross], -1), np.stack([cross, sigma_left**2], -1)], -2)


def reach_probability(entries: NDArray) -> NDArray[np.float64]:
    """entries (N, 10) the ``GATE_FEATURES`` of N Pick vectors -> (N,) the belief's probability that the target lies
    within ``PICK_RANGE`` metres and within half the camera's field of view of the heading."""
    e = np.asarray(entries, np.float64)
    mean = e[:, :1] * e[:, 1:3]                                                   # (N, 2) ego, m
    covariance = _covariance(*e[:, 3:6].T) + _covariance(*e[:, 6:9].T)            # (N, 2, 2)
    covariance += 1e-12 * np.eye(2)  # the truth's zeros: a point mass, still factorable
    root = np.linalg.cholesky(covariance)                                          # (N, 2, 2)
    points = mean[:, None] + np.einsum("nij,sj->nsi", root, _DRAWS[:, :2])         # (N, S, 2)
    bearing = wrap_angle(np.arctan2(points[..., 1], points[..., 0]) - e[:, 9:10] * _DRAWS[None, :, 2])
    inside = (np.linalg.norm(points, axis=-1) <= PICK_RANGE) & (np.abs(bearing) <= CAMERA_FOV / 2.0)
    return inside.mean(axis=-1)


def gate_columns(names: Sequence[str]) -> NDArray[np.int64]:
    """The columns of ``GATE_FEATURES`` in a vector whose entries are ``names`` (a Pick layout with uncertainty)."""
    index = {name: i for i, name in enumerate(names)}
    missing = [name for name in GATE_FEATURES if name not in index]
    if missing:
        raise ValueError(f"the PICK gate needs a Pick observation with uncertainty; missing {', '.join(missing)}")
    return np.array([index[name] for name in GATE_FEATURES])


def pick_allowed(vectors: NDArray, columns: NDArray[np.int64], probability: float) -> NDArray[np.bool_]:
    """vectors (N, D) Pick observations -> (N,) whether PICK is allowed: the belief's ``reach_probability`` is at
    least ``probability``."""
    return reach_probability(np.asarray(vectors)[:, columns]) >= probability


@dataclass(frozen=True)
class PickGate:
    """The PICK gate of one Pick layout: the ``GATE_FEATURES``' columns in its vectors and the probability."""

    columns: NDArray[np.int64]
    probability: float

    @classmethod
    def of(cls, names: Sequence[str], probability: float) -> PickGate | None:
        """The gate of a Pick vector named ``names`` at ``probability``; None where ``probability`` is 0."""
        return cls(gate_columns(names), probability) if probability > 0.0 else None

    @classmethod
    def recorded(cls, meta: Path) -> PickGate | None:
        """The gate the policy whose signature is ``meta`` (its ``meta.json``) was trained with; None if none."""
        from mor.policy.signature import read_signature  # noqa: PLC0415 - the signature imports the layouts

        if not meta.is_file():
            return None
        signature = read_signature(meta)
        return cls.of(signature.observation, signature.features.pick_gate_probability) \
            if signature.task == "pick" else None

    def mask(self, vectors: NDArray, masks: NDArray[np.bool_]) -> NDArray[np.bool_]:
        """masks (N, A) with PICK cleared where the vectors (N, D) give the target too little probability."""
        masks = np.array(masks, dtype=bool)
        masks[:, Action.PICK] &= pick_allowed(vectors, self.columns, self.probability)
        return masks
