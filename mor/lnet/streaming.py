"""The streaming tracker's one loop: N environments' frames through an ``LNetRunner``, one batched step per call,
each environment's episode starts and ends handled there (its tracker state and looks reset, its previous action
-1 on its first frame). The policies' trackers (``mor.policy.lnet_tracking``) and live evaluation
(``mor.lnet.predict.predict_live``) run their episodes through it.

    stream = StreamingTracker(runner, n_envs)                 # arena=...: also the search belief's looks
    estimates = stream.step(frames, previous_actions, starting)
    now, last = stream.step_across_ends(last_frames, frames, previous_actions, ended)   # SB3 vector envs

frames: N environments' observations stacked (``stack_frames``): image (N, H, W, 3) uint8, object_classes (N, n),
held (N,) (n: nothing held). previous_actions (N,): the action taken before each frame (ignored on a first frame).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mor.data.schema import NO_ACTION
from mor.lnet.model import PoseEstimate
from mor.lnet.runtime import LNetRunner
from mor.lnet.stated import Estimates
from mor.sim.arena import Arena

#: The observation keys the L-Net reads.
FRAME_KEYS = ("image", "object_classes", "held")

Frames = dict[str, np.ndarray]


def stack_frames(observations: list[dict[str, Any]]) -> Frames:
    """N environments' observation dicts -> ``Frames`` (each of ``FRAME_KEYS`` stacked, leading dim N)."""
    return {key: np.stack([np.asarray(o[key]) for o in observations]) for key in FRAME_KEYS}


class StreamingTracker:
    """N environments' episodes tracked by ``runner``: one forward pass per ``step``. With ``arena``, each
    environment's looks of the arena grid are kept too (``mor.lnet.search.SearchMap``, from the estimated poses, with
    the calibration's look cap and grid spacing), so the estimates carry the search belief's density
    (``Estimates.search_density``)."""

    def __init__(self, runner: LNetRunner, n_envs: int, arena: Arena | None = None) -> None:
        self.runner = runner
        self.state = runner.initial_state(n_envs)
        self.search = None if arena is None else runner.fitted.stated.search_map(arena, n_envs)

    def track(self, frames: Frames, previous_actions: np.ndarray, starting: np.ndarray) -> PoseEstimate:
        """One frame of each environment -> the model's world-frame estimate (N, 1, ...) of all K slots, before
        calibration (``LNetRunner.track``). starting (N,) bool: the frame is an episode's first."""
        starting = np.asarray(starting, dtype=bool)
        state = self.runner.reset(self.state, starting) if starting.any() else self.state
        previous = np.where(starting, NO_ACTION, np.asarray(previous_actions))
        tracked, self.state = self.runner.track(frames["image"], frames["object_classes"], np.asarray(frames["held"]),
                                                previous, state)
        if self.search is not None:
            self.search.reset(starting)
            self.search.update(*(getattr(tracked, name)[:, -1].float().cpu().numpy() for name in ("agent_mean",
                                                                                                  "heading")))
        return tracked

    def step(self, frames: Frames, previous_actions: np.ndarray, starting: np.ndarray) -> Estimates:
        """``track``, then the stated belief of the n objects of each environment (``LNetRunner.estimates``)."""
        tracked = self.track(frames, previous_actions, starting)
        return self.runner.estimates(tracked, np.asarray(frames["object_classes"]), np.asarray(frames["held"]),
                                     self.search)

    def step_across_ends(self, last_frames: Frames, frames: Frames, previous_actions: np.ndarray, ended: np.ndarray
                         ) -> tuple[Estimates, Estimates]:
        """A vector step in which the environments where ``ended`` (N,) bool is True finished an episode and started
        the next (as SB3's vector envs report it): ``last_frames`` holds their episode's last frame, ``frames`` the
        next one's first (elsewhere both hold this step's frame). Two forward passes: the last frames from the
        running state, then the first frames from a reset one; each environment goes on from the one of its own.
        Returns (the estimates each environment goes on from: the first frame's where ``ended``, else this frame's;
        the estimates of ``last_frames``)."""
        ended = np.asarray(ended, dtype=bool)
        last = self.step(last_frames, previous_actions, np.zeros_like(ended))
        continued, looks = self.state, None if self.search is None else self.search.counts.copy()
        first = self.step(frames, previous_actions, ended)
        self.state = self.runner.select(continued, self.state, ended)
        if self.search is not None:
            self.search.counts = np.where(ended[:, None], self.search.counts, looks)
        return last.where(ended, first), last
