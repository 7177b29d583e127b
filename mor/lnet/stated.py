"""The stated belief: what a consumer of the L-Net states about each object, made from the tracker's output.

Per object, from the tracker's Gaussian (before calibration) and the calibration (``mor.lnet.calibration``):

- its Gaussian, calibrated;
- the probability that the belief is lost, the object anywhere in the arena instead (``mor.lnet.lost``), by group:
  objects of a colour of their own (``StatedParams.lost_own``) and confusable ones (``lost_shared``);
- whether the belief has found its object: not while its uncalibrated geometric-mean standard deviation is above
  ``StatedParams.not_found_sigma`` (``lnet.not_found_sigma``, 1 m: the filter's prior is about 1.7 m wide and one
  sighting brings a belief to tenths of a metre);
- for a belief not found yet, the search belief over where the camera has not looked (``mor.lnet.search``), each
  look finding the object with probability ``StatedParams.search_find`` (None: not fitted, such an object's stated
  belief is its Gaussian too), look counts capped at ``StatedParams.search_max_looks`` (``lnet.search_max_looks``).

The lost and search beliefs count points of the arena grid of ``StatedParams.arena_grid_spacing`` metres
(``lnet.arena_grid_spacing``, ``mor.lnet.lost.arena_grid``).

Its two consumers read it here: the streaming runner per step (``stated_estimates`` -> ``Estimates``, with the
search density where the loop keeps the looks, ``mor.lnet.streaming``) and evaluation per frame of a set of
predictions (``stated_inputs``, then ``stated_truth``: where the truth falls in the stated belief).

Shapes: N environments (or frames), n objects (K slots), M arena grid points. Positions in metres.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Any, ClassVar

import numpy as np
import torch

from mor.lnet.calibration import Calibration, confusable
from mor.lnet.lost import ArenaShares, arena_shares, log_density, region_mass
from mor.lnet.model import PoseEstimate
from mor.lnet.params import STATED_SETTINGS, LNetParams
from mor.lnet.predictions import Predictions
from mor.lnet.search import (
    SearchLooks,
    SearchMap,
    search_log_density,
    search_looks,
    search_mass,
)
from mor.sim.arena import Arena


def _chosen_default(name: str) -> Any:
    """A chosen setting's default: the profile's (``LNetParams``), the one place it is written."""
    return LNetParams.model_fields[name].default


@dataclass(frozen=True)
class StatedParams:
    """The stated belief's fitted parameters (``mor.lnet.calibration_fit``, stored in ``calibration.json``): the
    probability that an object's belief is lost for objects of their own colour (``lost_own``) and confusable ones
    (``lost_shared``, None: the same as ``lost_own``), each in [0, 1); the probability in [0, 1] that one look finds
    an object not found yet (``search_find``; None: no search belief); and, chosen not fitted (``CHOSEN``, each
    ``lnet.<name>`` in the profile): the width (m, geometric mean of the standard deviations, uncalibrated) above
    which a belief has not found its object (``not_found_sigma``), the look count above which the search belief
    counts a point as looked at that many times (``search_max_looks``) and the spacing (m) of the arena grid the
    lost and search beliefs count (``arena_grid_spacing``)."""

    #: The fields a run chooses in its profile rather than the calibration fitting them.
    CHOSEN: ClassVar[tuple[str, ...]] = STATED_SETTINGS

    lost_own: float = 0.0
    lost_shared: float | None = None
    search_find: float | None = None
    not_found_sigma: float = _chosen_default("not_found_sigma")
    search_max_looks: int = _chosen_default("search_max_looks")
    arena_grid_spacing: float = _chosen_default("arena_grid_spacing")

    def lost(self, confusable_mask: np.ndarray) -> np.ndarray:
        """(..., K) float64 the probability that each object's belief is lost, by group: confusable_mask (..., K)
        bool (``mor.lnet.calibration.confusable``)."""
        shared = self.lost_own if self.lost_shared is None else self.lost_shared
        return np.where(np.asarray(confusable_mask), shared, self.lost_own)

    def chosen_from(self, settings: StatedParams) -> StatedParams:
        """These parameters with the chosen settings (``CHOSEN``) of ``settings``."""
        return replace(self, **{name: getattr(settings, name) for name in self.CHOSEN})

    def search_map(self, arena: Arena, n_envs: int) -> SearchMap:
        """An empty ``SearchMap`` of ``n_envs`` environments in ``arena`` with these settings (the look cap and the
        grid's spacing in metres)."""
        return SearchMap(arena, n_envs, self.search_max_looks, self.arena_grid_spacing)


def not_found(object_tril: np.ndarray, sigma: float) -> np.ndarray:
    """(...) whether each belief (lower Cholesky factors (..., 2, 2), uncalibrated) has not found its object: wider
    than ``sigma`` metres (``StatedParams.not_found_sigma``)."""
    return np.sqrt(np.abs(object_tril[..., 0, 0] * object_tril[..., 1, 1])) > sigma


@dataclass(frozen=True)
class Estimates:
    """The stated belief of N environments with n objects each, one step (float32 numpy arrays, calibrated).

    agent_mean (N, 2) m; agent_cov (N, 2, 2) m^2; heading (N,) rad, the mean of a von Mises with concentration
    heading_kappa (N,); object_mean (N, n, 2) m; object_cov (N, n, 2, 2) m^2; object_lost (N, n) the probability
    that an object's belief is lost, the object anywhere in the arena instead (0 unless the calibration fitted it);
    object_searching (N, n) bool the belief has not found its object yet, so its stated belief is the search
    belief; search_density (N, M) the search belief's density (per m^2) at the arena grid's points
    (``SearchMap.grid``), where the loop keeps the looks and the calibration fitted ``search_find`` (else None);
    object_visible (N, n) the PoseNet's probability that each object is in view on this frame (its visibility head,
    trained on the simulator's rule ``mor.sim.rules.visible``; None for a model without the head).
    """

    agent_mean: np.ndarray
    agent_cov: np.ndarray
    heading: np.ndarray
    heading_kappa: np.ndarray
    object_mean: np.ndarray
    object_cov: np.ndarray
    object_lost: np.ndarray
    object_searching: np.ndarray
    search_density: np.ndarray | None = None
    object_visible: np.ndarray | None = None

    def where(self, take_other: np.ndarray, other: Estimates) -> Estimates:
        """Per environment, ``other``'s estimates where ``take_other`` (N,) bool is True, else these."""
        def pick(mine: np.ndarray | None, theirs: np.ndarray | None) -> np.ndarray | None:
            if mine is None or theirs is None:
                return None
            return np.where(np.reshape(take_other, (-1,) + (1,) * (mine.ndim - 1)), theirs, mine)

        return Estimates(*(pick(getattr(self, f.name), getattr(other, f.name)) for f in fields(self)))


def _covariance(tril: torch.Tensor) -> np.ndarray:
    return (tril @ tril.transpose(-1, -2)).float().cpu().numpy()


def stated_estimates(last: PoseEstimate, object_classes: np.ndarray, held: np.ndarray, calibration: Calibration,
                     params: StatedParams, search: SearchMap | None = None) -> Estimates:
    """The ``Estimates`` of the tracker's world-frame estimate of one step (``last``: (N, ...) tensors, the n
    objects of ``object_classes`` (N, n); ``held`` (N,): which object each environment holds, n or -1 for none),
    calibrated; ``search``: the environments' looks so far, this step's included (None: no search density)."""
    mask = confusable(object_classes, held)
    as_numpy = lambda t: t.float().cpu().numpy()  # noqa: E731
    searching = not_found(as_numpy(last.object_tril), params.not_found_sigma)  # judged on the uncalibrated belief
    visible = None if last.visibility_logit is None else as_numpy(torch.sigmoid(last.visibility_logit))
    last = calibration.apply(last, torch.as_tensor(mask, device=last.agent_mean.device))
    density = None if search is None or params.search_find is None else \
        search.density(params.search_find).astype(np.float32)
    return Estimates(as_numpy(last.agent_mean), _covariance(last.agent_tril), as_numpy(last.heading),
                     as_numpy(last.kappa), as_numpy(last.object_mean), _covariance(last.object_tril),
                     params.lost(mask).astype(np.float32), searching, density, visible)


@dataclass(frozen=True)
class StatedInputs:
    """What the objects' stated belief needs of a set of predictions beyond their Gaussians: the arena shares of
    the lost belief (``mor.lnet.lost``), the looks of the search belief (``mor.lnet.search``) and which beliefs
    have not found their object (N, K), judged on the uncalibrated beliefs; made with the chosen settings of
    ``settings`` (``StatedParams.CHOSEN``)."""

    shares: ArenaShares
    looks: SearchLooks
    not_found: np.ndarray
    settings: StatedParams

    def select(self, rows: np.ndarray) -> StatedInputs:
        """The inputs of the frames ``rows`` (as ``Predictions.select``)."""
        return replace(self, shares=self.shares.select(rows), looks=self.looks.select(rows),
                       not_found=self.not_found[rows])


def stated_inputs(predictions: Predictions, arena: Arena, settings: StatedParams) -> StatedInputs:
    """``StatedInputs`` of the present objects of ``predictions`` with the chosen settings of ``settings`` (its
    fitted fields are not read): which beliefs are not found is judged on their own uncalibrated width against
    ``not_found_sigma`` metres, the arena grid has ``arena_grid_spacing`` metres between points, look counts are
    capped at ``search_max_looks``."""
    p, spacing = predictions, settings.arena_grid_spacing
    return StatedInputs(arena_shares(p.object_truth, p.object_mean, p.object_tril, p.present, arena, spacing),
                        search_looks(p.agent_mean, p.heading, p.object_truth, p.episode, arena,
                                     settings.search_max_looks, spacing),
                        p.present & not_found(p.object_tril, settings.not_found_sigma), settings)


def stated_truth(d2: np.ndarray, half_log_det: np.ndarray, lost: np.ndarray, inputs: StatedInputs | None,
                 search_find: float | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where the truth falls in the stated belief, per frame and slot (N, K): (the mass of the belief's highest-
    density region that reaches the truth: inside the k-sigma-equivalent region when <= the k-sigma mass; log
    p(truth) per m^2; whether the search belief states it). d2, half_log_det: the truth's squared Mahalanobis
    distance and log sqrt(det cov) under the calibrated Gaussians; lost (N, K) the lost probabilities
    (``StatedParams.lost``); ``inputs`` (of these frames) is needed where any lost probability is above 0 or
    ``search_find`` is given, else the figures are the Gaussian's own."""
    if inputs is None and (np.any(lost > 0) or search_find is not None):
        raise ValueError("the stated belief: lost probabilities above 0 or a search belief need the StatedInputs")
    mass = region_mass(d2, lost, np.zeros(d2.shape) if inputs is None else inputs.shares.share)
    log_p = log_density(d2, half_log_det, lost, 1.0 if inputs is None else inputs.shares.area)
    if search_find is None:
        return mass, log_p, np.zeros(d2.shape, bool)
    searching = inputs.not_found
    return (np.where(searching, search_mass(inputs.looks, search_find), mass),
            np.where(searching, search_log_density(inputs.looks, search_find), log_p), searching)
