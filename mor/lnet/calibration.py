"""The calibration of the L-Net, fitted on validation (``mor.lnet.evaluate``) and stored as ``calibration.json``
beside the checkpoint it belongs to: multipliers of the stated uncertainty (the agent's, the heading's, and the
objects' in two groups: objects of a colour of their own and objects sharing their colour with another, which the
PoseNet confuses), the tracking rule they were fitted for (the filter's data association), the filter's
measurement-noise multipliers for the two groups (``mor.lnet.filter``) and, when fitted, the two groups'
probabilities that a belief is lost (``mor.lnet.lost``) and the one-look find probability of the search belief of
objects not found yet (``mor.lnet.search``)."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from mor.errors import MorError
from mor.sim.catalog import shares_colour

CALIBRATION_FILE = "calibration.json"
_T = TypeVar("_T")


@dataclass(frozen=True)
class Calibration:
    """Multipliers of the stated standard deviations (agent; objects of their own colour, ``object_scale``;
    objects sharing their colour and not held, ``shared_colour_scale``, None: the same as ``object_scale``) and of the heading
    concentration; whether they were fitted (and so must be used) with the filter's data association; the
    filter's measurement-noise multipliers (own colour, shared colour) they were fitted with; and the
    probability that an object's belief is lost, anywhere in the arena (``mor.lnet.lost``), for objects of their
    own colour (``lost_own``) and confusable ones (``lost_shared``, None: the same as ``lost_own``); and the
    probability that one look finds an object not found yet (``search_find``, ``mor.lnet.search``; None: not
    fitted, such an object's stated belief is its Gaussian too)."""

    agent_scale: float = 1.0
    object_scale: float = 1.0
    kappa_scale: float = 1.0
    data_association: bool = False
    shared_colour_scale: float | None = None
    noise_own: float = 1.0
    noise_shared: float = 1.0
    lost_own: float = 0.0
    lost_shared: float | None = None
    search_find: float | None = None

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

    def lost(self, confusable_mask: np.ndarray) -> np.ndarray:
        """(..., K) float64 the probability that each object's belief is lost (``mor.lnet.lost``), by group:
        confusable_mask (..., K) bool as in ``apply``."""
        shared = self.lost_own if self.lost_shared is None else self.lost_shared
        return np.where(np.asarray(confusable_mask), shared, self.lost_own)


def confusable(classes: np.ndarray, held: np.ndarray) -> np.ndarray:
    """Which objects the PoseNet may take for another, the calibration's second group: those sharing their colour
    with another object of the episode (``mor.sim.catalog.shares_colour``), except while held (then the belief is
    the agent's). classes (..., K) class ids (-1: an empty slot); held (B...) the held index (-1 or >= K: none),
    broadcast against the leading dims of classes: (K,) with (T,) -> (T, K); (N, K) with (N,) -> (N, K)."""
    classes = np.asarray(classes)
    return shares_colour(classes) & (np.asarray(held)[..., None] != np.arange(classes.shape[-1]))


def read_calibration(path: Path, dataset_version: str | None = None) -> Calibration:
    """The calibration in the JSON file at ``path`` (written by ``mor calibrate-lnet``; a file without
    ``data_association``, ``shared_colour_scale``, the ``noise_*`` multipliers or the ``lost_*`` probabilities
    predates them and was fitted without them); one clear error if unusable, or if it records a dataset version
    other than ``dataset_version`` (the checkpoint's)."""
    try:
        values = json.loads(Path(path).read_text())
        calibration = calibration_from_values(values)
    except FileNotFoundError:
        raise MorError(f"{path}: no calibration beside the checkpoint; run mor calibrate-lnet") from None
    except (ValueError, KeyError, TypeError) as error:
        raise MorError(f"{path}: not an L-Net calibration ({type(error).__name__}: {error}); run mor calibrate-lnet")\
            from None
    fitted_on = values.get("dataset_version")
    if dataset_version is not None and fitted_on is not None and fitted_on != dataset_version:
        raise MorError(f"{path}: calibration dataset_version is {fitted_on} but the checkpoint's is {dataset_version}; "
                       "run mor calibrate-lnet for this checkpoint")
    check_scales(calibration, path)
    return calibration


def calibration_from_values(values: dict[str, Any]) -> Calibration:
    """The ``Calibration`` a ``calibration.json`` (or one of its ``criteria``) records; ValueError, KeyError or
    TypeError where a field is missing or of the wrong kind."""
    shared, lost_shared, find = (values.get(key) for key in ("shared_colour_scale", "lost_shared", "search_find"))
    calibration = Calibration(*(float(values[key]) for key in ("agent_scale", "object_scale", "kappa_scale")),
                              data_association=values.get("data_association", False),
                              shared_colour_scale=None if shared is None else float(shared),
                              noise_own=float(values.get("noise_own", 1.0)),
                              noise_shared=float(values.get("noise_shared", 1.0)),
                              lost_own=float(values.get("lost_own", 0.0)),
                              lost_shared=None if lost_shared is None else float(lost_shared),
                              search_find=None if find is None else float(find))
    if not isinstance(calibration.data_association, bool):
        raise TypeError(f"data_association must be true or false, got {calibration.data_association!r}")
    return calibration


def check_scales(calibration: Calibration, path: Path) -> None:
    """One clear error unless every scale and multiplier is a positive finite number (NaN estimates give NaN
    scales), every lost probability lies in [0, 1) and the search belief's find probability in [0, 1]."""
    scales = (calibration.agent_scale, calibration.object_scale, calibration.kappa_scale, calibration.noise_own,
              calibration.noise_shared, calibration.object_scale if calibration.shared_colour_scale is None
              else calibration.shared_colour_scale)
    if not all(math.isfinite(scale) and scale > 0 for scale in scales):
        raise MorError(f"{path}: calibration scales must be positive and finite, got {calibration}; run mor "
                       "calibrate-lnet (non-finite scales come from non-finite estimates on validation)")
    lost = (calibration.lost_own, calibration.lost_own if calibration.lost_shared is None else calibration.lost_shared)
    if not all(0.0 <= weight < 1.0 for weight in lost):
        raise MorError(f"{path}: lost_own and lost_shared must lie in [0, 1), got {lost}; run mor calibrate-lnet")
    if calibration.search_find is not None and not 0.0 <= calibration.search_find <= 1.0:
        raise MorError(f"{path}: search_find must lie in [0, 1], got {calibration.search_find}; run mor calibrate-lnet")
