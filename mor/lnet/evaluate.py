"""Evaluating the L-Net on whole episodes: errors, NLL, coverage of the stated uncertainty, calibration.

Coverage: a 2-D Gaussian's k-sigma region {d^2 <= k^2} (d = Mahalanobis distance) holds 1 - exp(-k^2 / 2) of the
mass: 39.3%, 86.5%, 98.9% for k = 1, 2, 3. For the heading (1-D) the k-sigma-equivalent region is the central
von Mises interval holding the 1-D normal's mass for k: 68.3%, 95.4%, 99.7%.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np
import torch
from scipy import optimize, stats
from torch.utils.data import DataLoader
from tqdm import tqdm

from mor.data.sequences import SequenceWindows
from mor.data.visibility import visible_per_frame
from mor.lnet.calibration import Calibration
from mor.lnet.likelihoods import gaussian_nll, log_i0, mahalanobis_squared, von_mises_nll
from mor.lnet.model import LNet
from mor.lnet.train import run_model, to_device
from mor.sim.geometry import wrap_angle

SIGMAS = (1, 2, 3)
NOMINAL_2D = {k: float(1.0 - np.exp(-k * k / 2.0)) for k in SIGMAS}
NOMINAL_1D = {k: float(stats.norm.cdf(k) - stats.norm.cdf(-k)) for k in SIGMAS}
RELIABILITY_LEVELS = np.linspace(0.05, 0.95, 19)


@dataclass
class Predictions:
    """The LSTM's world-frame estimates and the truth, frame by frame over many episodes (N frames, K slots).

    agent_pose (N, 3) truth; agent_mean (N, 2); agent_tril (N, 2, 2); heading (N,); kappa (N,);
    object_truth (N, K, 2); object_mean (N, K, 2); object_tril (N, K, 2, 2); present (N, K) slot in use;
    seen (N, K) the object was visible or held at or before this frame; episode (N,); frame (N,).
    """

    agent_pose: np.ndarray
    agent_mean: np.ndarray
    agent_tril: np.ndarray
    heading: np.ndarray
    kappa: np.ndarray
    object_truth: np.ndarray
    object_mean: np.ndarray
    object_tril: np.ndarray
    present: np.ndarray
    seen: np.ndarray
    episode: np.ndarray
    frame: np.ndarray

    def select(self, rows: np.ndarray) -> Predictions:
        return Predictions(*(getattr(self, f.name)[rows] for f in fields(self)))


def seen_so_far(agent_pose: np.ndarray, objects: np.ndarray, held: np.ndarray, present: np.ndarray) -> np.ndarray:
    """(T, K) whether each object was visible to the camera (``rules.visible``) or held at or before frame t."""
    n = int(present.sum())
    now = np.zeros(objects.shape[:2], dtype=bool)
    now[:, :n] = visible_per_frame(agent_pose, objects[:, :n], held) | (held[:, None] == np.arange(n))
    return np.maximum.accumulate(now, axis=0)


@torch.no_grad()
def predict(model: LNet, root: Path, max_episodes: int, device: torch.device, progress: bool = True) -> Predictions:
    """Run the L-Net over whole episodes of the split at ``root`` (the first ``max_episodes``)."""
    episodes = SequenceWindows(root, window=None)
    count = min(max_episodes, len(episodes))
    parts: dict[str, list[np.ndarray]] = {f.name: [] for f in fields(Predictions)}
    model.eval()
    loader = DataLoader(torch.utils.data.Subset(episodes, range(count)), batch_size=1)
    for index, batch in enumerate(tqdm(loader, total=count, desc="predict", unit="ep", disable=not progress)):
        _, tracked, _ = run_model(model, to_device(batch, device))
        estimate = {name: value[0] for name, value in tracked.to_numpy().items()}
        truth = {name: batch[name][0].numpy() for name in ("agent_pose", "object_positions", "held")}
        present = batch["object_mask"][0].numpy()
        length = len(truth["agent_pose"])
        parts["agent_pose"].append(truth["agent_pose"])
        parts["object_truth"].append(truth["object_positions"])
        parts["present"].append(np.broadcast_to(present, (length, len(present))))
        parts["seen"].append(seen_so_far(truth["agent_pose"], truth["object_positions"], truth["held"], present))
        parts["episode"].append(np.full(length, index))
        parts["frame"].append(np.arange(length))
        for name in ("agent_mean", "agent_tril", "heading", "kappa"):
            parts[name].append(estimate[name])
        parts["object_mean"].append(estimate["object_mean"])
        parts["object_tril"].append(estimate["object_tril"])
    return Predictions(**{name: np.concatenate(values) for name, values in parts.items()})


# ---- calibration ------------------------------------------------------------------------------------------------
def _d2(truth: np.ndarray, mean: np.ndarray, tril: np.ndarray) -> np.ndarray:
    return mahalanobis_squared(*(torch.as_tensor(a, dtype=torch.float64) for a in (truth, mean, tril))).numpy()


def fit_calibration(predictions: Predictions) -> Calibration:
    """Scales that minimize the NLL on ``predictions``: for a 2-D Gaussian scaled by s, the optimum is
    s^2 = mean(d^2) / 2; the heading's kappa multiplier is found numerically."""
    agent_d2 = _d2(predictions.agent_pose[:, :2], predictions.agent_mean, predictions.agent_tril)
    object_d2 = _d2(predictions.object_truth, predictions.object_mean, predictions.object_tril)[predictions.present]
    error = torch.as_tensor(wrap_angle(predictions.agent_pose[:, 2] - predictions.heading))
    kappa = torch.as_tensor(predictions.kappa, dtype=torch.float64)

    def heading_nll(log_scale: float) -> float:
        scaled = kappa * float(np.exp(log_scale))
        return float((-scaled * torch.cos(error) + log_i0(scaled)).mean())

    log_scale = optimize.minimize_scalar(heading_nll, bounds=(-8.0, 8.0), method="bounded").x
    return Calibration(float(np.sqrt(agent_d2.mean() / 2.0)), float(np.sqrt(object_d2.mean() / 2.0)),
                       float(np.exp(log_scale)))


# ---- metrics ----------------------------------------------------------------------------------------------------
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


def metrics(predictions: Predictions) -> dict[str, Any]:
    """NLL, errors, k-sigma coverage and reliability curves of ``predictions`` (JSON-ready)."""
    p = predictions
    as_t = lambda a: torch.as_tensor(a, dtype=torch.float64)  # noqa: E731
    agent_d2 = _d2(p.agent_pose[:, :2], p.agent_mean, p.agent_tril)
    object_d2 = _d2(p.object_truth, p.object_mean, p.object_tril)
    heading_error = np.abs(wrap_angle(p.agent_pose[:, 2] - p.heading))
    heading_mass = heading_central_mass(heading_error, p.kappa)
    seen = p.present & p.seen
    object_error = np.linalg.norm(p.object_truth - p.object_mean, axis=-1)
    nll = {
        "agent_position": float(gaussian_nll(as_t(p.agent_pose[:, :2]), as_t(p.agent_mean), as_t(p.agent_tril)).mean()),
        "heading": float(von_mises_nll(as_t(p.agent_pose[:, 2]), as_t(p.heading), as_t(p.kappa)).mean()),
        "objects": float(gaussian_nll(as_t(p.object_truth), as_t(p.object_mean), as_t(p.object_tril))[
            torch.as_tensor(p.present)].mean()),
    }
    coverage = {
        "agent_position": {f"{k}sigma": float(np.mean(agent_d2 <= k * k)) for k in SIGMAS},
        "objects_seen": {f"{k}sigma": float(np.mean(object_d2[seen] <= k * k)) for k in SIGMAS},
        "objects_all": {f"{k}sigma": float(np.mean(object_d2[p.present] <= k * k)) for k in SIGMAS},
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
        "object_position_error_m": {"seen": _summary(object_error[seen]), "all": _summary(object_error[p.present])},
        "coverage": coverage,
        "reliability": reliability,
    }
