"""The belief filter's rules on hand-made measurements: fix, held, drop, unseen, visibility weight, gate,
data association."""

from __future__ import annotations

import math

import pytest
import torch

from mor.lnet.filter import BeliefFilter, TrackingSettings, associate
from mor.lnet.small_matrices import cholesky_2x2
from mor.sim.rules import DROP_DISTANCE

TIGHT = 1e-3  # metres: a near-exact measurement


def _fix(x: float, y: float, theta: float) -> tuple[torch.Tensor, ...]:
    return (torch.tensor([[x, y]]), TIGHT * torch.eye(2)[None], torch.tensor([theta]), torch.tensor([1e6]))


def _ego(points: list[tuple[float, float]]) -> tuple[torch.Tensor, torch.Tensor]:
    return torch.tensor([points]), (TIGHT * torch.eye(2)).expand(1, len(points), 2, 2)


@torch.no_grad()
def _run(steps: list[dict], data_association: bool = False) -> list[tuple[torch.Tensor, ...]]:
    belief = BeliefFilter(n_slots=2, tracking=TrackingSettings(data_association=data_association))
    state = belief.initial_state(1)
    states = []
    for step in steps:
        state = belief.step(state, _fix(*step["agent"]), _ego(step["ego"]), torch.tensor([step["visible"]]),
                            torch.tensor([step["held"]]), torch.tensor([step.get("action", -1)]))
        states.append(state)
    return states


def test_a_seen_object_moves_to_its_measurement_and_an_unseen_one_keeps_the_prior() -> None:
    (state,) = _run([{"agent": (1.0, -1.0, math.pi / 2), "ego": [(2.0, 0.0), (0.5, 0.5)], "visible": [1.0, 0.0],
                      "held": -1}])
    agent, _, heading, _, objects, object_cov, _ = state
    torch.testing.assert_close(agent[0], torch.tensor([1.0, -1.0]), atol=1e-3, rtol=0)
    assert heading.item() == pytest.approx(math.pi / 2, abs=1e-3)
    torch.testing.assert_close(objects[0, 0], torch.tensor([1.0, 1.0]), atol=1e-2, rtol=0)  # 2 m ahead, facing +y
    prior = BeliefFilter(n_slots=2).initial_state(1)
    torch.testing.assert_close(objects[0, 1], prior[4][0, 1], atol=1e-6, rtol=0)
    assert object_cov[0, 1, 0, 0] > 1.0 > 100 * object_cov[0, 0, 0, 0]


def test_a_held_object_follows_the_agent_and_lands_ahead_when_dropped() -> None:
    steps = [{"agent": (0.0, 0.0, 0.0), "ego": [(3.0, 0.0), (0.0, 0.0)], "visible": [0.0, 0.0], "held": 1},
             {"agent": (1.0, 0.5, 0.0), "ego": [(3.0, 0.0), (0.0, 0.0)], "visible": [0.0, 0.0], "held": 1},
             {"agent": (1.0, 0.5, math.pi), "ego": [(3.0, 0.0), (0.0, 0.0)], "visible": [0.0, 0.0], "held": -1,
              "action": 4}]
    held, carried, dropped = _run(steps)
    for state in (held, carried):
        torch.testing.assert_close(state[4][0, 1], state[0][0])  # exactly the agent's belief
        torch.testing.assert_close(state[5][0, 1], state[1][0])
    torch.testing.assert_close(carried[0][0], torch.tensor([1.0, 0.5]), atol=1e-2, rtol=0)
    torch.testing.assert_close(dropped[4][0, 1], torch.tensor([1.0 - DROP_DISTANCE, 0.5]), atol=2e-2, rtol=0)
    assert dropped[5][0, 1, 0, 0] < 0.1  # the agent's (small) uncertainty carried, not the prior's


def test_an_outlier_far_outside_a_confident_belief_is_gated_out() -> None:
    seen = {"agent": (0.0, 0.0, 0.0), "ego": [(2.0, 0.0), (0.0, 0.0)], "visible": [1.0, 0.0], "held": -1}
    outlier = {**seen, "ego": [(2.0, 2.5), (0.0, 0.0)]}
    _, after = _run([seen, outlier])
    torch.testing.assert_close(after[4][0, 0], torch.tensor([2.0, 0.0]), atol=2e-2, rtol=0)


@pytest.mark.parametrize("data_association", [False, True])
def test_a_measurement_another_tracked_slot_claims_goes_to_that_slot(data_association: bool) -> None:
    # Slot 0 is tracked 2 m ahead. Then slot 1 (never seen) "sees" the same spot as slot 0 does: a same-coloured
    # object confused for it. Associated, slot 0's confident belief explains it and slot 1 keeps (nearly) its prior.
    tracked = {"agent": (0.0, 0.0, 0.0), "ego": [(2.0, 0.0), (0.0, 0.0)], "visible": [1.0, 0.0], "held": -1}
    confused = {**tracked, "ego": [(2.0, 0.0), (2.0, 0.0)], "visible": [1.0, 0.9]}
    _, after = _run([tracked, confused], data_association)
    distance_from_prior = torch.linalg.norm(after[4][0, 1] - BeliefFilter(n_slots=2).initial_state(1)[4][0, 1])
    assert (distance_from_prior < 0.2) == data_association  # without: pulled about 2 m to slot 0's object
    torch.testing.assert_close(after[4][0, 0], torch.tensor([2.0, 0.0]), atol=2e-2, rtol=0)


def test_a_belief_that_cannot_explain_its_measurement_at_all_gives_no_nan() -> None:
    # Slot 0's tight belief is 10 m from its measurement (log-likelihood about -25,000 below slot 1's); slot 1 does
    # not claim it (not visible), so slot 0 keeps its whole weight instead of 0 x inf.
    tight = 1e-3 * torch.eye(2).expand(1, 2, 2, 2)
    weight = associate(torch.tensor([[1.0, 0.0]]), torch.zeros(1, 2, 2), tight, torch.tensor([[[10.0, 0.0],
                                                                                             [0.0, 0.0]]]), tight)
    torch.testing.assert_close(weight, torch.tensor([[1.0, 0.0]]))


def test_a_doubtful_update_keeps_the_spread_of_its_outcomes_in_the_covariance() -> None:
    half_seen = {"agent": (0.0, 0.0, 0.0), "ego": [(2.0, 0.0), (0.0, 0.0)], "visible": [0.5, 0.0], "held": -1}
    (plain,), (associated,) = _run([half_seen]), _run([half_seen], data_association=True)
    torch.testing.assert_close(plain[4], associated[4])  # the same mean (no other slot claims it)
    # Halfway to the measurement either way; associated, the variance along the innovation (2 m along x, from the
    # prior's centre) also holds the spread of "moved" and "not moved": 0.5 x 0.5 x (2 m)^2 = 1 m^2.
    spread = associated[5][0, 0] - plain[5][0, 0]
    torch.testing.assert_close(spread, torch.tensor([[1.0, 0.0], [0.0, 0.0]]), atol=1e-2, rtol=0)


def test_cholesky_2x2_reproduces_the_covariance() -> None:
    cov = torch.tensor([[2.0, 0.3], [0.3, 0.5]])
    tril = cholesky_2x2(cov)
    torch.testing.assert_close(tril @ tril.T, cov)
    torch.testing.assert_close(tril, torch.linalg.cholesky(cov))


@torch.no_grad()
def test_measurement_noise_multipliers_trust_objects_of_their_own_colour_more_than_shared_ones() -> None:
    belief = BeliefFilter(n_slots=2, tracking=TrackingSettings(noise_own=0.25, noise_shared=16.0))
    ego = (torch.tensor([[(2.0, 1.0), (2.0, -1.0)]]), (0.5 * torch.eye(2)).expand(1, 2, 2, 2))
    state = belief.step(belief.initial_state(1), _fix(0.0, 0.0, 0.0), ego, torch.tensor([[1.0, 1.0]]),
                        torch.tensor([-1]), torch.tensor([-1]), shared=torch.tensor([[True, False]]))
    objects, object_cov = state[4][0], state[5][0]
    # the same measurement error either way; the shared-colour slot moves less and stays wider
    assert objects[1, 1].item() == pytest.approx(-1.0, abs=0.1) and 0.1 < objects[0, 1].item() < 0.9
    assert object_cov[0, 0, 0] > 10 * object_cov[1, 0, 0]
    default = BeliefFilter(n_slots=2).step(BeliefFilter(n_slots=2).initial_state(1), _fix(0.0, 0.0, 0.0), ego,
                                           torch.tensor([[1.0, 1.0]]), torch.tensor([-1]), torch.tensor([-1]),
                                           shared=torch.tensor([[True, False]]))
    torch.testing.assert_close(default[4][0, 0], default[4][0, 1] * torch.tensor([1.0, -1.0]))  # (1, 1): no effect
