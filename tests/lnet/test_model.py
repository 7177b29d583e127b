"""Model shapes, frame conventions, the masked loss, training resumption, checkpoint checks, calibration (with the
objects' lost probabilities: mor.lnet.lost)."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from mor.errors import MorError
from mor.lnet.calibration import Calibration
from mor.lnet.calibration_file import FittedCalibration, read_calibration
from mor.lnet.calibration_fit import fit_calibration
from mor.lnet.evaluate import NOMINAL_2D, calibrated_metrics, metrics
from mor.lnet.frames import ego_to_world, world_to_ego
from mor.lnet.loss import lnet_loss, nll_terms, previous_actions
from mor.lnet.lost import arena_shares, fit_nll, log_density, region_mass
from mor.lnet.model import LNet, ObjectAttention
from mor.lnet.params import LNetConfig
from mor.lnet.predictions import Predictions
from mor.lnet.stated import StatedParams, stated_inputs
from mor.sim import geometry
from mor.sim.arena import Arena

SMALL = LNetConfig(feature_dim=32, mlp_hidden=32, lstm_hidden=32)


def _batch(b: int = 2, t: int = 4, size: int = 16) -> dict[str, torch.Tensor]:
    generator = torch.Generator().manual_seed(0)
    return {
        "images": torch.rand(b, t, 3, size, size, generator=generator),
        "object_classes": torch.tensor([[3, 10, 20, -1, -1]] * b),
        "held": torch.full((b, t), -1),
        "actions": torch.zeros((b, t), dtype=torch.long),
        "agent_pose": torch.rand(b, t, 3, generator=generator),
        "object_positions": torch.rand(b, t, 5, 2, generator=generator),
        "object_mask": torch.tensor([[True, True, True, False, False]] * b),
    }


def test_torch_frames_agree_with_the_simulator_geometry() -> None:
    rng = np.random.default_rng(0)
    pose = np.array([1.2, -0.7, 2.5])
    points = rng.normal(size=(5, 2))
    ego = world_to_ego(torch.tensor(points), torch.tensor(pose[:2]), torch.tensor(pose[2]))
    np.testing.assert_allclose(ego.numpy(), geometry.world_to_ego(points, pose), atol=1e-12)
    back = ego_to_world(ego, torch.tensor(pose[:2]), torch.tensor(pose[2]))
    np.testing.assert_allclose(back.numpy(), points, atol=1e-12)


@pytest.mark.parametrize(("tracker", "visibility"), [("lstm", False), ("lstm", True), ("filter", True)])
@pytest.mark.parametrize("object_head", ["global", "attention"])
@pytest.mark.parametrize("encoder", ["compact", "resnet18"])
def test_lnet_shapes(encoder: str, object_head: str, tracker: str, visibility: bool) -> None:
    model = LNet(SMALL.model_copy(update={"encoder": encoder, "object_head": object_head, "tracker": tracker,
                                          "visibility": visibility}))
    batch = _batch()
    single, tracked, state = model(batch["images"], batch["object_classes"], batch["held"],
                                   previous_actions(batch["actions"]))
    assert single.frame == "ego" and tracked.frame == "world"
    assert tracked.agent_mean.shape == (2, 4, 2) and tracked.agent_tril.shape == (2, 4, 2, 2)
    assert tracked.object_mean.shape == (2, 4, 5, 2) and tracked.kappa.shape == (2, 4)
    assert torch.all(tracked.kappa > 0) and torch.all(torch.diagonal(tracked.object_tril, dim1=-2, dim2=-1) > 0)
    assert (single.visibility_logit is not None) == visibility
    assert state[0].shape == ((1, 2, 32) if tracker == "lstm" else (2, 2))


def test_attention_finds_each_object_in_its_own_cells() -> None:
    # Two slots of different classes attend to different cells when the map makes one cell match each query.
    attention = ObjectAttention(channels=4, embedding_dim=2)
    with torch.no_grad():
        attention.query.weight.copy_(torch.tensor([[40.0, 0.0], [0.0, 40.0], [0.0, 0.0], [0.0, 0.0]]))
        attention.query.bias.zero_()
        attention.position.zero_()
    spatial = torch.zeros(1, 4, 4, 4)
    spatial[0, 0, 1, 2] = 1.0  # channel 0 lights up in cell (1, 2), channel 1 in cell (3, 0)
    spatial[0, 1, 3, 0] = 1.0
    attended = attention(spatial, torch.tensor([[[1.0, 0.0], [0.0, 1.0]]]))
    torch.testing.assert_close(attended[0, 0, :2], torch.tensor([1.0, 0.0]), atol=1e-3, rtol=0)
    torch.testing.assert_close(attended[0, 1, :2], torch.tensor([0.0, 1.0]), atol=1e-3, rtol=0)


@pytest.mark.parametrize("detach", [False, True])
def test_detached_visibility_learns_from_its_bce_only(detach: bool) -> None:
    model = LNet(SMALL.model_copy(update={"tracker": "filter", "visibility": True, "detach_visibility": detach}))
    batch = _batch()
    single, tracked, _ = model(batch["images"], batch["object_classes"], batch["held"],
                               previous_actions(batch["actions"]))
    single.visibility_logit.retain_grad()
    sum(nll_terms(tracked, batch["agent_pose"], batch["object_positions"],
                  batch["object_mask"].unsqueeze(1)).values()).backward()
    grad = single.visibility_logit.grad
    tracker_moves_visibility = grad is not None and bool(torch.any(grad != 0))
    assert tracker_moves_visibility != detach
    # the filter still weighs its measurements by the (detached) visibility: the estimates are the same
    again = LNet(model.config.model_copy(update={"detach_visibility": not detach}))
    again.load_state_dict(model.state_dict())
    _, other, _ = again(batch["images"], batch["object_classes"], batch["held"], previous_actions(batch["actions"]))
    torch.testing.assert_close(other.object_mean, tracked.object_mean)


def test_absent_objects_do_not_change_the_loss() -> None:
    model = LNet(SMALL)
    batch = _batch()
    out = model(batch["images"], batch["object_classes"], batch["held"], previous_actions(batch["actions"]))
    loss, _ = lnet_loss(*out[:2], batch)
    batch["object_positions"][:, :, 3:] += 100.0
    again, _ = lnet_loss(*out[:2], batch)
    assert loss.item() == pytest.approx(again.item())


def test_with_visibility_the_posenet_object_terms_see_only_visible_frames_and_beta_reweights_them() -> None:
    model = LNet(SMALL.model_copy(update={"visibility": True}))
    batch = _batch()
    batch["visible"] = torch.zeros(2, 4, 5, dtype=torch.bool)
    batch["visible"][:, 1:3, 0] = True
    out = model(batch["images"], batch["object_classes"], batch["held"], previous_actions(batch["actions"]))
    _, parts = lnet_loss(*out[:2], batch)
    assert parts["posenet_visibility"] > 0
    moved = {**batch, "object_positions": batch["object_positions"].clone()}
    moved["object_positions"][:, 0] += 5.0  # frame 0: object 0 is not visible there
    _, again = lnet_loss(*out[:2], moved)
    assert again["posenet_objects"] == pytest.approx(parts["posenet_objects"])
    assert again["tracker_objects"] != pytest.approx(parts["tracker_objects"])  # the tracker answers for all
    _, beta = lnet_loss(*out[:2], batch, beta=0.5)
    assert beta["posenet_objects"] != pytest.approx(parts["posenet_objects"])
    assert beta["tracker_objects"] == pytest.approx(parts["tracker_objects"])


def _predictions(n: int, true_scale: float, stated_scale: float) -> Predictions:
    rng = np.random.default_rng(0)
    agent = rng.normal(size=(n, 3))
    objects = rng.normal(size=(n, 5, 2))
    tril = np.broadcast_to(np.eye(2) * stated_scale, (n, 2, 2)).copy()
    return Predictions(
        agent_pose=agent, agent_mean=agent[:, :2] + rng.normal(scale=true_scale, size=(n, 2)), agent_tril=tril,
        heading=agent[:, 2] + rng.vonmises(0.0, 100.0, size=n), kappa=np.full(n, 400.0),
        object_truth=objects, object_mean=objects + rng.normal(scale=true_scale, size=(n, 5, 2)),
        object_tril=np.broadcast_to(np.eye(2) * stated_scale, (n, 5, 2, 2)).copy(),
        present=np.tile([True, True, True, False, False], (n, 1)), visible=np.ones((n, 5), bool),
        since_seen=np.zeros((n, 5), int), sightings=np.ones((n, 5), int), held=np.full(n, -1),
        episode=np.zeros(n, int), frame=np.arange(n), confusable=np.zeros((n, 5), bool))


@pytest.mark.parametrize("criterion", ["nll", "coverage"])
def test_calibration_repairs_overconfidence(criterion: str) -> None:
    predictions = _predictions(4000, true_scale=0.2, stated_scale=0.1)  # stated sigma half the true one
    before = metrics(predictions)["coverage"]["agent_position"]["2sigma"]
    calibration = fit_calibration(predictions, criterion).scales  # Gaussian errors: both criteria agree
    assert calibration.agent_scale == pytest.approx(2.0, rel=0.05)
    assert calibration.object_scale == pytest.approx(2.0, rel=0.05)
    assert calibration.kappa_scale == pytest.approx(0.25, rel=0.1)  # kappa 400 stated, 100 true
    after = metrics(calibration.apply(predictions, predictions.confusable))["coverage"]
    assert before < 0.5
    for k in (1, 2, 3):
        assert after["agent_position"][f"{k}sigma"] == pytest.approx(NOMINAL_2D[k], abs=0.03)
        assert after["objects_seen"][f"{k}sigma"] == pytest.approx(NOMINAL_2D[k], abs=0.03)
    assert Calibration().apply(predictions, predictions.confusable).agent_tril is not None


def test_the_coverage_criterion_trades_the_nll_for_coverage_on_heavy_tailed_errors() -> None:
    predictions = _predictions(4000, true_scale=0.1, stated_scale=0.1)
    rng = np.random.default_rng(1)
    tail = rng.random((4000, 5)) < 0.15  # a narrow core and a tail ten times wider
    predictions = replace(predictions, object_mean=predictions.object_mean + np.where(
        tail[..., None], rng.normal(scale=1.0, size=(4000, 5, 2)), 0.0))

    def worst(calibration: Calibration) -> tuple[float, float]:
        scored = metrics(calibration.apply(predictions, predictions.confusable))
        coverage = scored["coverage"]["objects_seen"]
        return max(abs(coverage[f"{k}sigma"] - NOMINAL_2D[k]) for k in (1, 2, 3)), scored["nll"]["objects"]

    (nll_worst, nll_nll), (coverage_worst, coverage_nll) = (worst(fit_calibration(predictions, c).scales)
                                                            for c in ("nll", "coverage"))
    assert coverage_worst < nll_worst and nll_nll < coverage_nll  # each wins on what it optimizes
    with pytest.raises(ValueError, match="calibration criterion: expected one of"):
        fit_calibration(predictions, "quantile")


def test_objects_sharing_their_colour_get_their_own_scale() -> None:
    predictions = _predictions(4000, true_scale=0.2, stated_scale=0.1)
    shared = np.zeros((4000, 5), bool)
    shared[:, 0] = True  # slot 0 shares its colour; its errors are three times larger
    predictions = replace(predictions, confusable=shared, object_mean=predictions.object_mean + np.where(
        shared[..., None], 2.0 * (predictions.object_mean - predictions.object_truth), 0.0))
    calibration = fit_calibration(predictions).scales
    assert calibration.object_scale == pytest.approx(2.0, rel=0.05)
    assert calibration.shared_colour_scale == pytest.approx(6.0, rel=0.05)
    scaled = calibration.apply(predictions, predictions.confusable).object_tril
    assert scaled[0, 0, 0, 0] == pytest.approx(0.6, rel=0.05) and scaled[0, 1, 0, 0] == pytest.approx(0.2, rel=0.05)
    for k in (1, 2, 3):  # each group honest, so all of them
        after = metrics(calibration.apply(predictions, predictions.confusable))["coverage"]["objects_seen"]
        assert after[f"{k}sigma"] == pytest.approx(NOMINAL_2D[k], abs=0.03)


def test_an_object_sharing_its_colour_is_confusable_except_while_held() -> None:
    from mor.lnet.calibration import confusable  # noqa: PLC0415

    classes = np.array([2, 8, 0, -1, -1])  # a blue cube, a blue sphere, a red cube, two empty slots
    held = np.array([-1, 1, 5])  # nothing, the sphere, none (the environments' convention: n)
    assert confusable(classes, held).tolist() == [[True, True, False, False, False],
                                                  [True, False, False, False, False],
                                                  [True, True, False, False, False]]
    per_env = confusable(np.stack([classes[:3], classes[:3]]), np.array([0, 3]))  # (N, n) with (N,)
    assert per_env.tolist() == [[False, True, False], [True, True, False]]


def test_coverage_by_sightings_bins_the_remembered_objects_by_how_often_they_were_in_view() -> None:
    from dataclasses import replace  # noqa: PLC0415

    from mor.lnet.evaluate import SIGHTINGS_BINS  # noqa: PLC0415

    honest = _predictions(4000, true_scale=0.2, stated_scale=0.2)
    # slot 1 was seen 30 times and states a tenth of its error; slot 0 seen once, honest; slot 2 is held
    tril = honest.object_tril.copy()
    tril[:, 1] *= 0.1
    sightings = np.tile([1, 30, 3, 0, 0], (4000, 1))
    scored = metrics(replace(honest, object_tril=tril, sightings=sightings, held=np.full(4000, 2)))
    table = scored["objects_seen_by_sightings"]
    assert table["bin_start"] == list(SIGHTINGS_BINS)
    once, many = SIGHTINGS_BINS.index(1), len(SIGHTINGS_BINS) - 1
    assert table["count"][once] == table["count"][many] == 4000 and sum(table["count"]) == 8000  # held: left out
    for k in (1, 2, 3):
        assert table[f"{k}sigma"][once] == pytest.approx(NOMINAL_2D[k], abs=0.03)
        assert table[f"{k}sigma"][many] < NOMINAL_2D[k] - 0.2
    assert table["median_m"][once] == pytest.approx(0.2 * np.sqrt(2 * np.log(2)), rel=0.1)  # Rayleigh median
    assert table["median_d2"][once] == pytest.approx(2 * np.log(2), rel=0.1)
    assert table["median_d2"][many] == pytest.approx(200 * np.log(2), rel=0.1)  # a tenth of the error stated


def test_heading_central_mass_agrees_with_the_interval_it_names() -> None:
    from mor.lnet.evaluate import heading_central_mass
    from mor.lnet.likelihoods import heading_halfwidth

    for kappa in (0.5, 5.0, 300.0):
        for mass in (0.3, 0.683, 0.954):
            edge = heading_halfwidth(kappa, mass)
            assert heading_central_mass(np.array([edge]), np.array([kappa]))[0] == pytest.approx(mass, abs=1e-6)
    assert heading_central_mass(np.array([np.pi / 2]), np.array([0.0]))[0] == pytest.approx(0.5)


ARENA = Arena.build("square", 6.0)


def _lost_predictions(n: int, lost: float, seed: int = 0) -> Predictions:
    """Objects anywhere in the arena; beliefs honest Gaussians (sigma 0.1 m), except that with probability
    ``lost`` the mean is anywhere in the arena instead."""
    rng = np.random.default_rng(seed)
    predictions = _predictions(n, true_scale=0.1, stated_scale=0.1)
    truth = rng.uniform(-2.9, 2.9, size=(n, 5, 2))
    mean = np.where(rng.random((n, 5, 1)) < lost, rng.uniform(-2.9, 2.9, size=(n, 5, 2)),
                    truth + rng.normal(scale=0.1, size=(n, 5, 2)))
    return replace(predictions, object_truth=truth, object_mean=mean)


def test_the_arena_share_of_an_ellipse_is_its_area_until_it_meets_the_walls() -> None:
    truth = np.array([[[0.5, 0.0]], [[2.0, 0.0]], [[30.0, 0.0]]])  # d = 1, 4 and 60 sigma from the centre
    mean, tril = np.zeros((3, 1, 2)), np.broadcast_to(np.eye(2) * 0.5, (3, 1, 2, 2))
    share = arena_shares(truth, mean, tril, np.ones((3, 1), bool), ARENA, StatedParams.arena_grid_spacing).share[:, 0]
    assert share[0] == pytest.approx(np.pi * 0.5 ** 2 / 36.0, rel=0.05)  # a disc of radius 0.5 m
    assert share[1] == pytest.approx(np.pi * 2.0 ** 2 / 36.0, rel=0.05)
    assert share[2] == 1.0  # the whole arena
    assert np.all(arena_shares(truth, mean, tril, np.zeros((3, 1), bool), ARENA, 0.1).share == 0.0)


def test_without_a_lost_probability_the_stated_belief_is_the_gaussian() -> None:
    d2 = np.array([0.5, 1.0, 4.0, 9.5])
    assert np.allclose(region_mass(d2, 0.0, np.full(4, 0.3)), 1.0 - np.exp(-d2 / 2.0))
    far = np.array([3000.0])  # a Gaussian's log density far out, not floored
    assert log_density(far, np.zeros(1), 0.0, 36.0)[0] == pytest.approx(-1500.0 - np.log(2.0 * np.pi))
    assert log_density(far, np.zeros(1), 1.0, 36.0)[0] == pytest.approx(-np.log(36.0))  # all lost: uniform
    predictions = _predictions(500, true_scale=0.2, stated_scale=0.1)
    scored = calibrated_metrics(predictions, FittedCalibration(Calibration(object_scale=2.0)))
    assert scored["stated"]["nll_objects"] == pytest.approx(scored["nll"]["objects"], rel=1e-6)
    for k in (1, 2, 3):
        assert scored["stated"]["coverage"]["objects_seen"][f"{k}sigma"] == scored["coverage"]["objects_seen"][
            f"{k}sigma"]
    for needs_inputs in (StatedParams(lost_own=0.1), StatedParams(search_find=0.5)):
        with pytest.raises(ValueError, match="StatedInputs"):
            calibrated_metrics(predictions, FittedCalibration(stated=needs_inputs))


def test_em_recovers_the_scale_and_the_lost_probability() -> None:
    predictions = _lost_predictions(3000, lost=0.2)
    p = predictions
    rows = p.present
    d2 = (((p.object_truth - p.object_mean) / 0.1) ** 2).sum(-1)[rows]
    scale, weight = fit_nll(d2, np.full(d2.shape, np.log(0.01)), 36.0)
    assert scale == pytest.approx(1.0, rel=0.05) and weight == pytest.approx(0.2, abs=0.02)


def test_the_stated_inputs_follow_the_chosen_settings_and_the_fit_records_them() -> None:
    predictions = _lost_predictions(200, lost=0.2)
    chosen = StatedParams(not_found_sigma=2.0, search_max_looks=8, arena_grid_spacing=0.2)
    inputs = stated_inputs(predictions, ARENA, chosen)
    assert inputs.looks.max_looks == 8 and inputs.looks.truth_looks.max() <= 8
    assert inputs.looks.cell_area == pytest.approx(0.04)  # 900 points of 0.2 m in the 6 m square
    fitted = fit_calibration(predictions, "nll", inputs).stated
    assert (fitted.not_found_sigma, fitted.search_max_looks, fitted.arena_grid_spacing) == (2.0, 8, 0.2)


@pytest.mark.parametrize("criterion", ["nll", "coverage"])
def test_lost_probabilities_make_a_heavy_tail_honest_where_no_gaussian_scale_can(criterion: str) -> None:
    fit_on, test_on = _lost_predictions(3000, lost=0.2, seed=1), _lost_predictions(3000, lost=0.2, seed=2)
    gaussian = fit_calibration(fit_on, criterion)
    lost = fit_calibration(fit_on, criterion, stated_inputs(fit_on, ARENA, StatedParams()))
    assert gaussian.stated.lost_own == 0.0 and lost.stated.lost_own == pytest.approx(0.2, abs=0.04)
    shares = stated_inputs(test_on, ARENA, StatedParams())

    def worst(calibration: FittedCalibration) -> float:
        coverage = calibrated_metrics(test_on, calibration, shares)["stated"]["coverage"]["objects_seen"]
        return max(abs(coverage[f"{k}sigma"] - NOMINAL_2D[k]) for k in (1, 2, 3))

    assert worst(lost) < 0.03 < worst(gaussian)


def test_a_calibration_file_keeps_its_lost_probabilities_and_refuses_impossible_ones(tmp_path: Path) -> None:
    calibration = FittedCalibration(Calibration(object_scale=1.5, shared_colour_scale=3.0),
                                     stated=StatedParams(lost_own=0.05, lost_shared=0.3))
    path = tmp_path / "calibration.json"
    path.write_text(json.dumps(calibration.values()))
    assert read_calibration(path) == calibration
    assert calibration.stated.lost(np.array([[True, False]])).tolist() == [[0.3, 0.05]]
    path.write_text(json.dumps(calibration.values() | {"lost_shared": 1.0}))
    with pytest.raises(MorError, match="lost_own and lost_shared must lie in"):
        read_calibration(path)


def test_the_committed_calibration_files_read_as_written() -> None:
    """Every committed calibration.json (main and settings) reads into the three records, which give back its
    fields as they are in the file."""
    root = Path(__file__).parents[2]
    committed = [root / "cards/lnet/calibration.json", *root.glob("settings/*/cards/lnet/calibration.json")]
    for path in committed:
        values, written = json.loads(path.read_text()), read_calibration(path).values()
        assert {key: values[key] for key in written if key in values} == {
            key: written[key] for key in written if key in values}
