"""Negative information (``mor.lnet.unseen``): a frame that does not see an object widens a contradicted confident
belief, moves a belief partly in view away from the view, and leaves every other belief alone."""

from __future__ import annotations

import math

import torch

from mor.lnet.filter import BeliefFilter, TrackingSettings
from mor.lnet.unseen import UNSEEN_REACH, in_view_within_reach, not_seen_update

AGENT, HEADING = torch.zeros(1, 2), torch.zeros(1)  # at the origin, facing +x


def _belief(x: float, y: float, sigma: float) -> tuple[torch.Tensor, torch.Tensor]:
    return torch.tensor([[[x, y]]]), (sigma ** 2 * torch.eye(2)).expand(1, 1, 2, 2).clone()


def test_in_view_is_the_cameras_wedge_within_reach() -> None:
    points = torch.tensor([[[0.5, 0.0], [0.5, 0.4], [-0.5, 0.0], [UNSEEN_REACH + 0.1, 0.0]]])
    assert in_view_within_reach(points, AGENT, HEADING).tolist() == [[True, False, False, False]]
    facing_left = in_view_within_reach(torch.tensor([[[0.0, 0.5]]]), AGENT, torch.tensor([math.pi / 2]))
    assert facing_left.tolist() == [[True]]


def test_a_confident_belief_in_view_that_the_frame_misses_widens_about_where_it_was() -> None:
    mean, cov = _belief(0.6, 0.0, 0.1)
    new_mean, new_cov = not_seen_update(mean, cov, AGENT, HEADING, torch.ones(1, 1))
    assert torch.linalg.det(new_cov[0, 0]) > 10 * torch.linalg.det(cov[0, 0])
    assert torch.linalg.vector_norm(new_mean - mean) < 0.1
    generator = torch.Generator().manual_seed(0)
    share = lambda m, c: in_view_within_reach(  # noqa: E731
        (m[0, 0] + torch.randn(4000, 2, generator=generator) @ torch.linalg.cholesky(c[0, 0]).T)[None],
        AGENT, HEADING).float().mean()
    assert share(new_mean, new_cov) < 0.5 * share(mean, cov)


def test_repeated_misses_keep_widening() -> None:
    mean, cov = _belief(0.6, 0.0, 0.1)
    widths = []
    for _ in range(3):
        mean, cov = not_seen_update(mean, cov, AGENT, HEADING, torch.ones(1, 1))
        widths.append(float(torch.linalg.det(cov[0, 0])))
    assert widths[0] < widths[1] < widths[2]


def test_no_evidence_changes_nothing() -> None:
    ahead, behind = _belief(0.6, 0.0, 0.1), _belief(-1.0, 0.0, 0.1)
    for (mean, cov), missed in ((ahead, 0.0), (behind, 1.0)):
        new_mean, new_cov = not_seen_update(mean, cov, AGENT, HEADING, torch.full((1, 1), missed))
        assert torch.equal(new_mean, mean) and torch.equal(new_cov, cov)


def test_a_belief_at_the_edge_of_view_moves_away_from_it() -> None:
    mean, cov = _belief(0.6, 0.4, 0.15)  # bearing 34 degrees: just outside the 30-degree half-width
    new_mean, _ = not_seen_update(mean, cov, AGENT, HEADING, torch.ones(1, 1))
    assert new_mean[0, 0, 1] > mean[0, 0, 1]


def test_each_episode_is_judged_from_its_own_agent() -> None:
    mean, cov = _belief(0.6, 0.0, 0.1)
    agents, headings = torch.zeros(2, 2), torch.tensor([0.0, math.pi])  # the second faces away from the belief
    new_mean, new_cov = not_seen_update(mean.expand(2, 1, 2), cov.expand(2, 1, 2, 2), agents, headings,
                                        torch.ones(2, 1))
    assert torch.linalg.det(new_cov[0, 0]) > 10 * torch.linalg.det(cov[0, 0])
    assert torch.equal(new_mean[1], mean[0]) and torch.equal(new_cov[1], cov[0])


@torch.no_grad()
def test_the_filter_applies_it_only_when_asked() -> None:
    def step(negative: bool, visibility: torch.Tensor | None = torch.zeros(1, 1)) -> torch.Tensor:
        belief = BeliefFilter(n_slots=1, tracking=TrackingSettings(negative_information=negative))
        held = belief.initial_state(1)[-1]
        mean, cov = _belief(0.6, 0.0, 0.1)
        state = (AGENT, 1e-6 * torch.eye(2)[None], HEADING, torch.tensor([1e-6]), mean, cov, held)
        fix = (AGENT, 1e-3 * torch.eye(2)[None], HEADING, torch.tensor([1e6]))
        ego = (torch.zeros(1, 1, 2), torch.eye(2).expand(1, 1, 2, 2))
        return belief.step(state, fix, ego, visibility, torch.tensor([-1]), torch.tensor([-1]))[5]

    assert torch.linalg.det(step(True)[0, 0]) > 10 * torch.linalg.det(step(False)[0, 0])
    assert torch.equal(step(True, visibility=None), step(False, visibility=None))  # no visibility: nothing missed
