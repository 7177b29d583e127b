"""The L-Net's predictions beside the truth, frame by frame over many episodes (``Predictions``): what evaluation
scores (``mor.lnet.evaluate``), calibration is fitted on (``mor.lnet.calibration_fit``) and the figures show; made by
``mor.lnet.predict``.

Shapes: N frames, T frames of one episode, K object slots. Positions in metres, headings in radians.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from mor.lnet.calibration import confusable


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
