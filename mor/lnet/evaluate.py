"""Evaluating the L-Net on whole episodes: errors, NLL, coverage of the stated uncertainty, calibration.

Coverage: a 2-D Gaussian's k-sigma region {d^2 <= k^2} (d = Mahalanobis distance) holds 1 - exp(-k^2 / 2) of the
mass: 39.3%, 86.5%, 98.9% for k = 1, 2, 3. For the heading (1-D) the k-sigma-equivalent region is the central
von Mises interval holding the 1-D normal's mass for k: 68.3%, 95.4%, 99.7%.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from pathlib import Path
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from scipy import optimize, stats
from torch.utils.data import DataLoader
from tqdm import tqdm

import mor.sim  # noqa: F401 - registers the environments
from mor.data.schema import MAX_OBJECTS
from mor.data.sequences import SequenceWindows
from mor.lnet.calibration import Calibration, confusable
from mor.lnet.likelihoods import gaussian_nll, log_i0, mahalanobis_squared, von_mises_nll
from mor.lnet.loss import previous_actions
from mor.lnet.lost import ArenaShares, arena_shares, fit_nll, log_density, region_mass
from mor.lnet.search import FIND_GRID, SearchLooks, not_found, search_log_density, search_looks, search_mass
from mor.lnet.model import ESTIMATE_FIELDS, LNet, PoseEstimate
from mor.lnet.runtime import LNetRunner
from mor.sim.arena import Arena
from mor.sim.config import SimConfig
from mor.sim.geometry import wrap_angle
from mor.sim.rollout import episode_seed, make_policy
from mor.sim.rules import PICK_RANGE, visible

LIVE_ENV = "MOR/Rearrange-v0"

SIGMAS = (1, 2, 3)
NOMINAL_2D = {k: float(1.0 - np.exp(-k * k / 2.0)) for k in SIGMAS}
NOMINAL_1D = {k: float(stats.norm.cdf(k) - stats.norm.cdf(-k)) for k in SIGMAS}
RELIABILITY_LEVELS = np.linspace(0.05, 0.95, 19)


@dataclass
class Predictions:
    """The tracker's world-frame estimates and the truth, frame by frame over many episodes (N frames, K slots).

    agent_pose (N, 3) truth; agent_mean (N, 2); agent_tril (N, 2, 2); heading (N,); kappa (N,);
    object_truth (N, K, 2); object_mean (N, K, 2); object_tril (N, K, 2, 2); present (N, K) slot in use;
    visible (N, K) in view now (``rules.visible``); since_seen (N, K) frames since the object was last visible or
    held (0: now; -1: not yet in this episode); sightings (N, K) frames of the episode so far (this one included)
    in which the object was in view; held (N,) index or -1; episode (N,); frame (N,); confusable (N, K) the
    object shares its colour with another of the episode (``mor.sim.catalog.shares_colour``) and is not held.
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
    visible: np.ndarray
    since_seen: np.ndarray
    sightings: np.ndarray
    held: np.ndarray
    episode: np.ndarray
    frame: np.ndarray
    confusable: np.ndarray

    @property
    def seen(self) -> np.ndarray:
        """(N, K) the object was visible or held at or before this frame."""
        return self.since_seen >= 0

    def select(self, rows: np.ndarray) -> Predictions:
        return Predictions(*(getattr(self, f.name)[rows] for f in fields(self)))


def steps_since_seen(visible: np.ndarray, held: np.ndarray) -> np.ndarray:
    """(T, K) frames since each object was last visible or held (0 on such a frame; -1 before the first).

    visible (T, K) bool; held (T,) index or -1."""
    now = visible | (held[:, None] == np.arange(visible.shape[1]))
    t = np.arange(len(now))[:, None]
    last = np.maximum.accumulate(np.where(now, t, -1), axis=0)
    return np.where(last >= 0, t - last, -1)


def episode_predictions(estimate: dict[str, np.ndarray], agent_pose: np.ndarray, object_positions: np.ndarray,
                        held: np.ndarray, visible: np.ndarray, classes: np.ndarray, episode: int) -> Predictions:
    """One episode's ``Predictions`` from the tracker's estimates (``PoseEstimate.to_numpy`` of one episode,
    (T, ...)) and the truth: agent_pose (T, 3), object_positions (T, K, 2), held (T,), visible (T, K), classes (K,)
    the slots' class ids (-1: empty)."""
    length = len(agent_pose)
    present = classes >= 0
    return Predictions(
        agent_pose=agent_pose, agent_mean=estimate["agent_mean"], agent_tril=estimate["agent_tril"],
        heading=estimate["heading"], kappa=estimate["kappa"], object_truth=object_positions,
        object_mean=estimate["object_mean"], object_tril=estimate["object_tril"],
        present=np.broadcast_to(present, (length, len(present))), visible=visible,
        since_seen=steps_since_seen(visible, held), sightings=np.cumsum(visible, axis=0), held=held,
        episode=np.full(length, episode),
        frame=np.arange(length), confusable=confusable(classes, held))


def story(predictions: Predictions, n_frames: int = 6) -> tuple[int, list[int]]:
    """An episode and ``n_frames`` frames of it that show the tracker at work: the first episode with a pick
    followed by a drop, at the start, when the carried object first comes into view, when it is picked, while it
    is carried, when it is dropped, and at the end. Without such an episode: the first one, evenly spaced."""
    p = predictions
    for episode in np.unique(p.episode):
        rows = np.flatnonzero(p.episode == episode)
        held, visible = p.held[rows], p.visible[rows]
        picks = np.flatnonzero((held[1:] >= 0) & (held[:-1] < 0)) + 1
        for pick in picks:
            drops = np.flatnonzero((held[pick + 1:] < 0)) + pick + 1
            if len(drops):
                slot, drop = int(held[pick]), int(drops[0])
                first_seen = int(np.argmax(visible[:, slot])) if visible[:, slot].any() else 0
                chosen = [0, min(first_seen, pick), pick, (pick + drop) // 2, drop, len(rows) - 1]
                return int(episode), sorted(set(chosen))
    first = np.flatnonzero(p.episode == p.episode[0])
    return int(p.episode[0]), np.linspace(0, len(first) - 1, n_frames).round().astype(int).tolist()


def concatenate(parts: list[Predictions]) -> Predictions:
    return Predictions(*(np.concatenate([getattr(p, f.name) for p in parts]) for f in fields(Predictions)))


#: What ``frame_estimates`` keeps of an episode besides the PoseNet's estimates (no images: they would not fit).
_EPISODE_FIELDS = ("agent_pose", "object_positions", "held", "visible", "object_classes", "actions")


@torch.no_grad()
def frame_estimates(model: LNet, root: Path, max_episodes: int, device: torch.device, progress: bool = True
                    ) -> list[tuple[PoseEstimate, dict[str, torch.Tensor]]]:
    """The PoseNet over whole episodes of the split at ``root`` (the first ``max_episodes``): per episode its
    estimates (1, T, ...) and the episode's truth and inputs (``_EPISODE_FIELDS``, (1, T, ...)), ready for
    ``track_episodes`` (the tracker replayed without the PoseNet, e.g. once per tracking setting)."""
    episodes = SequenceWindows(root, window=None)
    count = min(max_episodes, len(episodes))
    model.eval()
    loader = DataLoader(torch.utils.data.Subset(episodes, range(count)), batch_size=1)
    return [(model.frame_estimates(batch["images"].to(device), batch["object_classes"].to(device)),
             {name: batch[name].to(device) for name in _EPISODE_FIELDS})
            for batch in tqdm(loader, total=count, desc="PoseNet", unit="ep", disable=not progress)]


def _padded(tensors: list[torch.Tensor], length: int) -> torch.Tensor:
    """(1, T_i, ...) each -> (n, length, ...), each repeating its last frame (the trackers are causal)."""
    return torch.cat([torch.cat([t, t[:, -1:].expand(1, length - t.shape[1], *t.shape[2:])], 1) for t in tensors])


@torch.no_grad()
def track_episodes(model: LNet, episodes: list[tuple[PoseEstimate, dict[str, torch.Tensor]]],
                   batch_size: int = 64) -> Predictions:
    """The model's tracker over ``frame_estimates``' episodes, ``batch_size`` episodes at a time (padded to the
    longest), with the model's current tracking settings -> ``Predictions`` (episodes numbered in order)."""
    model.eval()
    parts = []
    for first in range(0, len(episodes), batch_size):
        chunk = episodes[first:first + batch_size]
        length = max(truth["held"].shape[1] for _, truth in chunk)
        single = PoseEstimate(*(_padded([getattr(e, name) for e, _ in chunk], length) for name in ESTIMATE_FIELDS),
                              frame="ego", visibility_logit=None if chunk[0][0].visibility_logit is None else
                              _padded([e.visibility_logit for e, _ in chunk], length))
        truth = {name: _padded([t[name] for _, t in chunk], length) if name != "object_classes" else
                 torch.cat([t[name] for _, t in chunk]) for name in _EPISODE_FIELDS}
        tracked, _ = model.track(single, truth["object_classes"], truth["held"], previous_actions(truth["actions"]))
        estimate = tracked.to_numpy()
        for i, (_, episode) in enumerate(chunk):
            steps = episode["held"].shape[1]
            parts.append(episode_predictions(
                {name: value[i, :steps] for name, value in estimate.items()},
                *(episode[name][0].cpu().numpy() for name in ("agent_pose", "object_positions", "held", "visible",
                                                              "object_classes")), first + i))
    return concatenate(parts)


def predict(model: LNet, root: Path, max_episodes: int, device: torch.device, progress: bool = True) -> Predictions:
    """Run the L-Net over whole episodes of the split at ``root`` (the first ``max_episodes``)."""
    return track_episodes(model, frame_estimates(model, root, max_episodes, device, progress))


def predict_live(runner: LNetRunner, sim: SimConfig, policy: str, episodes: int, seed: int, n_envs: int = 8,
                 horizon: int | None = None, progress: bool = True) -> Predictions:
    """Run ``episodes`` Rearrange episodes driven by ``policy`` (``oracle`` or ``random``) in ``n_envs``
    environments at once, tracked by the streaming step, with the truth from ``info`` and visibility by
    ``rules.visible``; episode ``i`` starts from ``reset(seed=episode_seed(seed, i))``. horizon: the env's
    (None: Rearrange's own, 1000 steps)."""
    envs = [gym.make(LIVE_ENV, horizon=horizon, **sim.model_dump()) for _ in range(min(n_envs, episodes))]
    policies = [make_policy(policy, env, seed + i) for i, env in enumerate(envs)]
    next_episode, parts = 0, []
    records: list[dict[str, list] | None] = [None] * len(envs)
    observations: list[dict] = [{}] * len(envs)
    infos: list[dict] = [{}] * len(envs)
    state, previous = runner.initial_state(len(envs)), np.full(len(envs), -1)
    bar = tqdm(total=episodes, desc=f"predict ({policy})", unit="ep", disable=not progress)

    def start(i: int) -> None:
        nonlocal next_episode
        if hasattr(policies[i], "reset"):
            policies[i].reset()
        observations[i], infos[i] = envs[i].reset(seed=episode_seed(seed, next_episode))
        records[i] = {"index": next_episode, "classes": np.asarray(observations[i]["object_classes"]), "estimates": [],
                      "truth": []}
        next_episode += 1

    for i in range(len(envs)):
        start(i)
    while any(r is not None for r in records):
        tracked, state = runner.track(np.stack([o["image"] for o in observations]),
                                      np.stack([o["object_classes"] for o in observations]),
                                      np.array([o["held"] for o in observations]), previous, state)
        estimate = tracked.to_numpy()
        done = np.zeros(len(envs), dtype=bool)
        for i, env in enumerate(envs):
            record = records[i]
            if record is None:
                continue  # this env has no episode left; its frames are ignored
            world = env.unwrapped.state
            record["estimates"].append({name: value[i, 0] for name, value in estimate.items()})
            record["truth"].append((infos[i]["agent_pose"], infos[i]["object_positions"], infos[i]["held"],
                                    [visible(world, k) for k in range(world.n_objects)]))
            if record.get("ended"):  # its last frame (after the last action) is recorded too, as in the dataset
                parts.append(_live_episode(record))
                bar.update(1)
                records[i], done[i], previous[i] = None, True, -1
                if next_episode < episodes:
                    start(i)
                continue
            action = policies[i](observations[i], infos[i])
            observations[i], _, terminated, truncated, infos[i] = env.step(action)
            previous[i] = action
            record["ended"] = terminated or truncated
        state = runner.reset(state, done)
    bar.close()
    for env in envs:
        env.close()
    return concatenate(sorted(parts, key=lambda p: p.episode[0]))


def _live_episode(record: dict[str, Any]) -> Predictions:
    """A finished live episode's records -> ``Predictions`` with the objects padded to MAX_OBJECTS slots."""
    estimate = {name: np.stack([e[name] for e in record["estimates"]]) for name in record["estimates"][0]}
    poses, objects, held, seen_now = (np.asarray(column) for column in zip(*record["truth"], strict=True))
    n = objects.shape[1]
    pad = ((0, 0), (0, MAX_OBJECTS - n))
    return episode_predictions(estimate, poses, np.pad(objects, (*pad, (0, 0))), held,
                               np.pad(seen_now.astype(bool), pad),
                               np.pad(record["classes"], (0, MAX_OBJECTS - n), constant_values=-1), record["index"])


# ---- calibration ------------------------------------------------------------------------------------------------
def _d2(truth: np.ndarray, mean: np.ndarray, tril: np.ndarray) -> np.ndarray:
    return mahalanobis_squared(*(torch.as_tensor(a, dtype=torch.float64) for a in (truth, mean, tril))).numpy()


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


def _half_log_det(tril: np.ndarray) -> np.ndarray:
    """log sqrt(det cov) of lower Cholesky factors (..., 2, 2)."""
    return np.log(np.abs(tril[..., 0, 0])) + np.log(np.abs(tril[..., 1, 1]))


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
                    ) -> Calibration:
    """Multipliers of the stated uncertainty fitted on ``predictions``, per group of objects seen earlier
    (confusable: sharing their colour with another and not held; the others), for the agent and for the heading's
    kappa, by ``criterion``: ``nll`` minimizes the NLL (for a 2-D Gaussian scaled by s the optimum is s^2 =
    mean(d^2) / 2; kappa's multiplier is found numerically); ``coverage`` brings the 1/2/3-sigma coverage closest
    to nominal (``COVERAGE_GRID``). With ``inputs`` (of these predictions: ``stated_inputs``) each group of objects
    also gets a lost probability, fitted with its multiplier by the same criterion (the NLL by
    expectation-maximization, ``mor.lnet.lost.fit_nll``; the coverage over ``COVERAGE_GRID`` x ``LOST_GRID``,
    whose w stops at 0.5), and the search belief of the beliefs that have not found their object its find
    probability (``_search_fit``, on those beliefs, whichever objects they are: the tracker cannot tell). The objects' multipliers are fitted on the objects seen earlier only: a belief of an object not yet seen
    is the arena's prior, whatever the PoseNet says, so its errors would only pull the seen objects' fit (their
    coverage is reported on its own). The tracking settings (rule, measurement noise) are left at their defaults:
    the caller records the ones the predictions were tracked with."""
    if criterion not in CRITERIA:
        raise ValueError(f"calibration criterion: expected one of {CRITERIA}, got {criterion!r}")
    p = predictions
    scale, kappa_scale = (_scale, _nll_kappa_scale) if criterion == "nll" else (_coverage_scale, _coverage_kappa_scale)
    agent_d2 = _d2(p.agent_pose[:, :2], p.agent_mean, p.agent_tril)
    object_d2 = _d2(p.object_truth, p.object_mean, p.object_tril)
    seen = p.present & p.seen  # the beliefs of objects not yet seen are the prior's (see the docstring)
    groups = (seen & ~p.confusable, seen & p.confusable)
    if inputs is None:
        own, shared = ((fitted, 0.0) if (fitted := scale(object_d2[rows])) is not None else None for rows in groups)
    else:
        half_log_det, shares = _half_log_det(p.object_tril), inputs.shares
        own, shared = (_lost_fit(criterion, object_d2[rows], half_log_det[rows], shares.share[rows], shares.area)
                       for rows in groups)
    if own is None:  # every object shares its colour: one group
        own, shared = shared or (1.0, 0.0), None
    heading = kappa_scale(wrap_angle(p.agent_pose[:, 2] - p.heading), np.asarray(p.kappa, np.float64))
    return Calibration(scale(agent_d2) or 1.0, own[0], heading, shared_colour_scale=shared and shared[0],
                       lost_own=own[1], lost_shared=shared[1] if inputs is not None and shared else None,
                       search_find=None if inputs is None else _search_fit(criterion, inputs.looks, inputs.not_found))


#: The measurement-noise multipliers ``fit_measurement_noise`` chooses from: powers of two, 1/64 to 64.
NOISE_GRID = tuple(2.0 ** k for k in range(-6, 7))


def seen_object_mean_error(predictions: Predictions) -> float:
    """The mean distance (m) between estimated and true positions of the objects seen earlier (``metrics``'
    "seen" rows): what the measurement noise is chosen by (a mean, so the badly wrong beliefs count)."""
    return float(_object_error(predictions)[predictions.present & predictions.seen].mean())


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

    def error(noise: tuple[float, float]) -> float:
        if noise not in tried:
            model.use_measurement_noise(*noise)
            tried[noise] = seen_object_mean_error(track_episodes(model, episodes))
        return tried[noise]

    best = (1.0, 1.0)
    for _ in range(rounds):
        best = min(((value, best[1]) for value in NOISE_GRID), key=error)
        best = min(((best[0], value) for value in NOISE_GRID), key=error)
    model.use_measurement_noise(*best)
    return best, {f"{own:g} x {shared:g}": value for (own, shared), value in tried.items()}


def calibrate(model: LNet, episodes: list[tuple[PoseEstimate, dict[str, torch.Tensor]]], criterion: str = "nll",
              arena: Arena | None = None) -> tuple[Predictions, Calibration, dict[str, float], StatedInputs | None]:
    """Calibrate ``model`` (with its current tracking rule) on validation episodes (``frame_estimates``): the
    filter's measurement noise (``fit_measurement_noise``), then the scales (``fit_calibration`` by
    ``criterion``; with ``arena``, also the objects' lost probabilities and search belief). Returns the
    uncalibrated predictions with the chosen noise, the calibration (recording the rule and the noise), the noise
    search's tries and the predictions' ``StatedInputs`` (None without ``arena``)."""
    noise, tried = fit_measurement_noise(model, episodes)
    predictions = track_episodes(model, episodes)
    inputs = None if arena is None else stated_inputs(predictions, arena)
    return predictions, tracked_calibration(model, predictions, criterion, inputs), tried, inputs


def tracked_calibration(model: LNet, predictions: Predictions, criterion: str, inputs: StatedInputs | None = None
                        ) -> Calibration:
    """``fit_calibration`` of ``predictions`` by ``criterion`` (with lost probabilities and the search belief when
    ``inputs`` is given), recording the tracking rule and measurement noise ``model`` tracked them with."""
    data_association = model.config.tracker == "filter" and model.filter.data_association
    noise = model.filter.measurement_noise if model.config.tracker == "filter" else (1.0, 1.0)
    return replace(fit_calibration(predictions, criterion, inputs), data_association=data_association,
                   noise_own=noise[0], noise_shared=noise[1])


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
    agent_d2 = _d2(p.agent_pose[:, :2], p.agent_mean, p.agent_tril)
    object_d2 = _d2(p.object_truth, p.object_mean, p.object_tril)
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


@dataclass(frozen=True)
class StatedInputs:
    """What the objects' stated belief needs of a set of predictions beyond their Gaussians: the arena shares of
    the lost belief (``mor.lnet.lost``), the looks of the search belief (``mor.lnet.search``) and which beliefs
    have not found their object (N, K), judged on the uncalibrated beliefs."""

    shares: ArenaShares
    looks: SearchLooks
    not_found: np.ndarray

    def select(self, rows: np.ndarray) -> StatedInputs:
        """The inputs of the frames ``rows`` (as ``Predictions.select``)."""
        return StatedInputs(self.shares.select(rows), self.looks.select(rows), self.not_found[rows])


def stated_inputs(predictions: Predictions, arena: Arena) -> StatedInputs:
    """``StatedInputs`` of the present objects of ``predictions`` (uncalibrated: which beliefs are not found is
    judged on their own width)."""
    p = predictions
    return StatedInputs(arena_shares(p.object_truth, p.object_mean, p.object_tril, p.present, arena),
                        search_looks(p.agent_mean, p.heading, p.object_truth, p.episode, arena),
                        p.present & not_found(p.object_tril))


def stated_metrics(predictions: Predictions, lost: np.ndarray, inputs: StatedInputs | None,
                   search_find: float | None = None) -> dict[str, Any]:
    """The objects' NLL, 1/2/3-sigma coverage and reliability under their stated belief: the (calibrated)
    Gaussians of ``predictions`` with the lost probabilities ``lost`` (N, K) (``mor.lnet.lost``) and, with
    ``search_find``, the search belief for the objects not found yet (``mor.lnet.search``); ``inputs`` (of these
    predictions) is needed where any lost probability is above 0 or ``search_find`` is given. Without either these
    are the Gaussian's own figures."""
    p = predictions
    if inputs is None and (np.any(lost > 0) or search_find is not None):
        raise ValueError("stated_metrics: lost probabilities above 0 or a search belief need the StatedInputs")
    d2 = _d2(p.object_truth, p.object_mean, p.object_tril)
    mass = region_mass(d2, lost, np.zeros(d2.shape) if inputs is None else inputs.shares.share)
    log_p = log_density(d2, _half_log_det(p.object_tril), lost, 1.0 if inputs is None else inputs.shares.area)
    groups = _object_groups(p)
    searching = np.zeros_like(p.present) if search_find is None else inputs.not_found
    if search_find is not None:
        mass = np.where(searching, search_mass(inputs.looks, search_find), mass)
        log_p = np.where(searching, search_log_density(inputs.looks, search_find), log_p)
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


def calibrated_metrics(predictions: Predictions, calibration: Calibration, inputs: StatedInputs | None = None
                       ) -> dict[str, Any]:
    """``metrics`` of ``predictions`` after ``calibration``, with the objects' stated belief (``stated_metrics``,
    under the calibration's lost probabilities and search belief) as ``stated``."""
    calibrated = calibration.apply(predictions, predictions.confusable)
    return {**metrics(calibrated), "stated": stated_metrics(calibrated, calibration.lost(predictions.confusable),
                                                            inputs, calibration.search_find)}


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
