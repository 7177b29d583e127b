"""The policy's observation layout, the ground-truth and L-Net pose sources, and their agreement."""

from __future__ import annotations

import warnings
from collections.abc import Callable

import gymnasium as gym
import numpy as np
import pytest
import torch
from gymnasium.utils.env_checker import check_env as gymnasium_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env
from stable_baselines3.common.vec_env import DummyVecEnv

from mor.errors import ConfigError
from mor.lnet.calibration_file import FittedCalibration
from mor.lnet.model import LNet
from mor.lnet.params import LNetConfig
from mor.lnet.runtime import LNetRunner
from mor.policy.baselines import BaselineObservation
from mor.policy.belief import PoseBelief
from mor.policy.envs import make_policy_env, make_task_env, variant_sim
from mor.policy.features import ObservationLayout, feature_names, observation_vector
from mor.policy.lnet_tracking import LNetTracker, LNetVecObservation
from mor.policy.names import TASKS
from mor.policy.observations import GroundTruthTracker
from mor.policy.params import ObservationParams
from mor.policy.variants import POSE_VARIANTS, VARIANTS
from mor.sim.arena import Arena
from mor.sim.config import SimConfig
from mor.sim.rules import Action

SIM = SimConfig(n_objects=2, image_size=16)
ARENA = Arena.build("square", 6.0)


def _belief(agent=(0.0, 0.0, 0.0), objects=((2.0, 0.0), (0.0, 1.0))) -> PoseBelief:
    return PoseBelief.from_truth(np.array([agent]), np.array([objects]))


@pytest.mark.parametrize("task", TASKS)
@pytest.mark.parametrize("uncertainty", [True, False])
def test_the_vector_has_one_entry_per_named_feature(task: str, uncertainty: bool) -> None:
    goal = {"pick": np.array([1]), "drop": np.array([[1.0, 1.0]]), "decision": np.zeros((1, 2, 2))}[task]
    vector = observation_vector(_belief(), np.array([2]), task, goal, ObservationLayout(uncertainty), ARENA)
    assert vector.shape == (1, len(feature_names(task, 2, ObservationLayout(uncertainty))))
    assert vector.dtype == np.float32


def test_egocentric_goal_features_are_distance_and_bearing_in_the_agent_frame() -> None:
    belief = _belief(agent=(0.0, 0.0, np.pi / 2))  # facing north (+y)
    vector = observation_vector(belief, np.array([2]), "pick", np.array([1]), ObservationLayout(False), ARENA)[0]
    named = dict(zip(feature_names("pick", 2, ObservationLayout(False)), vector, strict=True))
    assert named["goal_distance"] == pytest.approx(1.0)  # object 1 at (0, 1): straight ahead
    assert named["goal_cos_bearing"] == pytest.approx(1.0)
    assert named["object0_sin_bearing"] == pytest.approx(-1.0, abs=1e-6)  # object 0 at (2, 0): to the right


def test_covariances_are_rotated_into_the_agent_frame() -> None:
    truth = _belief(agent=(0.0, 0.0, np.pi / 2))
    belief = PoseBelief(truth.agent_mean, np.array([[[4.0, 0.0], [0.0, 1.0]]], np.float32), truth.heading,
                        np.array([0.25], np.float32), truth.object_mean, np.zeros((1, 2, 2, 2), np.float32))
    named = dict(zip(feature_names("drop", 2, ObservationLayout()),
                     observation_vector(belief, np.array([2]), "drop", np.array([[1.0, 1.0]]), ObservationLayout(),
                                        ARENA)[0],
                     strict=True))
    assert named["agent_sigma_forward"] == pytest.approx(1.0)  # world y is forward when facing north
    assert named["agent_sigma_left"] == pytest.approx(2.0)
    assert named["heading_sigma"] == pytest.approx(0.5)


def test_ground_truth_observations_render_nothing_and_carry_zero_uncertainty() -> None:
    env = make_policy_env("pick", SIM, GroundTruthTracker(), ObservationLayout())
    vector, info = env.reset(seed=3)
    assert env.unwrapped._scene is None  # the fast path never builds the MuJoCo scene
    named = dict(zip(feature_names("pick", 2, ObservationLayout()), vector, strict=True))
    assert named["agent_x"] == pytest.approx(info["agent_pose"][0])
    assert named["agent_sigma_forward"] == 0.0 and named["goal_sigma_left"] == 0.0
    env.close()


def _runner() -> LNetRunner:
    torch.manual_seed(0)
    return LNetRunner(LNet(LNetConfig(feature_dim=16, mlp_hidden=16, lstm_hidden=16)), FittedCalibration(), 16,
                        "test")


def test_an_lnet_pick_skill_reads_the_lnets_detection_only_where_the_profile_asks() -> None:
    """``pick_visibility`` adds each object's and the goal's in-view probability (the PoseNet's visibility head) to
    the L-Net variants' Pick vector, and to nothing else."""
    detecting = ObservationParams(pick_visibility=True)
    layout = ObservationLayout.of(VARIANTS["lnet"], detecting)
    plain = feature_names("pick", 2, ObservationLayout.of(VARIANTS["lnet"], ObservationParams()))
    assert feature_names("pick", 2, layout) == plain + ["object0_visible", "object1_visible", "goal_visible"]
    for variant, task in (("lnet", "drop"), ("gt_pose", "pick")):  # neither the Drop skill nor the truth's Pick
        assert feature_names(task, 2, ObservationLayout.of(VARIANTS[variant], detecting)) == feature_names(
            task, 2, ObservationLayout.of(VARIANTS[variant], ObservationParams()))
    torch.manual_seed(0)
    runner = LNetRunner(LNet(LNetConfig(feature_dim=16, mlp_hidden=16, lstm_hidden=16, visibility=True)),
                        FittedCalibration(), 16, "test")
    env = make_policy_env("pick", SIM, LNetTracker(runner), layout)
    vector, _ = env.reset(seed=5)
    for action in (Action.MOVE, Action.TURN_LEFT, Action.MOVE):
        named = dict(zip(feature_names("pick", 2, layout), vector, strict=True))
        seen = [named["object0_visible"], named["object1_visible"]]
        assert all(0.0 < p < 1.0 for p in seen)
        assert named["goal_visible"] == seen[env.unwrapped.goal_object]
        vector = env.step(int(action))[0]
    blind = make_policy_env("pick", SIM, LNetTracker(_runner()), layout)  # an L-Net without the head
    with pytest.raises(ValueError, match="pick_visibility: this belief has no detection"):
        blind.reset(seed=5)


def test_the_batched_lnet_wrapper_equals_one_tracker_per_env_across_episode_ends() -> None:
    """One forward per vector step (two when an episode is truncated) gives what a per-env tracker gives: a
    truncated episode's terminal observation is its last frame's vector; a terminated one has none (SB3 never
    bootstraps from it)."""
    runner, n_envs, steps, horizon = _runner(), 2, 60, 6
    vec = LNetVecObservation(DummyVecEnv([lambda: make_task_env("pick", SIM, True, horizon=horizon)] * n_envs),
                             runner, "pick", 2, ObservationLayout())
    vec.seed(7)
    singles = [make_policy_env("pick", SIM, LNetTracker(runner), ObservationLayout(), horizon=horizon)
               for _ in range(n_envs)]
    batched = vec.reset()
    single = [env.reset(seed=7 + i)[0] for i, env in enumerate(singles)]
    rng, ends = np.random.default_rng(0), {"terminated": 0, "truncated": 0}
    for _ in range(steps):
        np.testing.assert_allclose(batched, np.stack(single), atol=1e-5)
        actions = rng.choice([0, 1, 2, 3], n_envs, p=[0.5, 0.2, 0.2, 0.1])
        batched, _, dones, infos = vec.step(actions)
        for i, env in enumerate(singles):
            vector, _, terminated, truncated, _ = env.step(int(actions[i]))
            assert dones[i] == (terminated or truncated)
            assert infos[i].get("TimeLimit.truncated", False) == truncated
            if truncated:
                np.testing.assert_allclose(infos[i]["terminal_observation"], vector, atol=1e-5)
            if terminated:
                assert "terminal_observation" not in infos[i]
            if dones[i]:
                ends["truncated" if truncated else "terminated"] += 1
                vector = env.reset()[0]  # DummyVecEnv resets without a seed: the env's own generator goes on
            single[i] = vector
    assert min(ends.values()) > 0, f"the test must cross both kinds of episode end: {ends}"


def test_the_batched_lnet_wrapper_gates_pick_as_each_env_does() -> None:
    """With the PICK gate on, MaskablePPO's masks from the batched wrapper are each env's gated ``action_masks``."""
    from sb3_contrib.common.maskable.utils import get_action_masks

    from mor.policy.pick_gate import PickGate

    runner, n_envs = _runner(), 2
    layout = ObservationLayout(features=ObservationParams(pick_gate_probability=0.05), gate=True)
    vec = LNetVecObservation(DummyVecEnv([lambda: make_task_env("pick", SIM, True)] * n_envs), runner, "pick", 2,
                             layout)
    vec.seed(3)
    singles = [make_policy_env("pick", SIM, LNetTracker(runner), layout) for _ in range(n_envs)]
    vec.reset()
    for i, env in enumerate(singles):
        env.reset(seed=3 + i)
    gate = PickGate.of(feature_names("pick", 2, layout), 0.05)
    rng, gated = np.random.default_rng(1), 0
    for _ in range(25):
        masks = get_action_masks(vec)
        np.testing.assert_array_equal(masks, np.stack([env.action_masks() for env in singles]))
        np.testing.assert_array_equal(masks, gate.mask(vec.vectors, np.stack([env.unwrapped.action_masks()
                                                                               for env in singles])))
        gated += int((~masks[:, 3]).sum())
        actions = rng.choice([0, 1, 2], n_envs)  # no PICK: the episodes go on
        vec.step(actions)
        for i, env in enumerate(singles):
            env.step(int(actions[i]))
    assert gated > 0, "the test must meet a masked PICK"


def test_clearance_is_the_free_distance_to_walls_and_floor_objects_but_not_the_held_one() -> None:
    from mor.policy.clearance import clearance
    from mor.sim.catalog import OBJECT_RADIUS
    from mor.sim.rules import AGENT_RADIUS

    rays = ObservationParams().clearance_rays_deg
    ahead = rays.index(0.0)

    def free(belief: PoseBelief, held: int) -> np.ndarray:
        return clearance(belief, np.array([held]), ARENA, rays, 3.0)[0]

    belief = _belief(agent=(0.0, 0.0, 0.0), objects=((1.0, 0.0), (0.0, 2.0)))
    assert free(belief, 2)[ahead] == pytest.approx(1.0 - AGENT_RADIUS - OBJECT_RADIUS)
    carried = free(belief, 0)  # object 0 is held: the ray reaches the east wall
    assert carried[ahead] == pytest.approx(min(3.0 - AGENT_RADIUS, 3.0))
    assert free(_belief(agent=(2.5, 0.0, 0.0)), 2)[ahead] == pytest.approx(0.5 - AGENT_RADIUS)


def test_the_rays_and_their_cut_are_the_profiles_settings() -> None:
    """policy.observation's rays name and fill the clearance entries; its cut caps them."""
    settings = ObservationParams(clearance_rays_deg=[0.0, 90.0, 180.0], clearance_max_m=1.5)
    layout = ObservationLayout(features=settings)
    belief = _belief(agent=(0.0, 0.0, 0.0), objects=((1.0, 0.0), (0.0, 2.0)))
    named = dict(zip(feature_names("drop", 2, layout),
                     observation_vector(belief, np.array([2]), "drop", np.array([[1.0, 1.0]]), layout, ARENA)[0],
                     strict=True))
    assert [name for name in named if name.startswith("clearance_")] == \
        ["clearance_+0deg", "clearance_+90deg", "clearance_+180deg"]
    assert named["clearance_+180deg"] == pytest.approx(1.5)  # 3 m to the west wall, cut at 1.5
    assert named["clearance_+0deg"] < 1.0  # object 0 ahead
    with pytest.raises(ValueError, match="a whole degree apart"):
        ObservationParams(clearance_rays_deg=[0.0, 0.0])


def test_a_task_that_is_not_a_policys_names_the_policies_and_a_policy_is_not_a_world_task() -> None:
    with pytest.raises(ConfigError, match=r"^task: 'rearrange' is not a policy; choose one of pick, drop, decision$"):
        make_policy_env("rearrange", SIM, GroundTruthTracker(), ObservationLayout())
    with pytest.raises(ConfigError, match=r"^task: 'decision' is not one of the world's tasks; choose one of pick, "
                                          r"drop, rearrange$"):
        make_task_env("decision", SIM, render_frames=False)


class _EndingSkill:
    """A stand-in skill that ends its part of a decision at once (PICK, then DROP): the decision env's checks stay
    a few primitive steps long."""

    def __init__(self, action: Action) -> None:
        self.action = action

    def act_batch(self, inputs: np.ndarray, masks: np.ndarray, rngs: list | None = None) -> np.ndarray:
        return np.full(len(masks), int(self.action))


def _policy_envs() -> dict[str, Callable[[], gym.Env]]:
    """Every policy environment ``mor.policy.envs`` makes: each variant's Pick and Drop (the L-Net's through a tiny
    untrained L-Net), the decision's over untrained skills, and each baseline's."""
    envs: dict[str, Callable[[], gym.Env]] = {}
    arena = Arena.build(SIM.arena, SIM.arena_size)
    trackers = {"gt_pose": GroundTruthTracker, "lnet": lambda: LNetTracker(_runner()),
                "lnet_no_uncertainty": lambda: LNetTracker(_runner()),
                "lnet_search": lambda: LNetTracker(_runner(), arena)}
    assert set(trackers) == set(POSE_VARIANTS)
    for variant, tracker in trackers.items():
        layout = ObservationLayout.of(VARIANTS[variant], ObservationParams())
        for task in ("pick", "drop"):
            envs[f"{variant}-{task}"] = lambda t=task, m=tracker, lay=layout: make_policy_env(t, SIM, m(), lay)
        if layout.uncertainty:
            envs[f"{variant}-decision"] = lambda m=tracker, lay=layout: make_policy_env(
                "decision", SIM, m(), lay, (_EndingSkill(Action.PICK), _EndingSkill(Action.DROP)))
    for variant in (v for v in VARIANTS.values() if v.is_baseline):
        for task in ("pick", "drop"):
            envs[f"{variant.name}-{task}"] = lambda t=task, v=variant: BaselineObservation(
                make_task_env(t, variant_sim(v, SIM), render_frames=True), v.baseline_input)
    return envs


POLICY_ENVS = _policy_envs()
#: What the checkers advise against by design: a wrapper is checked as it is (not its unwrapped MOR env), the
#: policy vector is unbounded (covariances), and the tests' 16-pixel frames are below NatureCNN's 36 (the compact
#: encoder takes any size).
ADVICE = ("is different from the unwrapped version", "observation space minimum value is -infinity",
          "observation space maximum value is infinity", "minimal resolution for an image is 36x36")


@pytest.mark.parametrize("checker", [lambda env: gymnasium_check_env(env, skip_render_check=True), sb3_check_env],
                         ids=["gymnasium", "sb3"])
@pytest.mark.parametrize("name", sorted(POLICY_ENVS))
def test_every_policy_env_passes_gymnasiums_and_sb3s_checks(name: str, checker: Callable[[gym.Env], None]) -> None:
    env = POLICY_ENVS[name]()
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the checkers' complaints are warnings: make them fail
        for advice in ADVICE:
            warnings.filterwarnings("ignore", message=f".*{advice}")
        checker(env)
    env.close()
