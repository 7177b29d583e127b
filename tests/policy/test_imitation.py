"""Behaviour cloning from the oracle with DAgger rounds (``mor.policy.imitation``) on tiny rendered baseline envs."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest
import torch
from sb3_contrib import MaskablePPO
from stable_baselines3.common.vec_env import DummyVecEnv

from mor.policy.baselines import BaselineObservation, baseline_extractor
from mor.policy.envs import make_task_env
from mor.policy.imitation import (Expert, LabelBuffer, Labelled, clone_oracle, discounted_returns, drive, expert_actions,
                                  fit)
from mor.policy.params import BaselineParams, ImitationParams
from mor.policy.policy_file import load_policy_file, save_policy_file
from mor.sim.config import SimConfig
from mor.sim.oracle import Oracle
from mor.sim.rules import Action, visible
from mor.sim.tasks import PickEnv

SIM = SimConfig(n_objects=3, image_size=32)


def baseline_envs(task: str, n: int = 2) -> DummyVecEnv:
    return DummyVecEnv([lambda: BaselineObservation(make_task_env(task, SIM, render_frames=True), "img")] * n)


def new_policy(env: DummyVecEnv, seed: int = 0) -> torch.nn.Module:
    torch.set_num_threads(1)
    kwargs = baseline_extractor(BaselineParams(encoder="compact", image_features=16), "pick")
    return MaskablePPO("MultiInputPolicy", env, seed=seed, n_steps=8, batch_size=8,
                       policy_kwargs={"net_arch": [16, 16], **kwargs}).policy


def experts_of(env: DummyVecEnv, look_first: bool = False) -> list[Expert]:
    return [Expert(e, look_first) for e in env.envs]


def test_discounted_returns_stop_at_each_episodes_end() -> None:
    rewards = np.array([[1.0], [2.0], [3.0], [4.0]])
    dones = np.array([[0.0], [1.0], [0.0], [0.0]])
    returns = discounted_returns(rewards, dones, gamma=0.5)
    assert returns[:, 0].tolist() == [1 + 0.5 * 2, 2, 3 + 0.5 * 4, 4]


@pytest.mark.parametrize("task", ["pick", "drop"])
def test_the_labels_are_the_oracles_actions_and_the_oracle_drives_round_zero(task: str) -> None:
    env = baseline_envs(task)
    experts = experts_of(env)
    env.seed(4)
    env.reset()
    expected = expert_actions(env, experts_of(env))
    data, figures = drive(env, experts, None, steps=12, gamma=0.99, seed=4, bar=_no_bar())
    assert len(data) == 12 and data.actions[:2].tolist() == expected.tolist()
    assert data.observations["image"].shape == (12, 3, 32, 32)
    assert data.masks[np.arange(12), data.actions].all()  # the oracle only takes allowed actions
    assert np.isnan(figures["agreement"])
    env.close()


def test_the_actor_learns_the_oracles_labels_and_the_critic_its_returns_without_moving_the_actor() -> None:
    env = baseline_envs("pick")
    policy = new_policy(env)
    data, _ = drive(env, experts_of(env), None, steps=64, gamma=0.99, seed=0, bar=_no_bar())
    settings = ImitationParams(rounds=1, epochs=1, batch_size=32, learning_rate=3e-3)
    still = settings.model_copy(update={"learning_rate": 1e-12})

    def losses() -> tuple[float, float]:  # (action_nll, value_mse), each measured by a pass that moves nothing
        return (fit(policy, data, still, torch.Generator().manual_seed(0))["action_nll"],
                fit(policy, data, still, torch.Generator().manual_seed(0), critic=True)["value_mse"])

    nll_before, _ = losses()
    fit(policy, data, settings.model_copy(update={"epochs": 30}), torch.Generator().manual_seed(0))
    nll_cloned, mse_cloned = losses()
    assert nll_cloned < 0.7 * nll_before
    fit(policy, data, settings.model_copy(update={"epochs": 30}), torch.Generator().manual_seed(0), critic=True)
    nll_after, mse_after = losses()
    assert mse_after < 0.5 * mse_cloned
    assert nll_after == pytest.approx(nll_cloned, abs=1e-5)
    env.close()


def test_the_label_buffer_keeps_every_round_in_order_and_refuses_to_overflow() -> None:
    def part(start: int, n: int) -> Labelled:
        steps = np.arange(start, start + n)
        return Labelled({"image": np.repeat(steps[:, None], 3, 1).astype(np.uint8)}, steps, np.ones((n, 2), bool),
                        steps.astype(np.float32))

    buffer = LabelBuffer(capacity=5)
    buffer.add(part(0, 2))
    buffer.add(part(2, 3))
    labels = buffer.labels()
    assert labels.actions.tolist() == [0, 1, 2, 3, 4] and labels.observations["image"][:, 0].tolist() == [0, 1, 2, 3, 4]
    with pytest.raises(ValueError, match="overflow"):
        buffer.add(part(5, 1))


def pick_env_where_the_target_is(in_view: bool) -> tuple[DummyVecEnv, PickEnv]:
    """One baseline Pick env reset with the first seed whose target starts in view (or out of view)."""
    env = baseline_envs("pick", n=1)
    for seed in range(20):
        env.seed(seed)
        env.reset()
        base = env.envs[0].unwrapped
        if visible(base.state, base.goal_object) == in_view:
            return env, base
    raise AssertionError(f"no seed below 20 starts with the target {'in' if in_view else 'out of'} view")


def test_the_pick_expert_looks_for_the_target_before_it_follows_the_oracle() -> None:
    env, base = pick_env_where_the_target_is(in_view=False)
    expert, oracle = Expert(env.envs[0], look_first=True), Oracle(base.arena, base.noise)
    turns = 0
    while not visible(base.state, base.goal_object) and turns < Expert.FULL_TURN:
        assert expert.act(env.envs[0]) == Action.TURN_LEFT
        env.step(np.array([Action.TURN_LEFT]))
        turns += 1
    assert 0 < turns
    assert expert.act(env.envs[0]) == oracle.pick(base.state, base.goal_object)
    env.close()


def test_the_pick_expert_that_searches_again_turns_left_whenever_the_target_leaves_the_view() -> None:
    env, base = pick_env_where_the_target_is(in_view=True)
    wrapped, oracle = env.envs[0], Oracle(base.arena, base.noise)
    again, once = Expert(wrapped, look_first=True, search_again=True), Expert(wrapped, look_first=True)
    assert again.act(wrapped) == once.act(wrapped) == oracle.pick(base.state, base.goal_object)  # seen at once
    while visible(base.state, base.goal_object):
        env.step(np.array([Action.TURN_RIGHT]))
    assert again.act(wrapped) == Action.TURN_LEFT
    assert once.act(wrapped) == oracle.pick(base.state, base.goal_object)
    again.turns = Expert.FULL_TURN  # a full turn spent searching in this episode: the oracle drives
    assert again.act(wrapped) == oracle.pick(base.state, base.goal_object)
    again.reset()
    assert again.act(wrapped) == Action.TURN_LEFT
    env.close()


def test_clone_oracle_logs_its_rounds_and_repeats_itself_with_the_same_seed(tmp_path: Path) -> None:
    settings = ImitationParams(rounds=2, round_steps=16, epochs=1, batch_size=8)
    weights = []
    for run in ("a", "b"):
        env = baseline_envs("pick")
        policy = new_policy(env)
        rows = clone_oracle(policy, env, settings, 0.99, seed=3, log_path=tmp_path / run / "imitation.csv",
                            progress=False)
        env.close()
        weights.append(torch.cat([p.detach().flatten() for p in policy.parameters()]))
        with (tmp_path / run / "imitation.csv").open() as handle:
            logged = list(csv.DictReader(handle))
        assert [row["driver"] for row in logged] == ["expert", "policy", "policy"] == [r["driver"] for r in rows]
        assert [row["trains"] for row in logged] == ["actor", "actor", "critic"]
        assert [int(row["labels"]) for row in logged] == [16, 32, 16]
        assert 0.0 <= float(logged[1]["agreement"]) <= 1.0
    assert torch.equal(weights[0], weights[1])


def _no_bar() -> object:
    class Bar:
        def update(self, n: int) -> None:
            pass

    return Bar()


@pytest.mark.parametrize("share", [True, False])
def test_a_saved_baseline_acts_as_it_did_whether_or_not_its_critic_has_its_own_encoder(tmp_path: Path,
                                                                                      share: bool) -> None:
    env = baseline_envs("pick", n=1)
    kwargs = baseline_extractor(BaselineParams(encoder="compact", image_features=16, share_encoder=share), "pick")
    policy = MaskablePPO("MultiInputPolicy", env, seed=0, policy_kwargs={"net_arch": [16], **kwargs}).policy
    save_policy_file(policy, tmp_path / "policy.pth")
    loaded = load_policy_file(tmp_path / "policy.pth")
    assert loaded.share_features_extractor is share
    observation, _ = policy.obs_to_tensor(env.reset())
    torch.testing.assert_close(loaded.get_distribution(observation).distribution.logits,
                               policy.get_distribution(observation).distribution.logits)
    env.close()
