"""The calibration's scales: multipliers of the L-Net's stated uncertainty, fitted on validation
(``mor.lnet.calibration_fit``) and stored in ``calibration.json`` beside the checkpoint
(``mor.lnet.calibration_file``): the agent's, the heading's, and the objects' in two groups, objects of a colour of
their own and objects sharing their colour with another (which the PoseNet confuses)."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, TypeVar

import numpy as np

from mor.sim.catalog import shares_colour

_T = TypeVar("_T")


@dataclass(frozen=True)
class Calibration:
    """Multipliers of the stated standard deviations (agent; objects of their own colour, ``object_scale``;
    objects sharing their colour and not held, ``shared_colour_scale``, None: the same as ``object_scale``) and of
    the heading concentration."""

    agent_scale: float = 1.0
    object_scale: float = 1.0
    kappa_scale: float = 1.0
    shared_colour_scale: float | None = None

    def apply(self, estimates: _T, confusable_mask: Any) -> _T:
        """A copy of ``estimates`` (any dataclass with ``agent_tril``, ``object_tril`` (..., K, 2, 2) and
        ``kappa``) with the Cholesky factors and the concentration scaled; confusable_mask (..., K) bool (numpy
        or torch, as the estimates): the object shares its colour with another and is not held (``confusable``
        below), so ``shared_colour_scale`` is its scale."""
        common = self.object_scale if self.shared_colour_scale is None else self.shared_colour_scale
        object_scale = self.object_scale + (common - self.object_scale) * confusable_mask
        return replace(estimates, agent_tril=estimates.agent_tril * self.agent_scale,  # type: ignore[type-var]
                       object_tril=estimates.object_tril * object_scale[..., None, None],  # type: ignore[attr-defined]
                       kappa=estimates.kappa * self.kappa_scale)  # type: ignore[attr-defined]


def confusable(classes: np.ndarray, held: np.ndarray) -> np.ndarray:
    """Which objects the PoseNet may take for another, the calibration's second group: those sharing their colour
    with another object of the episode (``mor.sim.catalog.shares_colour``), except while held (then the belief is
    the agent's). classes (..., K) class ids (-1: an empty slot); held (B...) the held index (-1 or >= K: none),
    broadcast against the leading dims of classes: (K,) with (T,) -> (T, K); (N, K) with (N,) -> (N, K)."""
    classes = np.asarray(classes)
    return shares_colour(classes) & (np.asarray(held)[..., None] != np.arange(classes.shape[-1]))
