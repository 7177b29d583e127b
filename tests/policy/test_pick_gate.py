"""The PICK gate: the belief's probability that the target lies in reach and view, read from the Pick vector; the
gate masks PICK wherever a Pick skill of an L-Net variant with uncertainty meets it, and a policy records it."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from mor.errors import ConfigError
from mor.policy.envs import make_policy_env
from mor.policy.features import ObservationLayout, feature_names
from mor.policy.hierarchy import Skill, skill_mask
from mor.policy.observations import GroundTruthTracker
from mor.policy.params import ObservationParams
from mor.policy.pick_gate import GATE_FEATURES, PickGate, reach_probability
from mor.policy.signature import PolicySignature, check_signature, warm_start_names, write_signature
from mor.policy.variants import VARIANTS
from mor.sim.config import SimConfig
from mor.sim.geometry import wrap_angle
from mor.sim.rules import CAMERA_FOV, N_ACTIONS, PICK_RANGE, Action

SIM = SimConfig(n_objects=2, image_size=16)
GATED = ObservationParams(pick_gate_probability=0.6)


def _entries(distance: float, bearing_deg: float, sigma: float = 0.0, heading_sigma: float = 0.0) -> np.ndarray:
    """One row of ``GATE_FEATURES``: the target at ``distance`` m and ``bearing_deg``, round σ for target and agent."""
    b = np.deg2rad(bearing_deg)
    return np.array([[distance, np.cos(b), np.sin(b), sigma, sigma, 0.0, sigma, sigma, 0.0, heading_sigma]])


def test_the_reach_probability_is_the_share_of_the_belief_in_reach_and_view() -> None:
    assert reach_probability(_entries(0.5, 0.0))[0] == 1.0
    assert reach_probability(_entries(1.2, 0.0))[0] == 0.0  # beyond PICK's reach
    assert reach_probability(_entries(0.5, 40.0))[0] == 0.0  # outside the camera's 60 degrees
    at_edge = reach_probability(_entries(PICK_RANGE, 0.0, sigma=0.1))[0]
    assert 0.35 < at_edge < 0.65  # half the mass beyond the reach
    wide = reach_probability(_entries(0.5, 0.0, sigma=1.0))[0]
    near = reach_probability(_entries(0.5, 0.0, sigma=0.05))[0]
    assert near == 1.0 and 0.0 < wide < 0.5  # a wide belief puts most of its mass out of reach or view
    turned = reach_probability(_entries(0.5, 25.0, heading_sigma=np.deg2rad(10.0)))[0]
    assert 0.6 < turned < 0.8  # 5 degrees inside the edge of the view: P(10 z < 5) = 0.69 for z ~ N(0, 1)
    assert np.rad2deg(CAMERA_FOV / 2) == pytest.approx(30.0)


class _AlwaysPick(Skill):
    """A skill that would PICK wherever it may (else turn left)."""

    def __init__(self, gate: PickGate | None) -> None:
        super().__init__(None, deterministic=True, gate=gate)

    def probabilities(self, vectors: np.ndarray, masks: np.ndarray) -> np.ndarray:
        if self.gate is not None:
            masks = self.gate.mask(vectors, masks)
        p = np.where(masks, 0.01, 0.0)
        p[:, Action.PICK] = np.where(masks[:, Action.PICK], 1.0, 0.0)
        return p / p.sum(-1, keepdims=True)


def test_a_gated_skill_picks_only_where_its_belief_says_the_target_is_in_reach() -> None:
    layout = ObservationLayout.of(VARIANTS["lnet"], GATED)
    names = feature_names("pick", 2, layout)
    vectors = np.zeros((3, len(names)), np.float32)
    columns = [names.index(name) for name in GATE_FEATURES]
    vectors[:, columns] = np.concatenate([_entries(0.5, 0.0), _entries(1.5, 0.0), _entries(0.9, 0.0, sigma=0.3)])
    masks = np.stack([skill_mask("pick")] * 3)
    gated = _AlwaysPick(PickGate.of(names, 0.6)).act_batch(vectors, masks)
    assert list(gated == Action.PICK) == [True, False, False]
    assert list(_AlwaysPick(None).act_batch(vectors, masks) == Action.PICK) == [True, True, True]
    assert PickGate.of(names, 0.0) is None
    with pytest.raises(ValueError, match="missing goal_sigma_forward"):
        PickGate.of(feature_names("pick", 2, ObservationLayout.of(VARIANTS["lnet_no_uncertainty"], GATED)), 0.6)


def test_the_gated_env_masks_pick_where_the_truth_is_out_of_reach_or_view() -> None:
    # the truth's belief is a point mass: the gate then allows PICK exactly where the target is in reach and view
    layout = ObservationLayout(uncertainty=True, features=GATED, gate=True)
    env = make_policy_env("pick", SIM, GroundTruthTracker(), layout)
    allowed = []
    for episode in range(40):
        env.reset(seed=episode)
        base = env.unwrapped
        offset = base.state.floor_positions[base.goal_object] - base.state.agent_pose[:2]
        bearing = wrap_angle(np.arctan2(offset[1], offset[0]) - base.state.agent_pose[2])
        expected = np.linalg.norm(offset) <= PICK_RANGE and abs(bearing) <= CAMERA_FOV / 2
        mask = env.action_masks()
        assert mask.shape == (N_ACTIONS,) and mask[Action.PICK] == expected
        allowed.append(expected)
    assert any(allowed) and not all(allowed)  # the episodes meet both cases
    ungated = make_policy_env("pick", SIM, GroundTruthTracker(), ObservationLayout(uncertainty=True, features=GATED))
    ungated.reset(seed=0)
    assert ungated.action_masks()[Action.PICK]  # the truth's own variant has no gate


def test_a_policy_records_its_gate_and_plays_with_it(tmp_path: Path) -> None:
    lnet = PolicySignature.of("pick", VARIANTS["lnet"], 2, "square", "v", GATED)
    assert lnet.features.pick_gate_probability == 0.6
    for name in ("gt_pose", "lnet_no_uncertainty"):  # only the L-Net's beliefs with uncertainty read it
        assert PolicySignature.of("pick", VARIANTS[name], 2, "square", "v", GATED).features.pick_gate_probability == 0
    for task in ("drop", "decision"):  # and only their Pick skills: a Drop trained without the gate still loads
        write_signature(tmp_path / "meta.json", PolicySignature.of(task, VARIANTS["lnet"], 2, "square", "v",
                                                                   ObservationParams()))
        check_signature(tmp_path / "meta.json", PolicySignature.of(task, VARIANTS["lnet"], 2, "square", "v", GATED))
    write_signature(tmp_path / "meta.json", lnet)
    gate = PickGate.recorded(tmp_path / "meta.json")
    assert gate is not None and gate.probability == 0.6
    assert PickGate.recorded(tmp_path / "missing.json") is None
    with pytest.raises(ConfigError, match=r"pick_gate_probability=0.6 but this run needs 0.0"):
        check_signature(tmp_path / "meta.json", PolicySignature.of("pick", VARIANTS["lnet"], 2, "square", "v",
                                                                   ObservationParams()))
    # a gated run may start from an ungated policy: the gate masks an action and changes no feature
    write_signature(tmp_path / "meta.json", PolicySignature.of("pick", VARIANTS["lnet"], 2, "square", "v",
                                                               ObservationParams()))
    assert warm_start_names(tmp_path / "meta.json", lnet) == lnet.observation


def test_a_policy_records_whether_it_reads_the_lnets_detection(tmp_path: Path) -> None:
    detecting = ObservationParams(pick_visibility=True)
    lnet = PolicySignature.of("pick", VARIANTS["lnet"], 2, "square", "v", detecting)
    assert lnet.features.pick_visibility and lnet.observation[-1] == "goal_visible"
    for task, name in (("drop", "lnet"), ("pick", "gt_pose")):  # only the L-Net variants' Pick skills read it
        assert not PolicySignature.of(task, VARIANTS[name], 2, "square", "v", detecting).features.pick_visibility
    old = PolicySignature.of("pick", VARIANTS["lnet"], 2, "square", "v", ObservationParams())
    write_signature(tmp_path / "meta.json", old)
    with pytest.raises(ConfigError, match=r"pick_visibility=False but this run needs True"):
        check_signature(tmp_path / "meta.json", lnet)
    # a detecting run may start from a policy without it: the new features have names of their own (zero weights)
    assert warm_start_names(tmp_path / "meta.json", lnet) == old.observation
    recorded = json.loads((tmp_path / "meta.json").read_text())
    del recorded["features"]["pick_visibility"]  # a meta.json written before the setting existed still loads
    (tmp_path / "meta.json").write_text(json.dumps(recorded))
    check_signature(tmp_path / "meta.json", old)
