"""Fitting the calibration on validation predictions (``mor.lnet.predictions``): the filter's measurement noise
(``fit_measurement_noise``, by the error of the beliefs), then the scales of the stated uncertainty and, with the
arena, the stated belief's lost probabilities and search belief (``fit_calibration``, by the NLL or the coverage;
``mor.lnet.lost``, ``mor.lnet.search``). ``calibrate`` does both for the model's tracking rule and returns the
``FittedCalibration`` that ``mor calibrate-lnet`` writes to ``calibration.json``.

Shapes: N frames, K object slots, R rows (the frames and slots of one group). Positions in metres.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np
import torch
from scipy import optimize

from mor.lnet.calibration import Calibration
from mor.lnet.calibration_file import FittedCalibration
from mor.lnet.evaluate import (
    NOMINAL_1D,
    NOMINAL_2D,
    SIGMAS,
    heading_central_mass,
    seen_object_mean_error,
    squared_mahalanobis,
)
from mor.lnet.likelihoods import log_i0
from mor.lnet.lost import fit_nll, log_sqrt_det, region_mass
from mor.lnet.model import LNet, PoseEstimate
from mor.lnet.predict import track_episodes
from mor.lnet.predictions import Predictions
from mor.lnet.search import FIND_GRID, SearchLooks, search_log_density, search_mass
from mor.lnet.stated import StatedInputs, StatedParams, stated_inputs
from mor.sim.arena import Arena
from mor.sim.geometry import wrap_angle


def _scale(d2: np.ndarray) -> float | None:
    """The NLL-optimal multiplier of a 2-D Gaussian's standard deviations, s^2 = mean(d^2) / 2 (None: no rows)."""
    return float(np.sqrt(d2.mean() / 2.0)) if d2.size else None


#: The multipliers ``criterion="coverage"`` chooses from: 1/16 to 16 in steps of about 2.3%.
COVERAGE_GRID = np.exp(np.linspace(np.log(1 / 16), np.log(16), 241))


def _closest_coverage(coverage: Callable[[float], np.ndarray], nominal: np.ndarray) -> float:
    """The multiplier of ``COVERAGE_GRID`` whose 1/2/3-sigma coverage (``coverage(m)``, (3,)) deviates least from
    ``nominal`` (3,) at its worst level (the smallest such multiplier where several tie)."""
    worst = [float(np.max(np.abs(coverage(m) - nominal))) for m in COVERAGE_GRID]
    return float(COVERAGE_GRID[int(np.argmin(worst))])


def _coverage_scale(d2: np.ndarray) -> float | None:
    """The multiplier s of a 2-D Gaussian's standard deviations whose 1/2/3-sigma coverage (d^2 / s^2 <= k^2) is
    closest to nominal (None: no rows)."""
    if not d2.size:
        return None
    ordered, levels = np.sort(d2), np.array([k * k for k in SIGMAS], np.float64)
    nominal = np.array([NOMINAL_2D[k] for k in SIGMAS])
    return _closest_coverage(lambda s: np.searchsorted(ordered, levels * s * s, side="right") / ordered.size,
                             nominal)


def _nll_kappa_scale(error: np.ndarray, kappa: np.ndarray) -> float:
    """The multiplier of the von Mises concentrations ``kappa`` that minimizes the heading NLL of ``error`` (rad)."""
    error_t, kappa_t = torch.as_tensor(error), torch.as_tensor(kappa, dtype=torch.float64)

    def heading_nll(log_scale: float) -> float:
        scaled = kappa_t * float(np.exp(log_scale))
        return float((-scaled * torch.cos(error_t) + log_i0(scaled)).mean())

    return float(np.exp(optimize.minimize_scalar(heading_nll, bounds=(-8.0, 8.0), method="bounded").x))


def _coverage_kappa_scale(error: np.ndarray, kappa: np.ndarray) -> float:
    """The multiplier of the von Mises concentrations ``kappa`` whose 1/2/3-sigma-equivalent coverage of
    ``error`` (rad) is closest to nominal."""
    nominal = np.array([NOMINAL_1D[k] for k in SIGMAS])
    return _closest_coverage(
        lambda m: (heading_central_mass(error, kappa * m)[:, None] <= nominal).mean(0), nominal)


#: The lost probabilities the coverage criterion chooses from (with a multiplier of ``COVERAGE_GRID``): 0 to 0.5.
LOST_GRID = np.linspace(0.0, 0.5, 26)


def _lost_fit(criterion: str, d2: np.ndarray, half_log_det: np.ndarray, share: np.ndarray, area: float
              ) -> tuple[float, float] | None:
    """(multiplier, lost probability) of a group of objects' Gaussians (rows (R,): squared Mahalanobis d2, log
    sqrt(det cov), ``ArenaShares.share``) by ``criterion`` (``mor.lnet.lost``); None: no rows."""
    if not d2.size:
        return None
    if criterion == "nll":
        return fit_nll(d2, half_log_det, area)
    nominal = np.array([NOMINAL_2D[k] for k in SIGMAS])
    worst = np.empty((len(COVERAGE_GRID), len(LOST_GRID)))  # as _closest_coverage, over (multiplier, weight)
    for i, multiplier in enumerate(COVERAGE_GRID):
        core = region_mass(d2 / (multiplier * multiplier), 0.0, share)
        mass = (1.0 - LOST_GRID)[:, None] * core + LOST_GRID[:, None] * share              # (W, R)
        worst[i] = np.abs((mass[..., None] <= nominal).mean(1) - nominal).max(1)
    best_multiplier, best_weight = np.unravel_index(int(np.argmin(worst)), worst.shape)
    return float(COVERAGE_GRID[best_multiplier]), float(LOST_GRID[best_weight])


#: How ``fit_calibration`` chooses each multiplier: the NLL's optimum, or the 1/2/3-sigma coverage closest to
#: nominal (the largest deviation of the three smallest).
CRITERIA = ("nll", "coverage")


def criterion_name(criterion: str, lost_objects: bool) -> str:
    """How ``calibration.json`` names a criterion: ``nll``, ``coverage``, or either with ``+lost`` (lost
    probabilities fitted too)."""
    return criterion + ("+lost" if lost_objects else "")


def _search_fit(criterion: str, looks: SearchLooks, rows: np.ndarray) -> float | None:
    """The search belief's one-look find probability (``FIND_GRID``) for the beliefs ``rows`` (N, K) by
    ``criterion``: the NLL's minimum, or the 1/2/3-sigma coverage closest to nominal; None: no rows."""
    if not rows.any():
        return None
    if criterion == "nll":
        return float(FIND_GRID[int(np.argmin([-search_log_density(looks, q)[rows].mean() for q in FIND_GRID]))])
    nominal = np.array([NOMINAL_2D[k] for k in SIGMAS])
    worst = [np.abs((search_mass(looks, q)[rows][:, None] <= nominal).mean(0) - nominal).max() for q in FIND_GRID]
    return float(FIND_GRID[int(np.argmin(worst))])


def fit_calibration(predictions: Predictions, criterion: str = "nll", inputs: StatedInputs | None = None
                    ) -> FittedCalibration:
    """The scales of the stated uncertainty fitted on ``predictions``, per group of objects seen earlier
    (confusable: sharing their colour with another and not held; the others), for the agent and for the heading's
    kappa, by ``criterion``: ``nll`` minimizes the NLL (for a 2-D Gaussian scaled by s the optimum is s^2 =
    mean(d^2) / 2; kappa's multiplier is found numerically); ``coverage`` brings the 1/2/3-sigma coverage closest
    to nominal (``COVERAGE_GRID``). With ``inputs`` (of these predictions: ``stated_inputs``) each group of objects
    also gets a lost probability, fitted with its multiplier by the same criterion (the NLL by
    expectation-maximization, ``mor.lnet.lost.fit_nll``; the coverage over ``COVERAGE_GRID`` x ``LOST_GRID``,
    whose w stops at 0.5), and the search belief of the beliefs that have not found their object its find
    probability (``_search_fit``, on those beliefs, whichever objects they are: the tracker cannot tell): the
    stated belief's parameters (``mor.lnet.stated.StatedParams``). The objects' multipliers are fitted on the
    objects seen earlier only: a belief of an object not yet seen is the arena's prior, whatever the PoseNet says,
    so its errors would only pull the seen objects' fit (their coverage is reported on its own). The tracking
    settings are left at their defaults: the caller records the ones the predictions were tracked with
    (``tracked_calibration``)."""
    if criterion not in CRITERIA:
        raise ValueError(f"calibration criterion: expected one of {CRITERIA}, got {criterion!r}")
    p = predictions
    scale, kappa_scale = (_scale, _nll_kappa_scale) if criterion == "nll" else (_coverage_scale, _coverage_kappa_scale)
    agent_d2 = squared_mahalanobis(p.agent_pose[:, :2], p.agent_mean, p.agent_tril)
    object_d2 = squared_mahalanobis(p.object_truth, p.object_mean, p.object_tril)
    seen = p.present & p.seen  # the beliefs of objects not yet seen are the prior's (see the docstring)
    groups = (seen & ~p.confusable, seen & p.confusable)
    if inputs is None:
        own, shared = ((fitted, 0.0) if (fitted := scale(object_d2[rows])) is not None else None for rows in groups)
    else:
        half_log_det, shares = log_sqrt_det(p.object_tril), inputs.shares
        own, shared = (_lost_fit(criterion, object_d2[rows], half_log_det[rows], shares.share[rows], shares.area)
                       for rows in groups)
    if own is None:  # every object shares its colour: one group
        own, shared = shared or (1.0, 0.0), None
    heading = kappa_scale(wrap_angle(p.agent_pose[:, 2] - p.heading), np.asarray(p.kappa, np.float64))
    stated = StatedParams(own[1], shared[1] if inputs is not None and shared else None,
                          None if inputs is None else _search_fit(criterion, inputs.looks, inputs.not_found))
    return FittedCalibration(
        Calibration(scale(agent_d2) or 1.0, own[0], heading, shared_colour_scale=shared and shared[0]),
        stated=stated if inputs is None else stated.chosen_from(inputs.settings))


#: The measurement-noise multipliers ``fit_measurement_noise`` chooses from: powers of two, 1/64 to 64.
NOISE_GRID = tuple(2.0 ** k for k in range(-6, 7))


def fit_measurement_noise(model: LNet, episodes: list[tuple[PoseEstimate, dict[str, torch.Tensor]]],
                          rounds: int = 2) -> tuple[tuple[float, float], dict[str, float]]:
    """The filter's measurement-noise multipliers (own colour, shared colour) from ``NOISE_GRID`` that minimize
    ``seen_object_mean_error`` of the tracked ``episodes`` (``frame_estimates``), by coordinate search from (1, 1):
    ``rounds`` passes over each multiplier in turn. The noise decides where the beliefs go, so it is chosen by
    their error; how wide they are stated is the calibration's scales' job (``fit_calibration``, by the NLL).
    Returns the choice (left set on the model) and every tried pair's error ("own x shared": m). The LSTM tracker
    has no such noise: (1, 1) and no tries."""
    if model.config.tracker != "filter":
        return (1.0, 1.0), {}
    tried: dict[tuple[float, float], float] = {}

    def use(noise: tuple[float, float]) -> None:
        model.use_tracking(replace(model.tracking, noise_own=noise[0], noise_shared=noise[1]))

    def error(noise: tuple[float, float]) -> float:
        if noise not in tried:
            use(noise)
            tried[noise] = seen_object_mean_error(track_episodes(model, episodes))
        return tried[noise]

    best = (1.0, 1.0)
    for _ in range(rounds):
        best = min(((value, best[1]) for value in NOISE_GRID), key=error)
        best = min(((best[0], value) for value in NOISE_GRID), key=error)
    use(best)
    return best, {f"{own:g} x {shared:g}": value for (own, shared), value in tried.items()}


def calibrate(model: LNet, episodes: list[tuple[PoseEstimate, dict[str, torch.Tensor]]], criterion: str = "nll",
              arena: Arena | None = None, settings: StatedParams | None = None
              ) -> tuple[Predictions, FittedCalibration, dict[str, float], StatedInputs | None]:
    """Calibrate ``model`` (with its current tracking rule) on validation episodes (``frame_estimates``): the
    filter's measurement noise (``fit_measurement_noise``), then the scales (``fit_calibration`` by
    ``criterion``; with ``arena``, also the objects' lost probabilities and search belief, made with the chosen
    settings of ``settings``, ``StatedParams.CHOSEN``: None, the defaults). Returns the uncalibrated predictions
    with the chosen noise, the calibration (recording the rule, the noise and ``settings``' chosen settings, with
    ``arena`` or without), the noise search's tries and the predictions' ``StatedInputs`` (None without
    ``arena``)."""
    settings = settings or StatedParams()
    _, tried = fit_measurement_noise(model, episodes)
    predictions = track_episodes(model, episodes)
    inputs = None if arena is None else stated_inputs(predictions, arena, settings)
    fitted = tracked_calibration(model, predictions, criterion, inputs)
    return predictions, replace(fitted, stated=fitted.stated.chosen_from(settings)), tried, inputs


def tracked_calibration(model: LNet, predictions: Predictions, criterion: str, inputs: StatedInputs | None = None
                        ) -> FittedCalibration:
    """``fit_calibration`` of ``predictions`` by ``criterion`` (with lost probabilities and the search belief when
    ``inputs`` is given), recording the tracking settings (rule, measurement noise) ``model`` tracked them with."""
    return replace(fit_calibration(predictions, criterion, inputs), tracking=model.tracking)
