"""The L-Net's parameters (architecture and training), validated; no torch import, so configs load fast."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import Field, model_validator

from mor.params_model import ParamsModel


class LNetConfig(ParamsModel):
    """Architecture. ``encoder``: ``compact`` (CPU profiles) or ``resnet18`` (the paper's, trained from scratch)."""

    encoder: Literal["compact", "resnet18"] = "compact"
    feature_dim: int = Field(256, ge=8)
    class_embedding_dim: int = Field(32, ge=1)
    mlp_hidden: int = Field(256, ge=8)
    lstm_hidden: int = Field(256, ge=8)
    use_actions: bool = Field(True, description="feed the previous action to the LSTM (our addition)")
    tracker: Literal["lstm", "filter"] = Field(
        "lstm", description="lstm: the paper's LSTM over PoseNet summaries; filter: a differentiable world-frame "
                            "Gaussian belief (mor.lnet.filter, our addition)")
    visibility: bool = Field(
        False, description="a per-object visibility head on the PoseNet (BCE against the dataset's "
                           "ground_truth.object_visible), its ego object NLL scored only where the object is "
                           "visible, and the tracker's measurement weighted by the predicted visibility (our addition)")
    object_head: Literal["global", "attention"] = Field(
        "global", description="object positions from the image's global feature (the paper's MLP) or from the "
                              "cells of the encoder's map that each object's class attends to (our addition; "
                              "trained per frame at equal budgets, its ego error on visible objects within 2 m was "
                              "about 0.1 m, the global head's about 0.3 m)")
    detach_visibility: bool = Field(
        False, description="with visibility and the filter: the filter weighs each measurement by the predicted "
                           "visibility without passing the tracker's loss back into the visibility head, which then "
                           "learns from its BCE alone and stays a calibrated probability. False (the committed "
                           "model's): the tracker's NLL also trains the head and pulls every probability down (its "
                           "mean on visible objects is 0.05 at a 15% base rate), so the filter ignores the images")


class TrainParams(ParamsModel):
    """Every hyper-parameter of a training run."""

    window: int = Field(32, ge=2, description="frames per training sequence")
    stride: int = Field(16, ge=1, description="frames between window starts")
    batch_size: int = Field(16, ge=1)
    learning_rate: float = Field(1e-3, gt=0)
    weight_decay: float = Field(1e-4, ge=0)
    grad_clip: float = Field(1.0, gt=0)
    max_steps: int = Field(3000, ge=1, description="steps on windows (after the pretraining)")
    pretrain_steps: int = Field(0, ge=0, description="PoseNet steps on single frames drawn from the whole training "
                                                     "split before the windows (our addition): many more frames per "
                                                     "step for the encoder and the object head; 0: none")
    pretrain_batch_size: int = Field(64, ge=1, description="frames per pretraining step")
    eval_every: int = Field(250, ge=1)
    validation_windows: int = Field(256, ge=1, description="fixed subset of validation windows per evaluation")
    patience: int = Field(4, ge=1, description="evaluations without improvement before stopping")
    num_workers: int = Field(1, ge=0)
    beta_nll: float = Field(0.0, ge=0.0, le=1.0, description="beta of the beta-NLL (Seitzer et al. 2022) on the "
                            "PoseNet's object terms: each NLL weighted by the stop-gradient variance^beta; 0: NLL")
    encoder_precision: Literal["float32", "bfloat16"] = Field(
        "float32", description="the image encoder's arithmetic while training (torch.autocast around the encoder "
        "only; weights, optimizer, heads and tracker stay float32); mor ablate-lnet --study training_precision "
        "compares the two at an equal budget")
    seed: int = Field(0, ge=0)


class CalibrationParams(ParamsModel):
    """Fitting the uncertainty scales on the validation split."""

    max_episodes: int = Field(200, ge=1, description="validation episodes used to fit the scales")
    criterion: Literal["nll", "coverage"] = Field(
        "nll", description="how each uncertainty multiplier is chosen: the NLL's optimum, or the 1/2/3-sigma "
        "coverage closest to nominal; calibrate-lnet fits and reports both, and keeps this one")
    lost_objects: bool = Field(
        False, description="also fit, per group of objects, the probability that a belief is lost (the object "
        "anywhere in the arena: mor.lnet.lost); calibrate-lnet reports every criterion with and without")


#: the filter's tracking rules a profile switches on or off (``mor.lnet.filter.TrackingSettings``)
TRACKING_RULES: tuple[str, ...] = ("data_association", "negative_information")
#: the stated belief's settings a profile chooses rather than the calibration fitting them (``StatedParams.CHOSEN``)
STATED_SETTINGS: tuple[str, ...] = ("not_found_sigma", "search_max_looks", "arena_grid_spacing")


class LNetParams(ParamsModel):
    """Everything the L-Net stages read from a profile."""

    model: LNetConfig = Field(default_factory=LNetConfig)
    train: TrainParams = Field(default_factory=TrainParams)
    calibration: CalibrationParams = Field(default_factory=CalibrationParams)
    eval_episodes: int = Field(200, ge=1, description="test episodes evaluated (all of them if fewer)")
    oracle_episodes: int = Field(50, ge=0, description="oracle-driven Rearrange episodes evaluated live (0: none)")
    compile_step: bool = Field(False, description="the policy stages run the L-Net's streaming step through "
                               "torch.compile: about 1.3x faster on CPU (mor bench lnet), estimates equal up to "
                               "float rounding, about a minute to compile once per process (docs/performance.md)")
    encoder_precision: Literal["float32", "bfloat16"] = Field(
        "float32", description="arithmetic of the image encoder when the L-Net is loaded for inference (load_lnet): "
        "bfloat16 (torch.autocast; the rest of the step stays float32) made the compiled step 1.3x faster on a CPU "
        "with bfloat16 instructions and moved the estimates by up to 2 cm (mor bench lnet, docs/performance.md); "
        "part of the L-Net's identity, so policies trained through one precision are stale under the other")
    data_association: bool = Field(False, description="track whole episodes with the filter's data association "
                                   "(mor.lnet.filter: a measurement two slots claim is shared by how well each belief "
                                   "explains it, and doubtful updates widen the belief); a tracking-time rule, not "
                                   "used in training, fitted and recorded by mor calibrate-lnet")
    gate: float = Field(9.21, gt=0, description="the filter's gate: the squared Mahalanobis distance of an "
                        "innovation beyond which an object measurement is dropped (9.21: chi-square, 2 dof, 99%); "
                        "a tracking-time setting, recorded by mor calibrate-lnet")
    negative_information: bool = Field(False, description="track with the filter's negative information "
                                       "(mor.lnet.unseen: a frame whose PoseNet does not see an object down-weights "
                                       "the part of its belief in the camera's view within PICK's reach, and a "
                                       "confident belief that the frame contradicts widens); needs the visibility "
                                       "head; a tracking-time rule, not used in training, recorded by mor "
                                       "calibrate-lnet")
    not_found_sigma: float = Field(1.0, gt=0, description="metres: a belief wider than this (geometric mean of its "
                                   "standard deviations, uncalibrated) has not found its object, and its stated "
                                   "belief is the search belief (mor.lnet.stated); recorded by mor calibrate-lnet")
    search_max_looks: int = Field(64, ge=1, description="the search belief counts a grid point looked at more often "
                                  "than this as looked at this many times ((1 - q)^64 < 0.002 for the find "
                                  "probabilities q above 0.1 the fit can choose; mor.lnet.search); recorded by mor "
                                  "calibrate-lnet")
    arena_grid_spacing: float = Field(0.1, gt=0, description="metres: the spacing of the arena grid whose points the "
                                      "lost belief's arena shares and the search belief count (3,600 points in a 6 m "
                                      "square; mor.lnet.lost.arena_grid); recorded by mor calibrate-lnet")

    def chosen_settings(self) -> dict[str, Any]:
        """The tracking-time settings this profile chooses, which ``calibrate-lnet`` records and ``load_lnet`` checks
        against the calibration (``mor.lnet.calibration_file.recorded_settings``)."""
        return {**{rule: getattr(self, rule) for rule in TRACKING_RULES}, "gate": self.gate,
                **{name: getattr(self, name) for name in STATED_SETTINGS}}

    @model_validator(mode="after")
    def _tracking_rules_need_the_filter(self) -> LNetParams:
        for rule in TRACKING_RULES:
            if getattr(self, rule) and self.model.tracker != "filter":
                raise ValueError(f"{rule}: needs model.tracker: filter (the LSTM keeps no per-object belief)")
        if self.negative_information and not self.model.visibility:
            raise ValueError("negative_information: needs model.visibility: true (it reads which objects the "
                             "PoseNet does not see)")
        return self


# `mor ablate-lnet --study NAME`: named variants of the profile's LNetConfig, trained and scored at equal budgets.
ABLATIONS: dict[str, dict[str, dict[str, object]]] = {
    "actions": {"with_actions": {"use_actions": True}, "without_actions": {"use_actions": False}},
    "object_head": {"global": {"object_head": "global"}, "attention": {"object_head": "attention"}},
    # Which tracker, and whether the visibility head and the visible-only ego loss earn their place.
    # A key of TrainParams (beta_nll) overrides the training parameters instead.
    "tracker": {
        "lstm": {"tracker": "lstm", "visibility": False},
        "lstm_visibility": {"tracker": "lstm", "visibility": True},
        "filter": {"tracker": "filter", "visibility": False},
        "filter_visibility": {"tracker": "filter", "visibility": True},
        "filter_visibility_beta": {"tracker": "filter", "visibility": True, "beta_nll": 0.5},
    },
    # The default training budget: the same model trained with its encoder in float32 or in bfloat16 (TrainParams).
    "training_precision": {"float32": {"encoder_precision": "float32"},
                           "bfloat16": {"encoder_precision": "bfloat16"}},
}
