"""Every hyper-parameter of policy training and evaluation, validated; no torch import, so configs load fast."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, field_validator, model_validator

from mor.params_model import ParamsModel, Seeds
from mor.policy.names import Task
from mor.policy.variants import POSE_VARIANTS
from mor.sim.rules import PICK_RANGE


class PPOParams(ParamsModel):
    """One policy's PPO run (sb3-contrib MaskablePPO). ``hidden``: the MLP's hidden widths; with the output layer
    four hidden layers make the paper's five-layer MLP (shared by the actor and the critic's shapes)."""

    steps: int = Field(300_000, ge=0, description="environment steps (decisions, for the decision policy); 0 with a "
                                                   "warm start keeps the starting policy as it is")
    n_envs: int = Field(8, ge=1, le=256)
    vec_env: Literal["dummy", "subproc", "batched"] = Field(
        "dummy", description="dummy: the envs in this process; subproc: one process each; batched: the ground truth's "
                             "Pick and Drop as one array-stepped env (mor.policy.batched_env), the rest as dummy")
    env_workers: int = Field(1, ge=1, le=256, description="processes that step the rendered Pick and Drop envs (the "
                                                           "L-Net variants' and the baselines'), each its share in "
                                                           "series (mor.policy.grouped_env); 1: in this process. "
                                                           "Not with vec_env subproc")
    hidden: list[int] = Field(default_factory=lambda: [256, 256, 256, 256], min_length=1)
    n_steps: int = Field(256, ge=2, description="steps per env per rollout")
    batch_size: int = Field(512, ge=2)
    n_epochs: int = Field(10, ge=1)
    learning_rate: float = Field(3e-4, gt=0)
    gamma: float = Field(0.99, gt=0, le=1)
    gae_lambda: float = Field(0.95, gt=0, le=1)
    clip_range: float = Field(0.2, gt=0)
    ent_coef: float = Field(0.01, ge=0)
    vf_coef: float = Field(0.5, ge=0)
    max_grad_norm: float = Field(0.5, gt=0)
    checkpoint_every: int = Field(50_000, ge=1, description="steps between resumable checkpoints")
    device: Literal["cpu", "cuda", "auto"] = Field("cpu", description="where the PPO update runs; auto: CUDA when "
                                                                      "there is one (the paper profile's ResNets)")

    @model_validator(mode="after")
    def _workers_fit(self) -> PPOParams:
        if self.env_workers > self.n_envs:
            raise ValueError(f"env_workers: {self.env_workers} is more than the {self.n_envs} envs (n_envs); lower it")
        if self.env_workers > 1 and self.vec_env == "subproc":
            raise ValueError("env_workers: subproc already runs one process per env; use vec_env dummy or batched")
        return self


class EncoderPretrainParams(ParamsModel):
    """The label-free pretraining of the baselines' ``autoencoder`` encoder (``mor.policy.frame_encoder``)."""

    frames: int = Field(20000, ge=16, description="frames of the exploration walk to learn from")
    episode_steps: int = Field(150, ge=1, description="steps per walk episode")
    steps: int = Field(2000, ge=1, description="Adam steps")
    batch_size: int = Field(64, ge=1, description="frames per step")
    learning_rate: float = Field(1e-3, gt=0)
    latent_channels: int = Field(16, ge=1, description="code channels per 8x8 pixel block")
    validation_share: float = Field(0.05, gt=0, lt=1, description="the last frames, held out")
    log_every: int = Field(100, ge=1, description="steps per log row")
    seed: int = Field(0, ge=0, description="the walk's and the training's seed")


class ImitationParams(ParamsModel):
    """Behaviour cloning from the scripted oracle with DAgger rounds before a baseline skill's PPO
    (``mor.policy.imitation``); ``rounds`` 0: none, the skill starts from its random initialization."""

    rounds: int = Field(0, ge=0, description="the actor's rounds: in round 0 the oracle drives, in later ones the "
                                             "policy drives and the oracle labels (DAgger); then one round for the "
                                             "critic; 0: no imitation")
    round_steps: int = Field(10_000, ge=1, description="env steps per round")
    epochs: int = Field(4, ge=1, description="passes over every label so far after each round")
    batch_size: int = Field(256, ge=1)
    learning_rate: float = Field(3e-4, gt=0, description="Adam's")
    look_first: bool = Field(True, description="Pick's expert turns on the spot until the target is in view before "
                                               "it follows the oracle (mor.policy.imitation.Expert)")
    search_again: bool = Field(False, description="with look_first, Pick's expert also turns on the spot whenever the "
                                                  "target is out of view later in the episode (at most a full turn "
                                                  "in an episode in all); false: only until it first sees it")


class SkillImitationParams(ParamsModel):
    """Each baseline skill's own imitation start: Pick needs more than Drop, whose target is a position it is given
    (docs/assumptions.md, Baselines)."""

    pick: ImitationParams = Field(default_factory=ImitationParams)
    drop: ImitationParams = Field(default_factory=ImitationParams)


class BaselineParams(ParamsModel):
    """The end-to-end CNN baselines (``mor.policy.baselines``): encoder and their Pick and Drop PPO runs."""

    encoder: Literal["nature_cnn", "compact", "resnet18", "resnet50", "autoencoder"] = Field(
        "nature_cnn", description="nature_cnn: SB3's NatureCNN (2 CPU cores; frames >= 36 px); compact: the L-Net's "
                                  "encoder (any frame size); resnet18/50: the paper's; autoencoder: pretrained "
                                  "without labels (mor policy pretrain-encoder) and frozen")
    image_features: int = Field(256, ge=8, description="the encoder's output width (autoencoder: its code's size)")
    share_encoder: bool = Field(True, description="the actor and the critic read one encoder (SB3's default), or each "
                                                  "its own, so that the value loss cannot move the actor's features")
    goal_gating: bool = Field(False, description="the Pick skill's encoder map is gated by its target's class "
                                                 "(Gated-Attention, mor.policy.baselines.BaselineExtractor); false: "
                                                 "the class is only concatenated after the encoder, as the paper's")
    pretrain: EncoderPretrainParams = Field(default_factory=EncoderPretrainParams)
    imitation: SkillImitationParams = Field(default_factory=SkillImitationParams)
    pick: PPOParams = Field(default_factory=PPOParams)
    drop: PPOParams = Field(default_factory=PPOParams)


class ObservationParams(ParamsModel):
    """The derived features of the pose policies' observation (``mor.policy.features``): the free-space rays and
    the search belief's sectors, and the PICK gate read from the same vector. They are part of a policy's signature:
    a policy loads only where they match."""

    clearance_rays_deg: list[float] = Field(
        default_factory=lambda: [-60.0, -30.0, 0.0, 30.0, 60.0], min_length=1,
        description="degrees from the heading, left positive: the free-space rays (mor.policy.clearance)")
    clearance_max_m: float = Field(3.0, gt=0, description="metres: a free-space ray is cut here")
    search_sectors: int = Field(8, ge=1, le=360, description="bearing sectors of equal width around the believed "
                                                            "heading that the search belief's mass is read in")
    pick_gate_probability: float = Field(
        0.0, ge=0.0, lt=1.0,
        description="the PICK gate (mor.policy.pick_gate): a Pick skill of an L-Net variant with uncertainty may PICK "
                    "only where its belief gives the target at least this probability of lying within reach and "
                    "view; 0: off. Not an observation but an action mask read from it, kept here so that a policy's "
                    "signature records it")
    pick_visibility: bool = Field(
        False, description="the Pick skills of the L-Net variants also read the L-Net's detection: each object's and "
                           "the goal's probability of being in view on this frame (the PoseNet's visibility head, "
                           "trained on the rule PICK's view follows); false: they do not")
    search_ring_edges_m: list[float] = Field(
        default_factory=lambda: [PICK_RANGE], min_length=1,
        description="metres: the outer radii of the search sectors' range rings, increasing (the last ring is "
                    "unbounded); the default ring is PICK's reach")

    @field_validator("clearance_rays_deg")
    @classmethod
    def _distinct_rays(cls, rays: list[float]) -> list[float]:
        if len({round(ray) for ray in rays}) != len(rays) or not all(-180.0 < ray <= 180.0 for ray in rays):
            raise ValueError(f"clearance rays must be angles in (-180, 180] degrees at least a whole degree apart "
                             f"(each feature is named by its rounded angle); got {rays}")
        return rays

    @field_validator("search_sectors")
    @classmethod
    def _whole_degree_sectors(cls, sectors: int) -> int:
        if 360 % sectors:
            raise ValueError(f"search sectors must divide 360 (each feature is named by its whole-degree bearing); "
                             f"got {sectors}")
        return sectors

    @field_validator("search_ring_edges_m")
    @classmethod
    def _increasing_rings(cls, edges: list[float]) -> list[float]:
        if edges[0] <= 0 or any(b <= a for a, b in zip(edges, edges[1:])):
            raise ValueError(f"search ring edges must be positive and increasing (metres); got {edges}")
        return edges


class PolicyParams(ParamsModel):
    """Phase I (pick, drop) and phase II (decision) training for each observation variant."""

    training_seeds: Seeds = Field(default_factory=lambda: [0], description="the training runs of every learned "
                                  "variant (mor policy train --seed overrides); a row aggregates over them")
    variants: list[str] = Field(default_factory=lambda: list(POSE_VARIANTS), min_length=1,
                                description="the pose variants mor policy train trains by default")
    pick: PPOParams = Field(default_factory=PPOParams)
    drop: PPOParams = Field(default_factory=PPOParams)
    decision: PPOParams = Field(default_factory=lambda: PPOParams(
        steps=10_000, n_envs=4, n_steps=64, batch_size=64, hidden=[128, 128, 128, 128], checkpoint_every=2_000))
    skills_deterministic: bool = Field(False, description="frozen skills act by their most likely action (True) or "
                                                          "draw from their distribution with a per-episode generator")
    lnet_warm_start: bool = Field(True, description="L-Net variants start from their warm_start variant's policies "
                                                    "(mor.policy.variants; same layout, uncertainty inputs "
                                                    "zero-weighted) and train lnet_steps more")
    baseline: BaselineParams = Field(default_factory=BaselineParams)
    observation: ObservationParams = Field(default_factory=ObservationParams)
    lnet_steps: dict[Task, int] = Field(default_factory=lambda: {"pick": 100_000, "drop": 100_000, "decision": 0},
                                        description="fine-tuning steps of the L-Net variants when warm-started")
    finetune_steps: dict[Task, int] = Field(default_factory=lambda: {"pick": 100_000, "drop": 100_000, "decision": 0},
                                            description="steps a setting with finetune_from_main (paper Tables 3 "
                                                        "and 4) trains the main workspace's policies more")

    @field_validator("variants")
    @classmethod
    def _pose_variants(cls, names: list[str]) -> list[str]:
        unknown = [name for name in names if name not in POSE_VARIANTS]
        if unknown:
            raise ValueError(f"unknown pose variant(s) {unknown}; choose from {', '.join(POSE_VARIANTS)}")
        return names


class EvalParams(ParamsModel):
    """The evaluation protocol: the same ``episodes`` episode seeds per seed for every method."""

    seeds: Seeds = Field(default_factory=lambda: [0, 1, 2, 3, 4])
    episodes: int = Field(100, ge=1, le=100_000)
    n_envs: int = Field(8, ge=1, le=256, description="episodes played in lockstep (one batched forward each step)")
    workers: int = Field(1, ge=1, le=1024, description="jobs (one per task and seed) played at once")
    backend: Literal["process", "ray"] = Field("process", description="the jobs run in worker processes of this "
                                                                      "machine or as Ray tasks (a Ray cluster)")
    horizon: int | None = Field(None, ge=1, description="cap every episode at this many steps (the tiny profile's "
                                                        "tests); None: the tasks' own horizons, 150 / 150 / 1,000")
    bootstrap_resamples: int = Field(10_000, ge=100)
