"""The L-Net: a PoseNet f(o_t, c) per frame and an LSTM g(h_t, s_ego_t) over time (paper section 4.1).

Shapes: B batch, T time, K = 5 object slots (absent slots have class -1 and are masked), images (3, H, W) in
[0, 1]. Positions in metres, angles in radians; world frame and ego frame as in docs/design.md.
"""

from __future__ import annotations

from dataclasses import dataclass
import torch
from torch import nn

from mor.data.schema import MAX_OBJECTS
from mor.lnet.filter import BeliefFilter, TrackingSettings
from mor.lnet.frames import ego_to_world
from mor.lnet.likelihoods import MIN_KAPPA, positive, scale_tril
from mor.lnet.params import LNetConfig
from mor.lnet.small_matrices import cholesky_2x2
from mor.sim.catalog import N_CLASSES, shares_colour
from mor.sim.rules import N_ACTIONS

K = MAX_OBJECTS
_ABSENT = N_CLASSES  # embedding index of an absent slot
_NO_ACTION = N_ACTIONS  # one-hot index of "no previous action"
ESTIMATE_FIELDS = ("agent_mean", "agent_tril", "heading", "kappa", "object_mean", "object_tril")  # of a PoseEstimate


@dataclass
class PoseEstimate:
    """Distributions over poses; leading dims (...) are (B, T) or (N,).

    agent_mean (..., 2) world; agent_tril (..., 2, 2); heading (...) and kappa (...) of a von Mises;
    object_mean (..., K, 2), object_tril (..., K, 2, 2) in ``frame`` ("ego" for the PoseNet, "world" for the tracker).
    """

    agent_mean: torch.Tensor
    agent_tril: torch.Tensor
    heading: torch.Tensor
    kappa: torch.Tensor
    object_mean: torch.Tensor
    object_tril: torch.Tensor
    frame: str
    visibility_logit: torch.Tensor | None = None  # (..., K), the PoseNet's, when the config asks for visibility

    def to_numpy(self) -> dict[str, object]:
        return {name: getattr(self, name).detach().cpu().numpy() for name in ESTIMATE_FIELDS}


def _mlp(inputs: int, hidden: int, outputs: int) -> nn.Sequential:
    """The paper's 3-layer MLP."""
    return nn.Sequential(nn.Linear(inputs, hidden), nn.ReLU(), nn.Linear(hidden, hidden), nn.ReLU(),
                         nn.Linear(hidden, outputs))


class CompactEncoder(nn.Module):
    """4 strided conv layers (32-64-128-128 channels) and a linear layer on the 4x4 map: (N,3,H,W) -> (N,D).

    The spatial layout is kept (no global pooling): where a wall corner or an object appears is the signal.
    """

    channels = 128  # of the last conv layer, i.e. of the spatial map

    def __init__(self, feature_dim: int) -> None:
        super().__init__()
        layers: list[nn.Module] = []
        for cin, cout in ((3, 32), (32, 64), (64, 128), (128, 128)):
            layers += [nn.Conv2d(cin, cout, 3, stride=2, padding=1), nn.GroupNorm(8, cout), nn.ReLU()]
        self.features = nn.Sequential(*layers, nn.AdaptiveAvgPool2d(4), nn.Flatten())
        self.project = nn.Sequential(nn.Linear(self.channels * 16, feature_dim), nn.ReLU())

    def encode(self, images: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(N, 3, H, W) -> features (N, D) and the spatial map they come from, (N, 128, 4, 4)."""
        spatial = self.features[:-1](images)
        return self.project(spatial.flatten(1)), spatial

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        return self.encode(images)[0]


class ResNetEncoder(nn.Module):
    """torchvision's ResNet18 or ResNet50, randomly initialized (no weights can be downloaded), -> (N, D)."""

    def __init__(self, feature_dim: int, depth: int = 18) -> None:
        super().__init__()
        from torchvision import models  # noqa: PLC0415 - only these encoders need torchvision

        self.backbone = getattr(models, f"resnet{depth}")(weights=None)
        self.channels = self.backbone.fc.in_features  # of the last stage's map: 512 (ResNet18) or 2048 (ResNet50)
        self.backbone.fc = nn.Sequential(nn.Linear(self.channels, feature_dim), nn.ReLU())

    def last_map(self, images: torch.Tensor) -> torch.Tensor:
        """(N, 3, H, W) -> the last stage's map (N, channels, H/32, W/32)."""
        net = self.backbone
        stem = net.maxpool(net.relu(net.bn1(net.conv1(images))))
        return net.layer4(net.layer3(net.layer2(net.layer1(stem))))

    def pool(self, last: torch.Tensor) -> torch.Tensor:
        """The last stage's map (N, channels, h, w) -> features (N, D): average pool, then the linear layer."""
        return self.backbone.fc(self.backbone.avgpool(last).flatten(1))

    def encode(self, images: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(N, 3, H, W) -> features (N, D) and the last stage's map resampled to 4x4, (N, channels, 4, 4)."""
        last = self.last_map(images)
        return self.pool(last), nn.functional.adaptive_avg_pool2d(last, 4)

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        return self.encode(images)[0]


def build_encoder(name: str, feature_dim: int) -> CompactEncoder | ResNetEncoder:
    """An image encoder by name: ``compact``, ``resnet18`` or ``resnet50``; (N, 3, H, W) in [0, 1] -> (N, D)."""
    if name == "compact":
        return CompactEncoder(feature_dim)
    if name in ("resnet18", "resnet50"):
        return ResNetEncoder(feature_dim, int(name.removeprefix("resnet")))
    raise ValueError(f"unknown image encoder {name!r}; choose compact, resnet18 or resnet50")


class ObjectAttention(nn.Module):
    """Each object slot's class embedding attends over the encoder's 4x4 map: where in the image that class is.

    spatial (N, C, 4, 4), embedded (N, K, E) -> (N, K, C): the attention-weighted cells, each cell's feature plus
    a learned embedding of its position, so the result says both what was found and where.
    """

    cells = 16

    def __init__(self, channels: int, embedding_dim: int) -> None:
        super().__init__()
        self.query = nn.Linear(embedding_dim, channels)
        self.position = nn.Parameter(0.02 * torch.randn(self.cells, channels))

    def forward(self, spatial: torch.Tensor, embedded: torch.Tensor) -> torch.Tensor:
        keys = spatial.flatten(2).transpose(1, 2) + self.position
        scores = torch.einsum("nkc,nsc->nks", self.query(embedded), keys) / keys.shape[-1] ** 0.5
        return torch.einsum("nks,nsc->nkc", scores.softmax(-1), keys)


def _agent_distribution(raw: torch.Tensor) -> tuple[torch.Tensor, ...]:
    """(..., 8) -> mean (..., 2), tril (..., 2, 2), heading (...), kappa (...)."""
    return raw[..., :2], scale_tril(raw[..., 2:5]), torch.atan2(raw[..., 6], raw[..., 5]), positive(raw[..., 7], MIN_KAPPA)


class PoseNet(nn.Module):
    """f(o_t, c): image + class ids -> agent global pose and each object's ego position, with uncertainty."""

    def __init__(self, config: LNetConfig) -> None:
        super().__init__()
        self.encoder = build_encoder(config.encoder, config.feature_dim)
        self.embed = nn.Embedding(N_CLASSES + 1, config.class_embedding_dim)
        self.agent_head = _mlp(config.feature_dim, config.mlp_hidden, 8)
        object_inputs = config.feature_dim + config.class_embedding_dim
        self.attention = None
        if config.object_head == "attention":
            self.attention = ObjectAttention(self.encoder.channels, config.class_embedding_dim)
            object_inputs += self.encoder.channels
        self.object_head = _mlp(object_inputs, config.mlp_hidden, 6 if config.visibility else 5)
        self.encoder_bfloat16 = False  # the encoder's arithmetic, not a weight: LNet.use_encoder_precision

    def forward(self, images: torch.Tensor, classes: torch.Tensor) -> PoseEstimate:
        """images (N, 3, H, W), classes (N, K) -> PoseEstimate with leading dim N (objects in the ego frame)."""
        with torch.autocast(images.device.type, torch.bfloat16, enabled=self.encoder_bfloat16):
            features, spatial = self.encoder.encode(images)
        features, spatial = features.float(), spatial.float()  # no-ops in float32
        mean, tril, heading, kappa = _agent_distribution(self.agent_head(features))
        embedded = self.embed(torch.where(classes >= 0, classes, torch.full_like(classes, _ABSENT)))
        object_inputs = [features.unsqueeze(1).expand(-1, K, -1), embedded]
        if self.attention is not None:
            object_inputs.append(self.attention(spatial, embedded))
        raw = self.object_head(torch.cat(object_inputs, -1))
        visibility = raw[..., 5] if raw.shape[-1] > 5 else None
        return PoseEstimate(mean, tril, heading, kappa, raw[..., :2], scale_tril(raw[..., 2:5]), "ego", visibility)


def _summary(estimate: PoseEstimate) -> torch.Tensor:
    """A flat, well-scaled vector of a PoseNet estimate, (..., 8 + 5K): means, log-scales, heading as cos/sin."""
    def tril_features(tril: torch.Tensor) -> torch.Tensor:
        return torch.stack([torch.log(tril[..., 0, 0]), torch.log(tril[..., 1, 1]), tril[..., 1, 0]], -1)

    agent = torch.cat([estimate.agent_mean, tril_features(estimate.agent_tril), torch.cos(estimate.heading)[..., None],
                       torch.sin(estimate.heading)[..., None], torch.log(estimate.kappa)[..., None]], -1)
    objects = torch.cat([estimate.object_mean, tril_features(estimate.object_tril)], -1).flatten(-2)
    return torch.cat([agent, objects], -1)


TrackerState = tuple[torch.Tensor, ...]


class LNet(nn.Module):
    """PoseNet per frame, then a tracker over the episode -> world-frame estimates of the agent and all objects.

    ``tracker: lstm`` (the paper's): an LSTM whose input per step is the PoseNet summary, the ego object estimates
    projected to the world with the PoseNet's agent estimate, which slots are present, which object is held
    (observed), optionally the previous action, and with ``visibility`` the predicted visibilities.
    ``tracker: filter``: the Gaussian belief of ``mor.lnet.filter``, each object measurement weighted by the
    predicted visibility (without the tracker's gradient when ``detach_visibility``).
    """

    def __init__(self, config: LNetConfig) -> None:
        super().__init__()
        self.config = config
        self.posenet = PoseNet(config)
        if config.tracker == "lstm":
            inputs = ((8 + 5 * K) + 2 * K + K + (K + 1) + ((N_ACTIONS + 1) if config.use_actions else 0)
                      + (K if config.visibility else 0))
            self.lstm = nn.LSTM(inputs, config.lstm_hidden, batch_first=True)
            self.head = nn.Linear(config.lstm_hidden, 8 + 5 * K)
        else:
            self.filter = BeliefFilter(K)

    def use_tracking(self, tracking: TrackingSettings) -> None:
        """Track with ``tracking`` from now on (the filter's rules and measurement noise, ``mor.lnet.filter``);
        anything but the defaults with the LSTM tracker, or negative information without the visibility head, is a
        ValueError."""
        if self.config.tracker == "filter":
            if tracking.negative_information and not self.config.visibility:
                raise ValueError("negative information needs the visibility head (model.visibility: true): it reads "
                                 "which objects the PoseNet does not see")
            self.filter.tracking = tracking
        elif tracking != TrackingSettings():
            raise ValueError(f"tracking settings need the filter tracker; this model's tracker is the LSTM "
                             f"({tracking})")

    @property
    def tracking(self) -> TrackingSettings:
        """The tracking settings in use (the defaults for the LSTM tracker, which has none)."""
        return self.filter.tracking if self.config.tracker == "filter" else TrackingSettings()

    def use_encoder_precision(self, precision: str) -> None:
        """The image encoder's arithmetic from now on, in training or inference: ``float32`` or ``bfloat16``
        (``torch.autocast`` around the encoder only; weights, heads and tracker stay float32). It is not saved with
        the weights: whoever loads them chooses. Anything else is a ValueError."""
        if precision not in ("float32", "bfloat16"):
            raise ValueError(f"encoder precision: expected float32 or bfloat16, got {precision!r}")
        self.posenet.encoder_bfloat16 = precision == "bfloat16"

    @property
    def _batch_dim(self) -> int:
        return 1 if self.config.tracker == "lstm" else 0  # the LSTM's (h, c) are (layers, B, hidden)

    def initial_state(self, n: int, device: torch.device | str = "cpu") -> TrackerState:
        """The tracker's state at the start of ``n`` episodes: zero LSTM (h, c), each (1, n, lstm_hidden), or the
        filter's prior belief (``mor.lnet.filter.FilterState``)."""
        if self.config.tracker == "lstm":
            zeros = torch.zeros(1, n, self.config.lstm_hidden, device=device)
            return zeros, zeros.clone()
        return self.filter.initial_state(n, device)

    def select_state(self, state: TrackerState, other: TrackerState, take_other: torch.Tensor) -> TrackerState:
        """Per episode, ``other``'s state where ``take_other`` (n,) bool is True, else ``state``'s."""
        def pick(mine: torch.Tensor, theirs: torch.Tensor) -> torch.Tensor:
            shape = [1] * mine.dim()
            shape[self._batch_dim] = -1
            return torch.where(take_other.view(shape), theirs, mine)

        return tuple(pick(mine, theirs) for mine, theirs in zip(state, other, strict=True))

    def reset_state(self, state: TrackerState, done: torch.Tensor) -> TrackerState:
        """``state`` with the episodes where ``done`` (n,) bool is True back at their start."""
        return self.select_state(state, self.initial_state(len(done), done.device), done)

    def forward(
        self, images: torch.Tensor, classes: torch.Tensor, held: torch.Tensor, previous_actions: torch.Tensor,
        state: TrackerState | None = None,
    ) -> tuple[PoseEstimate, PoseEstimate, TrackerState]:
        """images (B, T, 3, H, W); classes (B, K); held (B, T) index or -1; previous_actions (B, T) the action
        taken before each frame (-1 at an episode's start). Returns (per-frame PoseNet estimates, the tracker's
        world-frame estimates, the tracker's state), both estimates with leading dims (B, T)."""
        single = self.frame_estimates(images, classes)
        return (single, *self.track(single, classes, held, previous_actions, state))

    def frame_estimates(self, images: torch.Tensor, classes: torch.Tensor) -> PoseEstimate:
        """The PoseNet on every frame: images (B, T, 3, H, W), classes (B, K) -> estimates (B, T, ...), ego frame."""
        b, t = images.shape[:2]
        frame_classes = classes.unsqueeze(1).expand(-1, t, -1).reshape(b * t, K)
        flat = self.posenet(images.flatten(0, 1), frame_classes)
        visibility = None if flat.visibility_logit is None else flat.visibility_logit.unflatten(0, (b, t))
        return PoseEstimate(*(getattr(flat, n).unflatten(0, (b, t)) for n in ESTIMATE_FIELDS), frame="ego",
                            visibility_logit=visibility)

    def track(self, single: PoseEstimate, classes: torch.Tensor, held: torch.Tensor, previous_actions: torch.Tensor,
              state: TrackerState | None = None) -> tuple[PoseEstimate, TrackerState]:
        """The tracker over the PoseNet's estimates ``single`` (B, T, ...) -> (world-frame estimates (B, T, ...),
        the tracker's state); classes, held and previous_actions as in ``forward``."""
        if self.config.tracker == "filter":
            return self._filter(single, held, previous_actions, shares_colour(classes), state)
        t = held.shape[1]
        visibility = single.visibility_logit
        projected = ego_to_world(single.object_mean, single.agent_mean, single.heading).flatten(-2)
        present = (classes >= 0).float().unsqueeze(1).expand(-1, t, -1)
        held_one_hot = nn.functional.one_hot(torch.where(held >= 0, held, torch.full_like(held, K)), K + 1).float()
        inputs = [_summary(single), projected, present, held_one_hot]
        if self.config.use_actions:
            actions = torch.where(previous_actions >= 0, previous_actions, torch.full_like(previous_actions, _NO_ACTION))
            inputs.append(nn.functional.one_hot(actions, N_ACTIONS + 1).float())
        if visibility is not None:
            inputs.append(torch.sigmoid(visibility))
        hidden, state = self.lstm(torch.cat(inputs, -1), state)
        raw = self.head(hidden)
        mean, tril, heading, kappa = _agent_distribution(raw[..., :8])
        objects = raw[..., 8:].unflatten(-1, (K, 5))
        return PoseEstimate(mean, tril, heading, kappa, objects[..., :2], scale_tril(objects[..., 2:5]), "world"), state

    def _filter(self, single: PoseEstimate, held: torch.Tensor, previous_actions: torch.Tensor, shared: torch.Tensor,
                state: TrackerState | None) -> tuple[PoseEstimate, TrackerState]:
        """The belief filter over the T frames of ``single`` -> (world-frame estimates (B, T, ...), last state);
        shared (B, K): the object shares its colour with another of the episode."""
        b, t = held.shape
        state = self.filter.initial_state(b, held.device) if state is None else state
        visibility = None if single.visibility_logit is None else torch.sigmoid(single.visibility_logit)
        if visibility is not None and self.config.detach_visibility:
            visibility = visibility.detach()  # the head learns from its BCE only (LNetConfig.detach_visibility)
        outputs = []
        for i in range(t):
            state = self.filter.step(
                state, (single.agent_mean[:, i], single.agent_tril[:, i], single.heading[:, i], single.kappa[:, i]),
                (single.object_mean[:, i], single.object_tril[:, i]), None if visibility is None else visibility[:, i],
                held[:, i], previous_actions[:, i], shared)
            agent, agent_cov, heading, heading_var, objects, object_cov, _ = state
            outputs.append((agent, cholesky_2x2(agent_cov), heading,
                            (1.0 / heading_var).clamp(min=MIN_KAPPA), objects, cholesky_2x2(object_cov)))
        return PoseEstimate(*(torch.stack(parts, 1) for parts in zip(*outputs, strict=True)), frame="world"), state
