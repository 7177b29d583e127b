"""Scoring the L-Net's predictions (``mor.lnet.predictions.Predictions``): errors, NLL, coverage of the stated
uncertainty, before and after calibration, of the Gaussians and of the objects' stated belief (``mor.lnet.stated``).

Coverage: a 2-D Gaussian's k-sigma region {d^2 <= k^2} (d = Mahalanobis distance) holds 1 - exp(-k^2 / 2) of the
mass: 39.3%, 86.5%, 98.9% for k = 1, 2, 3. For the heading (1-D) the k-sigma-equivalent region is the central
von Mises interval holding the 1-D normal's mass for k: 68.3%, 95.4%, 99.7%.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from scipy import stats

from mor.lnet.calibration_file import FittedCalibration
from mor.lnet.likelihoods import gaussian_nll, mahalanobis_squared, von_mises_nll
from mor.lnet.lost import log_sqrt_det
from mor.lnet.predictions import Predictions
from mor.lnet.stated import StatedInputs, StatedParams, stated_truth
from mor.sim.geometry import wrap_angle
from mor.sim.rules import PICK_RANGE

SIGMAS = (1, 2, 3)
NOMINAL_2D = {k: float(1.0 - np.exp(-k * k / 2.0)) for k in SIGMAS}
NOMINAL_1D = {k: float(stats.norm.cdf(k) - stats.norm.cdf(-k)) for k in SIGMAS}
RELIABILITY_LEVELS = np.linspace(0.05, 0.95, 19)


def squared_mahalanobis(truth: np.ndarray, mean: np.ndarray, tril: np.ndarray) -> np.ndarray:
    """(...) the truth's squared Mahalanobis distances (float64) under Gaussians: truth, mean (..., 2), lower
    Cholesky factors tril (..., 2, 2)."""
    return mahalanobis_squared(*(torch.as_tensor(a, dtype=torch.float64) for a in (truth, mean, tril))).numpy()


def heading_central_mass(error: np.ndarray, kappa: np.ndarray) -> np.ndarray:
    """The probability mass of the central von Mises interval that just reaches ``error`` (radians): the
    error lies inside the interval of mass p exactly when this is <= p. One CDF per frame instead of one
    quantile search per frame and level."""
    error, kappa = np.abs(np.asarray(error, np.float64)), np.asarray(kappa, np.float64)
    uniform = kappa <= 1e-12
    mass = 2.0 * stats.vonmises.cdf(error, np.where(uniform, 1.0, kappa)) - 1.0
    return np.where(uniform, error / np.pi, mass)


def _summary(values: np.ndarray) -> dict[str, float]:
    if len(values) == 0:
        return {"median": float("nan"), "p90": float("nan"), "count": 0}
    return {"median": float(np.median(values)), "p90": float(np.percentile(values, 90)), "count": int(len(values))}


#: Bins of "frames since the object was last visible or held": [low, high) edges; the last is open.
SINCE_SEEN_BINS = (0, 1, 2, 4, 8, 16, 32, 64, 128)
#: Bins of the distance (m) from the agent to an object in view: [low, high) edges; the last is open.
DISTANCE_BINS = (0.0, 1.0, 2.0, 3.0, 4.0, 6.0)
#: Bins of how many frames an object has been in view so far: [low, high) edges; the last is open.
SIGHTINGS_BINS = (1, 2, 5, 20)


def _median_by_bins(error: np.ndarray, value: np.ndarray, rows: np.ndarray, bins: tuple[float, ...]
                    ) -> dict[str, list]:
    """Median of ``error`` where ``rows``, per [low, high) bin of ``value`` (the last bin open); (N, K) each."""
    edges = [*bins, np.inf]
    masks = [rows & (value >= low) & (value < high) for low, high in zip(edges[:-1], edges[1:], strict=True)]
    return {"bin_start": list(bins), "median_m": [float(np.median(error[m])) if m.any() else None for m in masks],
            "count": [int(m.sum()) for m in masks]}


def _object_error(p: Predictions) -> np.ndarray:
    """(N, K) distance (m) between each object's estimated and true position."""
    return np.linalg.norm(p.object_truth - p.object_mean, axis=-1)


def seen_object_mean_error(predictions: Predictions) -> float:
    """The mean distance (m) between estimated and true positions of the objects seen earlier (``metrics``'
    "seen" rows): what the measurement noise is chosen by (``mor.lnet.calibration_fit``; a mean, so the badly wrong
    beliefs count)."""
    return float(_object_error(predictions)[predictions.present & predictions.seen].mean())


def _object_distance(p: Predictions) -> np.ndarray:
    """(N, K) true distance (m) from the agent's centre to each object."""
    return np.linalg.norm(p.object_truth - p.agent_pose[:, None, :2], axis=-1)


def error_by_steps_since_seen(predictions: Predictions) -> dict[str, list]:
    """Median object position error (m) per bin of frames since the object was last visible or held
    (``SINCE_SEEN_BINS``); objects not yet seen are left out."""
    p = predictions
    return _median_by_bins(_object_error(p), p.since_seen, p.present & p.seen, SINCE_SEEN_BINS)


def error_by_distance_in_view(predictions: Predictions) -> dict[str, list]:
    """Median position error (m) of the objects in view now, per bin of their true distance from the agent
    (``DISTANCE_BINS``): a far object is a few pixels of a 64 px frame."""
    p = predictions
    return _median_by_bins(_object_error(p), _object_distance(p), p.present & p.visible, DISTANCE_BINS)


def coverage_by_sightings(predictions: Predictions, object_d2: np.ndarray, object_error: np.ndarray
                          ) -> dict[str, list]:
    """Objects seen earlier and not held now, per bin of how many frames they have been in view so far
    (``SIGHTINGS_BINS``): median error (m), median squared Mahalanobis distance d^2 (2 ln 2 = 1.39 for an honest
    2-D Gaussian), count and 1/2/3-sigma coverage: whether the stated uncertainty follows the error as sightings
    accumulate. object_d2, object_error: (N, K) of ``predictions``."""
    p = predictions
    rows = p.present & p.seen & (p.held[:, None] != np.arange(p.present.shape[1]))
    edges = [*SIGHTINGS_BINS, np.inf]
    masks = [rows & (p.sightings >= low) & (p.sightings < high) for low, high in zip(edges[:-1], edges[1:],
                                                                                       strict=True)]
    return {"bin_start": list(SIGHTINGS_BINS), "count": [int(m.sum()) for m in masks],
            "median_m": [float(np.median(object_error[m])) if m.any() else None for m in masks],
            "median_d2": [float(np.median(object_d2[m])) if m.any() else None for m in masks],
            **{f"{k}sigma": [float(np.mean(object_d2[m] <= k * k)) if m.any() else None for m in masks]
               for k in SIGMAS}}


def _object_groups(p: Predictions) -> dict[str, np.ndarray]:
    """The groups of objects the metrics report, (N, K) bool each."""
    return {"seen": p.present & p.seen, "all": p.present, "visible": p.present & p.visible,
            "unseen": p.present & ~p.seen,  # seen: at or before this frame; visible: now; unseen: not yet
            "visible_in_reach": p.present & p.visible & (_object_distance(p) <= PICK_RANGE),  # what PICK needs
            "seen_confusable": p.present & p.seen & p.confusable}  # sharing their colour, not held


def metrics(predictions: Predictions) -> dict[str, Any]:
    """NLL, errors, k-sigma coverage and reliability curves of ``predictions`` (JSON-ready)."""
    p = predictions
    as_t = lambda a: torch.as_tensor(a, dtype=torch.float64)  # noqa: E731
    agent_d2 = squared_mahalanobis(p.agent_pose[:, :2], p.agent_mean, p.agent_tril)
    object_d2 = squared_mahalanobis(p.object_truth, p.object_mean, p.object_tril)
    heading_error = np.abs(wrap_angle(p.agent_pose[:, 2] - p.heading))
    heading_mass = heading_central_mass(heading_error, p.kappa)
    groups = _object_groups(p)
    seen = groups["seen"]
    object_error = _object_error(p)
    nll = {
        "agent_position": float(gaussian_nll(as_t(p.agent_pose[:, :2]), as_t(p.agent_mean), as_t(p.agent_tril)).mean()),
        "heading": float(von_mises_nll(as_t(p.agent_pose[:, 2]), as_t(p.heading), as_t(p.kappa)).mean()),
        "objects": float(gaussian_nll(as_t(p.object_truth), as_t(p.object_mean), as_t(p.object_tril))[
            torch.as_tensor(p.present)].mean()),
    }
    coverage = {
        "agent_position": {f"{k}sigma": float(np.mean(agent_d2 <= k * k)) for k in SIGMAS},
        **{f"objects_{name}": {f"{k}sigma": float(np.mean(object_d2[rows] <= k * k)) if rows.any() else float("nan")
                               for k in SIGMAS} for name, rows in groups.items()},
        "heading": {f"{k}sigma": float(np.mean(heading_mass <= NOMINAL_1D[k])) for k in SIGMAS},
        "nominal_2d": {f"{k}sigma": NOMINAL_2D[k] for k in SIGMAS},
        "nominal_heading": {f"{k}sigma": NOMINAL_1D[k] for k in SIGMAS},
    }
    chi2 = -2.0 * np.log(1.0 - RELIABILITY_LEVELS)
    reliability = {
        "nominal": RELIABILITY_LEVELS.tolist(),
        "agent_position": [float(np.mean(agent_d2 <= q)) for q in chi2],
        "objects_seen": [float(np.mean(object_d2[seen] <= q)) for q in chi2],
        "heading": [float(np.mean(heading_mass <= m)) for m in RELIABILITY_LEVELS],
    }
    return {
        "frames": int(len(p.frame)),
        "episodes": int(len(np.unique(p.episode))),
        "nll": nll,
        "agent_position_error_m": _summary(np.linalg.norm(p.agent_pose[:, :2] - p.agent_mean, axis=-1)),
        "heading_error_deg": _summary(np.rad2deg(heading_error)),
        "object_position_error_m": {name: _summary(object_error[rows]) for name, rows in groups.items()},
        "object_error_by_steps_since_seen": error_by_steps_since_seen(p),
        "object_error_in_view_by_distance": error_by_distance_in_view(p),
        "objects_seen_by_sightings": coverage_by_sightings(p, object_d2, object_error),
        "coverage": coverage,
        "reliability": reliability,
    }


def stated_metrics(predictions: Predictions, stated: StatedParams, inputs: StatedInputs | None) -> dict[str, Any]:
    """The objects' NLL, 1/2/3-sigma coverage and reliability under their stated belief (``mor.lnet.stated``): the
    (calibrated) Gaussians of ``predictions`` with the lost probabilities and search belief of ``stated``; ``inputs``
    (of these predictions, ``stated_inputs``) is needed where any lost probability is above 0 or a search belief
    is fitted. Without either these are the Gaussian's own figures."""
    p = predictions
    d2 = squared_mahalanobis(p.object_truth, p.object_mean, p.object_tril)
    mass, log_p, searching = stated_truth(d2, log_sqrt_det(p.object_tril), stated.lost(p.confusable), inputs,
                                          stated.search_find)
    groups = _object_groups(p)
    return {"nll_objects": float(-log_p[p.present].mean()),
            "coverage": {f"objects_{name}": {f"{k}sigma": float(np.mean(mass[groups[name]] <= NOMINAL_2D[k]))
                                             if groups[name].any() else float("nan") for k in SIGMAS}
                         for name in ("seen", "unseen", "all")},
            "reliability_objects_seen": [float(np.mean(mass[groups["seen"]] <= level))
                                         for level in RELIABILITY_LEVELS],
            "reliability_objects_unseen": [float(np.mean(mass[groups["unseen"]] <= level))
                                           for level in RELIABILITY_LEVELS],
            "searching_share": {name: float(np.mean(searching[groups[name]])) if groups[name].any() else float("nan")
                                for name in ("seen", "unseen")}}


def calibrated_metrics(predictions: Predictions, fitted: FittedCalibration, inputs: StatedInputs | None = None
                       ) -> dict[str, Any]:
    """``metrics`` of ``predictions`` after the calibration's scales, with the objects' stated belief
    (``stated_metrics``, under the calibration's lost probabilities and search belief) as ``stated``."""
    calibrated = fitted.scales.apply(predictions, predictions.confusable)
    return {**metrics(calibrated), "stated": stated_metrics(calibrated, fitted.stated, inputs)}


def headline(scored: dict[str, Any]) -> dict[str, Any]:
    """The figures the model card compares tracking rules and encoder precisions by, from ``metrics``."""
    errors = scored["object_position_error_m"]
    return {"objects_seen_median_m": errors["seen"]["median"], "objects_visible_median_m": errors["visible"]["median"],
            "agent_median_m": scored["agent_position_error_m"]["median"],
            "heading_median_deg": scored["heading_error_deg"]["median"], "nll_objects": scored["nll"]["objects"],
            "nll_heading": scored["nll"]["heading"], "coverage_objects_seen": scored["coverage"]["objects_seen"],
            "coverage_agent": scored["coverage"]["agent_position"], "coverage_heading": scored["coverage"]["heading"],
            **({"nll_objects_stated": scored["stated"]["nll_objects"],
                "coverage_objects_seen_stated": scored["stated"]["coverage"]["objects_seen"],
                "coverage_objects_unseen_stated": scored["stated"]["coverage"]["objects_unseen"]} if "stated" in scored
               else {})}
