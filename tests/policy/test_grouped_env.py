"""The grouped worker processes (mor.policy.grouped_env) against a DummyVecEnv of the same rendered MOR envs: the same
observations, rewards, dones, infos and attributes, step by step, across episode ends."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pydantic
import pytest
import torch
from stable_baselines3.common.vec_env import DummyVecEnv

from mor.lnet.calibration_file import FittedCalibration
from mor.lnet.model import LNet
from mor.lnet.params import LNetConfig
from mor.lnet.runtime import LNetRunner
from mor.policy.envs import make_task_env, make_training_env
from mor.policy.grouped_env import GroupedSubprocVecEnv
from mor.policy.signature import PolicySignature
from mor.policy.params import ObservationParams, PPOParams
from mor.policy.train import train_policy
from mor.policy.variants import VARIANTS
from mor.sim.config import SimConfig

SIM = SimConfig(image_size=16)
N_ENVS = 5


def _fns(horizon: int) -> list:
    return [lambda: make_task_env("pick", SIM, render_frames=True, horizon=horizon)] * N_ENVS


def _assert_same_observations(grouped: dict, dummy: dict) -> None:
    assert grouped.keys() == dummy.keys()
    for key in dummy:
        np.testing.assert_array_equal(grouped[key], dummy[key], err_msg=key)


def test_grouped_workers_step_as_one_process_does() -> None:
    dummy, grouped = DummyVecEnv(_fns(horizon=6)), GroupedSubprocVecEnv(_fns(horizon=6), n_workers=2)
    try:
        assert grouped.shares == [[0, 1, 2], [3, 4]]
        for env in (dummy, grouped):
            env.seed(11)
        _assert_same_observations(grouped.reset(), dummy.reset())
        rng, ends, truncations = np.random.default_rng(0), 0, 0
        for _ in range(20):
            masks = np.stack(dummy.env_method("action_masks"))
            np.testing.assert_array_equal(np.stack(grouped.env_method("action_masks")), masks)
            actions = np.argmax(masks * rng.random(masks.shape), axis=1)
            got, want = grouped.step(actions), dummy.step(actions)
            _assert_same_observations(got[0], want[0])
            np.testing.assert_array_equal(got[1], want[1])
            np.testing.assert_array_equal(got[2], want[2])
            for info, expected in zip(got[3], want[3], strict=True):
                assert info.keys() == expected.keys()
                if "terminal_observation" in expected:
                    _assert_same_observations(info["terminal_observation"], expected["terminal_observation"])
                    truncations += expected["TimeLimit.truncated"]
            ends += int(want[2].sum())
        assert ends > N_ENVS and truncations > 0  # episodes ended both ways, and restarted alike
        assert grouped.get_attr("horizon", indices=[4, 0]) == dummy.get_attr("horizon", indices=[4, 0])
        grouped.set_attr("horizon", 9, indices=[1, 3])
        assert grouped.get_attr("horizon") == [6, 9, 6, 9, 6]
        assert grouped.env_is_wrapped(DummyVecEnv) == [False] * N_ENVS
        assert grouped.has_attr("action_masks") and not grouped.has_attr("no_such_attribute")
    finally:
        dummy.close()
        grouped.close()


def test_an_lnet_skill_trains_to_the_same_weights_in_two_workers(tmp_path: Path) -> None:
    torch.manual_seed(0)
    runner = LNetRunner(LNet(LNetConfig(feature_dim=16, mlp_hidden=16, lstm_hidden=16)), FittedCalibration(), 16,
                        "test")
    sim, features = SimConfig(n_objects=2, image_size=16), ObservationParams()
    signature = PolicySignature.of("pick", VARIANTS["lnet"], 2, "square", "test", features)
    weights = []
    for workers in (1, 2):
        params = PPOParams(steps=64, n_envs=3, n_steps=16, batch_size=16, n_epochs=1, hidden=[8, 8],
                           checkpoint_every=32, env_workers=workers)
        train_policy(lambda: make_training_env("pick", VARIANTS["lnet"], sim, params, features, runner),  # noqa: B023
                     params, signature, tmp_path / str(workers), 0, "pick", progress=False)
        weights.append((tmp_path / str(workers) / "policy.pth").read_bytes())
    assert weights[0] == weights[1]


@pytest.mark.parametrize(("settings", "field"), [({"n_envs": 2, "env_workers": 3}, "env_workers"),
                                                  ({"vec_env": "subproc", "env_workers": 2}, "subproc")])
def test_env_workers_that_cannot_run_are_refused(settings: dict, field: str) -> None:
    with pytest.raises(pydantic.ValidationError, match=field):
        PPOParams(**settings)
