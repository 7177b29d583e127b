"""The trained L-Net inside a control loop: ``load_lnet`` (one call) and a batched streaming step over N envs.

    runner = load_lnet(Path("cards/lnet/model.pt"))          # + calibration.json beside it
    state = runner.initial_state(n_envs)
    state = runner.reset(state, done)                          # (N,) bool: envs that start a new episode
    estimates, state = runner.step(obs_images, obs_classes, obs_held, previous_actions, state)

Inputs are the environments' observations (``mor.sim.env``): images (N, H, W, 3) uint8, object_classes (N, n),
held (N,) with n meaning "nothing held", and the action taken before each frame (-1 at an episode's start); they
are turned into the network's inputs by ``mor.data.observations.env_to_network``, the conversion the dataset
windows use. One forward pass for all N environments, without gradients. The estimates are the stated belief
(``mor.lnet.stated``), calibrated. ``mor.lnet.streaming.StreamingTracker`` runs this step over N environments'
episodes (starts, ends, the search belief's looks).
"""

from __future__ import annotations

import hashlib
import json
import logging
import warnings
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from mor.data.observations import env_to_network
from mor.errors import MorError
from mor.lnet.calibration import Calibration
from mor.lnet.calibration_file import (CALIBRATION_FILE, FittedCalibration, chosen_calibration, read_calibration,
                                      recorded_settings)
from mor.lnet.checkpoint import load_checkpoint, model_from_checkpoint
from mor.lnet.filter import TrackingSettings
from mor.lnet.model import LNet, PoseEstimate
from mor.lnet.params import LNetConfig
from mor.lnet.search import SearchMap
from mor.lnet.stated import Estimates, stated_estimates
from mor.sim.rules import N_ACTIONS


class ObservationMismatch(MorError, ValueError):
    """Observations the loaded model cannot read (wrong image size or dtype, inconsistent batch sizes)."""


@dataclass(frozen=True)
class StreamState:
    """The tracker's memory of ``n_envs`` running episodes (opaque to callers)."""

    n_envs: int
    memory: Any


class LNetRunner:
    """A trained L-Net with its calibration, stepped one frame at a time over N environments. ``fitted``: the
    scales, the tracking settings (applied to ``model`` here) and the stated belief's parameters."""

    def __init__(self, model: LNet, fitted: FittedCalibration, image_size: int, dataset_version: str,
                 device: torch.device | str = "cpu", checkpoint_digest: str | None = None,
                 compiled: bool = False) -> None:
        model.use_tracking(fitted.tracking)
        self.model = model.to(device).eval()
        # compiled: the step runs as torch.compile's fused kernels (the same arithmetic up to float rounding, about
        # 1e-7 here; about a minute to compile on first use, then cached on disk by torch). docs/performance.md.
        self.compiled = compiled
        if compiled:  # inductor's own notices (no CUDA on a CPU machine, its deprecations) are not the user's
            logging.getLogger("torch.utils.cpp_extension").setLevel(logging.ERROR)
            warnings.filterwarnings("ignore", category=FutureWarning, module=r"torch\._inductor")
        self._network = torch.compile(self.model, dynamic=False) if compiled else self.model
        self.fitted = fitted
        self.image_size = image_size
        self.dataset_version = dataset_version
        self.checkpoint_digest = checkpoint_digest
        self.device = torch.device(device)

    def __deepcopy__(self, memo: dict[int, Any]) -> LNetRunner:
        """The runner itself: its weights and calibration are read-only while it tracks, and every tracker keeps
        its own state, so a copied tracker (Gymnasium records a wrapper's arguments by deep copy) shares it (a
        compiled network cannot be deep-copied)."""
        return self

    @property
    def identity(self) -> str:
        """What a policy trained through this L-Net records (``lnet_version``): ``lnet_identity``."""
        return lnet_identity(self.dataset_version, self.checkpoint_digest, self.fitted, self.encoder_precision)

    @property
    def stated_identity(self) -> str:
        """What a policy that reads the stated belief records beside ``identity`` (``stated_version``):
        ``stated_identity``."""
        return stated_identity(self.fitted)

    @property
    def encoder_precision(self) -> str:
        """The image encoder's arithmetic (``LNet.use_encoder_precision``): float32 or bfloat16."""
        return "bfloat16" if self.model.posenet.encoder_bfloat16 else "float32"

    @property
    def config(self) -> LNetConfig:
        return self.model.config

    def initial_state(self, n_envs: int) -> StreamState:
        """The state of ``n_envs`` environments that all start an episode."""
        if n_envs < 1:
            raise ValueError(f"n_envs: must be at least 1 (got {n_envs})")
        with torch.no_grad():  # inference: the learned priors enter the state as plain values
            return StreamState(n_envs, self.model.initial_state(n_envs, self.device))

    def reset(self, state: StreamState, done: np.ndarray) -> StreamState:
        """``state`` with the environments where ``done`` (N,) bool is True back at an episode's start."""
        done = np.asarray(done)
        if done.shape != (state.n_envs,) or done.dtype != np.bool_:
            raise ObservationMismatch(f"done: expected ({state.n_envs},) bool, got {done.dtype} {done.shape}")
        mask = torch.from_numpy(done).to(self.device)
        return StreamState(state.n_envs, self.model.reset_state(state.memory, mask))

    def select(self, state: StreamState, other: StreamState, take_other: np.ndarray) -> StreamState:
        """Per environment, ``other``'s state where ``take_other`` (N,) bool is True, else ``state``'s (used to
        keep one environment's episode going while another's ends and restarts within one vector step)."""
        mask = torch.from_numpy(np.asarray(take_other, dtype=bool)).to(self.device)
        return StreamState(state.n_envs, self.model.select_state(state.memory, other.memory, mask))

    def _check(self, images: np.ndarray, previous_actions: np.ndarray, n_envs: int) -> None:
        expected = (n_envs, self.image_size, self.image_size, 3)
        if not isinstance(images, np.ndarray) or images.dtype != np.uint8 or images.shape != expected:
            got = f"{images.dtype} {images.shape}" if isinstance(images, np.ndarray) else type(images).__name__
            raise ObservationMismatch(f"images: expected uint8 frames of shape {expected} (one per environment, "
                                      f"the model's {self.image_size} px), got {got}")
        if previous_actions.shape != (n_envs,) or np.any((previous_actions < -1) | (previous_actions >= N_ACTIONS)):
            raise ObservationMismatch(f"previous_actions: expected ({n_envs},) actions in [-1, {N_ACTIONS - 1}] "
                                      f"(-1 at an episode's start), got {previous_actions.tolist()}")

    @torch.inference_mode()
    def track(self, images: np.ndarray, object_classes: np.ndarray, held: np.ndarray, previous_actions: np.ndarray,
              state: StreamState) -> tuple[PoseEstimate, StreamState]:
        """``step`` before calibration and conversion: the model's world-frame estimate (N, 1, ...) of all K slots,
        with the PoseNet's visibility logits of this frame (``visibility_logit`` (N, 1, K), None without the head)."""
        previous_actions = np.asarray(previous_actions)
        self._check(images, previous_actions, state.n_envs)
        try:
            inputs = env_to_network(images, object_classes, held)
        except ValueError as error:
            raise ObservationMismatch(str(error)) from None
        device = self.device
        single, tracked, memory = self._network(
            inputs.images.to(device)[:, None], inputs.object_classes.to(device), inputs.held.to(device)[:, None],
            torch.as_tensor(previous_actions, dtype=torch.long, device=device)[:, None], state.memory)
        return replace(tracked, visibility_logit=single.visibility_logit), StreamState(state.n_envs, memory)

    @torch.inference_mode()
    def step(self, images: np.ndarray, object_classes: np.ndarray, held: np.ndarray, previous_actions: np.ndarray,
             state: StreamState) -> tuple[Estimates, StreamState]:
        """One frame of each of N environments -> (calibrated estimates, the next state); one forward pass.

        images (N, H, W, 3) uint8; object_classes (N, n); held (N,) environment convention (n: none);
        previous_actions (N,) the action taken before this frame, -1 at an episode's start.
        """
        tracked, state = self.track(images, object_classes, held, previous_actions, state)
        return self.estimates(tracked, np.asarray(object_classes), np.asarray(held)), state

    def estimates(self, tracked: PoseEstimate, object_classes: np.ndarray, held: np.ndarray,
                  search: SearchMap | None = None) -> Estimates:
        """The stated belief (``mor.lnet.stated.stated_estimates``) of the last frame of the model's world-frame
        estimate (N, T, ...) for the n objects of ``object_classes`` (N, n) (``held`` (N,): which object each
        environment holds, n or -1 for none), calibrated, as numpy; ``search``: the environments' looks, this frame's
        included, for the search belief's density (None: without it)."""
        n_objects = object_classes.shape[1]
        visibility = None if tracked.visibility_logit is None else tracked.visibility_logit[:, -1, :n_objects]
        last = PoseEstimate(*(getattr(tracked, name)[:, -1] for name in (
            "agent_mean", "agent_tril", "heading", "kappa")), tracked.object_mean[:, -1, :n_objects],
            tracked.object_tril[:, -1, :n_objects], frame=tracked.frame, visibility_logit=visibility)
        return stated_estimates(last, object_classes, held, self.fitted.scales, self.fitted.stated, search)


def load_lnet(path: Path, device: torch.device | str = "cpu", expected: dict[str, Any] | None = None,
              calibrated: bool = True, compiled: bool = False, chosen: dict[str, Any] | None = None,
              encoder_precision: str = "float32") -> LNetRunner:
    """The trained L-Net at ``path`` with the calibration stored beside it (``calibration.json``).

    expected: a ``mor.lnet.checkpoint.signature`` (or part of one) the checkpoint must match: another tracker,
    config, dataset version or image size is one clear error naming both sides. calibrated=False: identity scales
    (what the calibration stage itself needs). compiled: the streaming step through ``torch.compile``.
    chosen: the run's tracking-time settings (``LNetParams.chosen_settings``: the tracking rule, the filter's gate,
    the not-found width, the search belief's look cap, the arena grid's spacing); None: those the calibration was
    fitted with (the defaults when uncalibrated); one given with a calibration fitted with another value, one clear
    error. encoder_precision: float32 or bfloat16 (``LNet.use_encoder_precision``), whichever the weights were
    trained with.
    """
    path = Path(path)
    saved = load_checkpoint(path, expected or {}, device)
    version = str(saved["dataset_version"])
    beside = path.parent / CALIBRATION_FILE
    chosen = chosen or {}
    fitted = read_calibration(beside, version) if calibrated else chosen_calibration(chosen)
    recorded = recorded_settings(fitted)
    for key, value in chosen.items():
        if value != recorded[key]:
            raise MorError(f"{beside}: fitted with {key} {recorded[key]} but this run's is {value} (lnet.{key}); "
                           "run mor calibrate-lnet")
    model = model_from_checkpoint(saved, device)
    model.use_encoder_precision(encoder_precision)
    return LNetRunner(model, fitted, int(saved["image_size"]), version, device, file_digest(path), compiled)


def lnet_identity(dataset_version: str, checkpoint_digest: str | None, fitted: FittedCalibration,
                  encoder_precision: str = "float32") -> str:
    """The dataset version; for a loaded checkpoint, the first 12 hex digits of its file's SHA-256 (another training
    run is another L-Net); unless the scales and the tracking settings are the defaults, ``-cal`` and 8 hex digits
    of them (another tracking rule or other scales give other estimates: what a policy reads changes; the stated
    belief's parameters, ``fitted.stated``, are left out: only a policy that reads the stated belief records them, as
``stated_identity``); and ``-bf16`` for a bfloat16
    encoder (its estimates differ a little from float32's)."""
    identity = dataset_version if checkpoint_digest is None else f"{dataset_version}-{checkpoint_digest}"
    if (fitted.scales, fitted.tracking) != (Calibration(), TrackingSettings()):
        # The fields one Calibration record held when the hash was introduced, the lost probabilities at their
        # defaults: every identity recorded since stands (docs/assumptions.md, "L-Net identity").
        hashed = {**asdict(fitted.scales), **asdict(fitted.tracking), "lost_own": 0.0, "lost_shared": None}
        if fitted.tracking.gate == TrackingSettings.gate:  # the gate joined the record later, at its default
            del hashed["gate"]
        if not fitted.tracking.negative_information:  # so did negative information, off
            del hashed["negative_information"]
        identity += "-cal" + hashlib.sha256(json.dumps(hashed, sort_keys=True).encode()).hexdigest()[:8]
    return identity + ("-bf16" if encoder_precision == "bfloat16" else "")


def stated_identity(fitted: FittedCalibration) -> str:
    """8 hex digits of the stated belief's parameters (``fitted.stated``: the lost probabilities, the search
    belief's find probability, its chosen settings), which ``lnet_identity`` leaves out: a policy that reads the
    stated belief (``Variant.search``) records it, so that another calibration of the belief refuses that policy."""
    return hashlib.sha256(json.dumps(asdict(fitted.stated), sort_keys=True).encode()).hexdigest()[:8]


def file_digest(path: Path) -> str:
    """The first 12 hex digits of the SHA-256 of the file at ``path`` (how checkpoints and policies are named in
    ``lnet_version`` and ``played_by``)."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:12]


def checkpoint_identity(path: Path, encoder_precision: str = "float32") -> str:
    """``LNetRunner.identity`` of the checkpoint at ``path`` (loaded with ``encoder_precision``) without building
    the model: what a policy trained or a row evaluated through it records as ``lnet_version``."""
    path = Path(path)
    saved = load_checkpoint(path, {}, "cpu")
    version = str(saved["dataset_version"])
    beside = path.parent / CALIBRATION_FILE
    return lnet_identity(version, file_digest(path), read_calibration(beside, version) if beside.is_file()
                         else FittedCalibration(), encoder_precision)
