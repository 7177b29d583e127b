"""The streaming API: one-call loading, the batched step equals the sequence model, resets, and bad input."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch

import mor.sim  # noqa: F401 - registers the envs
from mor.errors import MorError
from mor.lnet.calibration import Calibration
from mor.lnet.calibration_file import CALIBRATION_FILE, FittedCalibration
from mor.lnet.checkpoint import CheckpointMismatch, signature
from mor.lnet.filter import TrackingSettings
from mor.lnet.model import LNet
from mor.lnet.params import LNetConfig, LNetParams
from mor.lnet.runtime import LNetRunner, ObservationMismatch, checkpoint_identity, lnet_identity, load_lnet
from mor.lnet.stated import StatedParams, not_found

SMALL = LNetConfig(feature_dim=16, mlp_hidden=16, lstm_hidden=16)
SIZE = 16


TRACKERS = [SMALL, SMALL.model_copy(update={"tracker": "filter", "visibility": True})]


def _runner(fitted: FittedCalibration = FittedCalibration(), config: LNetConfig = SMALL) -> LNetRunner:
    torch.manual_seed(0)
    return LNetRunner(LNet(config), fitted, SIZE, "test")


def _rollouts(n_envs: int, steps: int) -> list[dict[str, np.ndarray]]:
    """Random-action observations of ``n_envs`` envs (with 2 objects), stacked per step."""
    envs = [gym.make("MOR/Rearrange-v0", image_size=SIZE, n_objects=2) for _ in range(n_envs)]
    observations = [env.reset(seed=i)[0] for i, env in enumerate(envs)]
    rng = np.random.default_rng(0)
    out = []
    for _ in range(steps):
        actions = rng.integers(0, 5, n_envs)
        out.append({"images": np.stack([o["image"] for o in observations]),
                    "classes": np.stack([o["object_classes"] for o in observations]),
                    "held": np.array([o["held"] for o in observations]), "actions": actions})
        observations = [env.step(int(a))[0] for env, a in zip(envs, actions, strict=True)]
    for env in envs:
        env.close()
    return out


def _previous(frames: list[dict[str, np.ndarray]], t: int) -> np.ndarray:
    return frames[t - 1]["actions"] if t > 0 else np.full(len(frames[0]["actions"]), -1)


@pytest.mark.parametrize("config", TRACKERS, ids=["lstm", "filter"])
def test_streaming_steps_equal_the_sequence_model_and_apply_the_calibration(config: LNetConfig) -> None:
    runner = _runner(FittedCalibration(Calibration(agent_scale=2.0, object_scale=0.5, kappa_scale=3.0)), config)
    frames = _rollouts(n_envs=3, steps=5)
    state = runner.initial_state(3)
    for t, frame in enumerate(frames):
        estimates, state = runner.step(frame["images"], frame["classes"], frame["held"], _previous(frames, t), state)
    from mor.data.observations import env_to_network  # noqa: PLC0415

    inputs = [env_to_network(f["images"], f["classes"], f["held"]) for f in frames]
    with torch.no_grad():
        single, tracked, _ = runner.model(torch.stack([i.images for i in inputs], 1), inputs[0].object_classes,
                                     torch.stack([i.held for i in inputs], 1),
                                     torch.as_tensor(np.stack([_previous(frames, t) for t in range(5)], 1)))
    assert estimates.object_mean.shape == (3, 2, 2) and estimates.object_cov.shape == (3, 2, 2, 2)
    assert estimates.agent_cov.shape == (3, 2, 2) and estimates.heading_kappa.shape == (3,)
    assert estimates.object_lost.shape == (3, 2) and not estimates.object_lost.any()  # none fitted
    assert estimates.search_density is None  # no looks kept (mor.lnet.streaming keeps them given the arena)
    assert all(v.dtype == np.float32 for k, v in vars(estimates).items()
               if k not in ("object_searching", "search_density") and v is not None)
    if config.visibility:  # this frame's detection: the PoseNet's visibility head, before any calibration
        np.testing.assert_allclose(estimates.object_visible,
                                   torch.sigmoid(single.visibility_logit[:, -1, :2]).numpy(), atol=1e-5)
    else:
        assert estimates.object_visible is None
    uncalibrated = tracked.object_tril[:, -1, :2].numpy()  # 'not found' is judged before the calibration's x 0.5
    np.testing.assert_array_equal(estimates.object_searching, not_found(uncalibrated, 1.0))
    np.testing.assert_allclose(estimates.agent_mean, tracked.agent_mean[:, -1].numpy(), atol=1e-5)
    np.testing.assert_allclose(estimates.object_mean, tracked.object_mean[:, -1, :2].numpy(), atol=1e-5)
    tril = tracked.agent_tril[:, -1]
    np.testing.assert_allclose(estimates.agent_cov, 4.0 * (tril @ tril.transpose(-1, -2)).numpy(), rtol=1e-4,
                               atol=1e-6)
    tril = tracked.object_tril[:, -1, :2]
    np.testing.assert_allclose(estimates.object_cov, 0.25 * (tril @ tril.transpose(-1, -2)).numpy(), rtol=1e-4,
                               atol=1e-6)
    np.testing.assert_allclose(estimates.heading_kappa, 3.0 * tracked.kappa[:, -1].numpy(), rtol=1e-5)


def test_the_streaming_step_scales_confusable_objects_by_their_own_scale_unless_held() -> None:
    runner = _runner(FittedCalibration(Calibration(object_scale=0.5, shared_colour_scale=2.0),
                                       stated=StatedParams(lost_own=0.05, lost_shared=0.3)))
    frame = _rollouts(n_envs=1, steps=1)[0]
    classes = np.array([[2, 8]])  # a blue cube and a blue sphere: confusable
    for held, scales in ((np.array([2]), (2.0, 2.0)), (np.array([1]), (2.0, 0.5))):  # nothing held; the sphere
        tracked, _ = runner.track(frame["images"], classes, held, np.array([-1]), runner.initial_state(1))
        estimates = runner.estimates(tracked, classes, held)
        tril = tracked.object_tril[0, -1, :2]
        stated = (tril @ tril.transpose(-1, -2)).numpy()
        for k, scale in enumerate(scales):
            np.testing.assert_allclose(estimates.object_cov[0, k], scale ** 2 * stated[k], rtol=1e-4, atol=1e-7)
        np.testing.assert_allclose(estimates.object_lost[0], [0.3 if scale == 2.0 else 0.05 for scale in scales])


@pytest.mark.parametrize("config", TRACKERS, ids=["lstm", "filter"])
def test_reset_restarts_only_the_environments_that_are_done(config: LNetConfig) -> None:
    runner = _runner(config=config)
    frames = _rollouts(n_envs=2, steps=3)
    state = runner.initial_state(2)
    for t, frame in enumerate(frames[:2]):
        _, state = runner.step(frame["images"], frame["classes"], frame["held"], _previous(frames, t), state)
    state = runner.reset(state, np.array([True, False]))
    last = frames[2]
    after_reset, _ = runner.step(last["images"], last["classes"], last["held"], np.array([-1, -1]), state)
    fresh, _ = runner.step(last["images"], last["classes"], last["held"], np.array([-1, -1]), runner.initial_state(2))
    np.testing.assert_allclose(after_reset.agent_mean[0], fresh.agent_mean[0], atol=1e-6)
    assert not np.allclose(after_reset.agent_mean[1], fresh.agent_mean[1], atol=1e-6)


@pytest.mark.parametrize(("change", "message"), [
    (lambda f: {**f, "images": f["images"].astype(np.float32)}, r"images: expected uint8 frames of shape \(2, 16"),
    (lambda f: {**f, "images": f["images"][:, :8]}, "the model's 16 px"),
    (lambda f: {**f, "images": f["images"][:1]}, "one per environment"),
    (lambda f: {**f, "held": np.array([0, 3])}, r"held: expected \(N,\)"),
    (lambda f: {**f, "actions": np.array([0, 5])}, "previous_actions"),
])
def test_bad_observations_are_one_clear_error(change, message: str) -> None:
    runner = _runner()
    frame = change(_rollouts(n_envs=2, steps=1)[0])
    with pytest.raises(ObservationMismatch, match=message) as error:
        runner.step(frame["images"], frame["classes"], frame["held"], frame["actions"], runner.initial_state(2))
    assert "\n" not in str(error.value)
    with pytest.raises(ObservationMismatch, match="done: expected"):
        runner.reset(runner.initial_state(2), np.array([True]))


def test_the_committed_model_loads_with_one_call_and_checks_what_it_was_made_with(repo_root: Path,
                                                                                    tmp_path: Path) -> None:
    committed = repo_root / "cards" / "lnet" / "model.pt"
    runner = load_lnet(committed)
    saved = torch.load(committed, weights_only=False)
    assert runner.image_size == saved["image_size"] and runner.dataset_version == saved["dataset_version"]
    assert runner.fitted.scales.agent_scale == json.loads((committed.parent / CALIBRATION_FILE).read_text())[
        "agent_scale"]
    other = LNetConfig(**saved["config"]).model_copy(update={"lstm_hidden": 8})
    with pytest.raises(CheckpointMismatch, match="checkpoint config is .*lstm_hidden.* but this run's is"):
        load_lnet(committed, expected=signature(other, saved["dataset_version"], saved["image_size"]))
    with pytest.raises(CheckpointMismatch, match="dataset_version is .* but this run's is elsewhere"):
        load_lnet(committed, expected={"dataset_version": "elsewhere"})
    alone = tmp_path / "model.pt"
    shutil.copyfile(committed, alone)
    with pytest.raises(MorError, match="no calibration beside the checkpoint"):
        load_lnet(alone)
    assert load_lnet(alone, calibrated=False).fitted == FittedCalibration()
    (tmp_path / CALIBRATION_FILE).write_text(json.dumps({"agent_scale": 1, "object_scale": 1, "kappa_scale": 1,
                                                         "dataset_version": "elsewhere"}))
    with pytest.raises(MorError, match="calibration dataset_version is elsewhere but the checkpoint's is"):
        load_lnet(alone)
    # Another training run on the same data is another L-Net to the policies: its identity names the file's bytes.
    retrained = tmp_path / "retrained" / "model.pt"
    retrained.parent.mkdir()
    payload = torch.load(committed, weights_only=False)
    payload["model"] = {key: value + 1e-3 if value.is_floating_point() else value
                        for key, value in payload["model"].items()}
    torch.save(payload, retrained)
    other_runner = load_lnet(retrained, calibrated=False)
    assert runner.identity.startswith(saved["dataset_version"] + "-") and other_runner.identity != runner.identity


def test_a_bfloat16_encoder_moves_the_estimates_by_centimetres_and_is_another_identity(repo_root: Path) -> None:
    committed = repo_root / "cards" / "lnet" / "model.pt"
    full, reduced = load_lnet(committed), load_lnet(committed, encoder_precision="bfloat16")
    envs = [gym.make("MOR/Rearrange-v0", image_size=full.image_size) for _ in range(2)]
    observations = [env.reset(seed=i)[0] for i, env in enumerate(envs)]
    states, previous, rng = [full.initial_state(2), reduced.initial_state(2)], np.full(2, -1), np.random.default_rng(0)
    for _ in range(4):
        inputs = (np.stack([o["image"] for o in observations]), np.stack([o["object_classes"] for o in observations]),
                  np.array([o["held"] for o in observations]), previous)
        (first, states[0]), (second, states[1]) = full.step(*inputs, states[0]), reduced.step(*inputs, states[1])
        previous = rng.integers(0, 3, 2)  # moves and turns: no episode ends
        observations = [env.step(int(a))[0] for env, a in zip(envs, previous, strict=True)]
    difference = np.abs(first.object_mean - second.object_mean).max()
    assert 0 < difference < 0.1  # m: bfloat16 arithmetic, not another model
    assert reduced.encoder_precision == "bfloat16" and reduced.identity == full.identity + "-bf16"
    assert checkpoint_identity(committed, "bfloat16") == reduced.identity
    with pytest.raises(ValueError, match="expected float32 or bfloat16, got 'float16'"):
        full.model.use_encoder_precision("float16")


def _filter_checkpoint(tmp_path: Path) -> tuple[LNetConfig, Path, dict[str, object]]:
    """A small filter L-Net saved in ``tmp_path`` (its config, its checkpoint) and identity calibration scales."""
    config = SMALL.model_copy(update={"tracker": "filter", "visibility": True})
    checkpoint = tmp_path / "model.pt"
    torch.save({**signature(config, "v", SIZE), "model": LNet(config).state_dict()}, checkpoint)
    return config, checkpoint, {"agent_scale": 1, "object_scale": 1, "kappa_scale": 1, "dataset_version": "v"}


def test_the_tracking_rule_follows_the_calibration_and_a_mismatch_is_one_clear_error(tmp_path: Path) -> None:
    config, checkpoint, scales = _filter_checkpoint(tmp_path)
    (tmp_path / CALIBRATION_FILE).write_text(json.dumps({**scales, "data_association": True}))
    runner = load_lnet(checkpoint)
    assert runner.model.tracking.data_association and "-cal" in runner.identity
    assert checkpoint_identity(checkpoint) == runner.identity
    with pytest.raises(MorError, match="fitted with data_association True but this run's is False"):
        load_lnet(checkpoint, chosen={"data_association": False})
    with pytest.raises(MorError, match=r"fitted with gate 9.21 but this run's is 4.0 \(lnet.gate\)"):
        load_lnet(checkpoint, chosen={"gate": 4.0})
    with pytest.raises(MorError, match="fitted with not_found_sigma 1.0 but this run's is 2.0"):
        load_lnet(checkpoint,
                  chosen=LNetParams(model=config, data_association=True, not_found_sigma=2.0).chosen_settings())
    assert not load_lnet(checkpoint, calibrated=False).model.tracking.data_association
    # the settings a profile chooses are recorded beside the fitted scales and read back; the default gate leaves
    # the identity as it was before the gate was recorded, another gate gives another identity
    chosen = {"data_association": True, "gate": 4.0, "not_found_sigma": 2.0}
    (tmp_path / CALIBRATION_FILE).write_text(json.dumps({**scales, **chosen}))
    tuned = load_lnet(checkpoint, chosen=chosen)
    assert (tuned.model.tracking.gate, tuned.fitted.stated.not_found_sigma) == (4.0, 2.0)
    assert tuned.identity != runner.identity
    (tmp_path / CALIBRATION_FILE).write_text(json.dumps({**scales, "data_association": True, "gate": 9.21}))
    assert load_lnet(checkpoint).identity == runner.identity
    # the search belief's look cap and the arena grid's spacing: absent, the defaults (a profile at its defaults
    # loads a calibration from before them); recorded, read back and checked; the stated belief's settings are no
    # part of the identity
    defaults = LNetParams(model=config, data_association=True).chosen_settings()
    assert load_lnet(checkpoint, chosen=defaults).fitted.stated.search_max_looks == 64
    with pytest.raises(MorError, match=r"with search_max_looks 64 but this run's is 8 \(lnet.search_max_looks\)"):
        load_lnet(checkpoint, chosen={**defaults, "search_max_looks": 8})
    with pytest.raises(MorError, match="fitted with arena_grid_spacing 0.1 but this run's is 0.2"):
        load_lnet(checkpoint, chosen={**defaults, "arena_grid_spacing": 0.2})
    searched = {"data_association": True, "search_max_looks": 8, "arena_grid_spacing": 0.2}
    (tmp_path / CALIBRATION_FILE).write_text(json.dumps({**scales, **searched}))
    coarse = load_lnet(checkpoint, chosen=searched)
    assert (coarse.fitted.stated.search_max_looks, coarse.fitted.stated.arena_grid_spacing) == (8, 0.2)
    assert coarse.identity == runner.identity
    with pytest.raises(MorError, match="fitted with search_max_looks 8 but this run's is 64"):
        load_lnet(checkpoint, chosen=defaults)
    (tmp_path / CALIBRATION_FILE).write_text(json.dumps({**scales, "search_max_looks": 8.5}))
    with pytest.raises(MorError, match="search_max_looks must be an integer"):
        load_lnet(checkpoint)
    # the measurement noise the calibration was fitted with is the one tracked with; another calibration, another
    # identity (a policy trained through the first is stale for the second)
    (tmp_path / CALIBRATION_FILE).write_text(json.dumps({**scales, "data_association": True, "noise_own": 0.5,
                                                         "noise_shared": 4.0, "shared_colour_scale": 2.0}))
    noisy = load_lnet(checkpoint)
    assert noisy.model.tracking == TrackingSettings(True, 0.5, 4.0)
    assert noisy.fitted.scales.shared_colour_scale == 2.0
    assert noisy.identity != runner.identity and checkpoint_identity(checkpoint) == noisy.identity
    assert load_lnet(checkpoint, calibrated=False).model.tracking == TrackingSettings()
    # the objects' lost probabilities are no part of it: no policy reads them
    (tmp_path / CALIBRATION_FILE).write_text(json.dumps({**scales, "data_association": True, "noise_own": 0.5,
                                                         "noise_shared": 4.0, "shared_colour_scale": 2.0,
                                                         "lost_own": 0.1, "lost_shared": 0.3}))
    lost = load_lnet(checkpoint)
    assert lost.fitted.stated.lost_shared == 0.3 and lost.identity == noisy.identity
    (tmp_path / CALIBRATION_FILE).write_text(json.dumps(scales))  # a file from before the rule: fitted without it
    assert not load_lnet(checkpoint).model.tracking.data_association
    (tmp_path / CALIBRATION_FILE).write_text(json.dumps({**scales, "data_association": "yes"}))
    with pytest.raises(MorError, match="data_association must be true or false"):
        load_lnet(checkpoint)
    (tmp_path / CALIBRATION_FILE).write_text(json.dumps({**scales, "object_scale": float("nan")}))
    with pytest.raises(MorError, match="scales must be positive and finite"):
        load_lnet(checkpoint)


def test_negative_information_is_recorded_checked_and_another_identity_only_when_on(tmp_path: Path) -> None:
    _, checkpoint, scales = _filter_checkpoint(tmp_path)
    (tmp_path / CALIBRATION_FILE).write_text(json.dumps({**scales, "data_association": True}))
    before = load_lnet(checkpoint)  # a file from before the rule: fitted without it
    assert not before.model.tracking.negative_information
    with pytest.raises(MorError, match="fitted with negative_information False but this run's is True"):
        load_lnet(checkpoint, chosen={"negative_information": True})
    (tmp_path / CALIBRATION_FILE).write_text(json.dumps({**scales, "data_association": True,
                                                         "negative_information": False}))
    assert load_lnet(checkpoint).identity == before.identity
    (tmp_path / CALIBRATION_FILE).write_text(json.dumps({**scales, "data_association": True,
                                                         "negative_information": True}))
    on = load_lnet(checkpoint, chosen={"negative_information": True})
    assert on.model.tracking.negative_information and on.identity != before.identity
    (tmp_path / CALIBRATION_FILE).write_text(json.dumps({**scales, "negative_information": 1}))
    with pytest.raises(MorError, match="negative_information must be true or false"):
        load_lnet(checkpoint)
    with pytest.raises(ValueError, match="negative_information: needs model.tracker: filter"):
        LNetParams(model=SMALL.model_copy(update={"tracker": "lstm"}), negative_information=True)
    with pytest.raises(ValueError, match="negative_information: needs model.visibility: true"):
        LNetParams(model=SMALL.model_copy(update={"tracker": "filter", "visibility": False}), negative_information=True)


def test_tracking_settings_other_than_the_defaults_need_the_filter_tracker() -> None:
    lstm = LNet(SMALL)
    lstm.use_tracking(TrackingSettings())  # the defaults: nothing to set
    assert lstm.tracking == TrackingSettings()
    with pytest.raises(ValueError, match="tracking settings need the filter tracker"):
        lstm.use_tracking(TrackingSettings(data_association=True))
    blind = LNet(SMALL.model_copy(update={"tracker": "filter", "visibility": False}))
    with pytest.raises(ValueError, match="negative information needs the visibility head"):
        blind.use_tracking(TrackingSettings(negative_information=True))


def test_the_identity_hashes_the_scales_and_tracking_settings_as_it_always_has() -> None:
    """The hash one Calibration record of every field gave before the records were split (the stated belief's
    parameters left out): identities recorded by trained policies and results rows stand."""
    fitted = FittedCalibration(Calibration(agent_scale=2.0, shared_colour_scale=1.5),
                               TrackingSettings(data_association=True, noise_own=0.5),
                               StatedParams(lost_own=0.1, search_find=0.3))
    assert lnet_identity("v", "abc", fitted) == "v-abc-cald128a5a5"
    assert lnet_identity("v", "abc", FittedCalibration(stated=fitted.stated)) == "v-abc"


def test_the_lnet_benchmark_counts_the_multiply_adds_of_a_frame_and_of_its_encoder() -> None:
    from mor.lnet.bench import benchmark_lnet  # noqa: PLC0415

    config = LNetConfig(encoder="compact", feature_dim=16, mlp_hidden=16, lstm_hidden=16)
    counted = benchmark_lnet(config, 32, [1, 2], repeats=1, steps=1)["results"]
    first = 32 * 16 * 16 * 3 * 9  # the first convolution alone: 32 channels on a 16x16 map, 3x3 over 3 channels
    assert counted["batch_1"]["multiply_adds_per_frame"] == counted["batch_2"]["multiply_adds_per_frame"]
    assert first < counted["batch_1"]["multiply_adds_per_frame"]["encoder"] < counted["batch_1"][
        "multiply_adds_per_frame"]["model"]


def test_streaming_benchmark_times_the_environments_and_the_lnet_in_one_run() -> None:
    from mor.lnet.bench import benchmark_streaming  # noqa: PLC0415
    from mor.sim.config import SimConfig  # noqa: PLC0415

    result = benchmark_streaming(LNet(SMALL), FittedCalibration(), SimConfig(image_size=SIZE, n_objects=2), n_envs=2,
                                 steps=3, repeats=2)
    assert len(result["runs_env"]) == len(result["runs_lnet"]) == len(result["compiled"]["runs_lnet"]) == 2
    assert result["lnet_over_env"] == pytest.approx(result["lnet_frames_per_s"] / result["env_frames_per_s"])
    for name in ("compiled", "compiled_bfloat16"):
        assert result[name]["lnet_over_env"] == pytest.approx(
            result[name]["lnet_frames_per_s"] / result["env_frames_per_s"])
        assert result[name]["largest_difference"] == max(result[name]["difference_by_array"].values())
    assert result["compiled"]["largest_difference"] < 1e-4  # the compiled step computes the same estimates
    assert result["compiled_bfloat16"]["difference_by_array"]["object_mean"] > 0  # bfloat16 is not float32


def test_live_oracle_episodes_are_scored_like_the_test_split() -> None:
    from mor.lnet.evaluate import metrics  # noqa: PLC0415
    from mor.lnet.predict import predict_live  # noqa: PLC0415
    from mor.sim.config import SimConfig  # noqa: PLC0415

    runner = _runner(config=TRACKERS[1])
    predictions = predict_live(runner, SimConfig(image_size=SIZE), "oracle", episodes=3, seed=0, n_envs=2, horizon=6,
                               progress=False)
    assert sorted(set(predictions.episode.tolist())) == [0, 1, 2] and len(predictions.frame) == 3 * 7
    assert predictions.present.sum(1).tolist() == [3] * 21 and predictions.object_truth.shape == (21, 5, 2)
    assert predictions.frame[:7].tolist() == list(range(7))
    result = metrics(predictions)
    assert result["object_position_error_m"]["all"]["count"] == 63


def test_steps_since_seen_counts_from_the_last_sighting_or_hold() -> None:
    from mor.lnet.predictions import steps_since_seen  # noqa: PLC0415

    visible = np.array([[0, 0], [1, 0], [0, 0], [0, 0], [0, 0]], bool)
    held = np.array([-1, -1, -1, 1, -1])
    assert steps_since_seen(visible, held).tolist() == [[-1, -1], [0, -1], [1, -1], [2, 0], [3, 1]]


def test_error_of_objects_in_view_is_binned_by_their_distance_from_the_agent() -> None:
    from mor.lnet.evaluate import error_by_distance_in_view  # noqa: PLC0415
    from mor.lnet.predictions import episode_predictions  # noqa: PLC0415

    truth = np.array([[[0.5, 0.0], [2.5, 0.0]], [[0.5, 0.0], [6.5, 0.0]]])  # (T=2, K=2) m; the agent at the origin
    estimate = {"agent_mean": np.zeros((2, 2)), "agent_tril": np.tile(np.eye(2), (2, 1, 1)), "heading": np.zeros(2),
                "kappa": np.ones(2), "object_mean": truth + [[[0.1, 0.0], [0.0, 0.4]], [[0.3, 0.0], [2.0, 0.0]]],
                "object_tril": np.tile(np.eye(2), (2, 2, 1, 1))}
    visible = np.array([[True, True], [True, False]])
    p = episode_predictions(estimate, np.zeros((2, 3)), truth, np.array([-1, -1]), visible, np.array([0, 1]), 0)
    binned = error_by_distance_in_view(p)
    assert binned["count"] == [2, 0, 1, 0, 0, 0]  # the object at 6.5 m is not in view on frame 1
    assert binned["median_m"][0] == pytest.approx(0.2) and binned["median_m"][2] == pytest.approx(0.4)
    assert binned["median_m"][1] is None


def test_story_picks_an_episode_with_a_pick_then_a_drop() -> None:
    from mor.lnet.predictions import story  # noqa: PLC0415

    held = np.array([-1] * 6 + [-1, -1, 1, 1, 1, -1, -1])  # episode 1 picks object 1 at frame 2, drops at 5
    visible = np.zeros((13, 5), bool)
    visible[7, 1] = True
    episode = np.array([0] * 6 + [1] * 7)
    predictions = type("P", (), {"episode": episode, "held": held, "visible": visible})()
    assert story(predictions) == (1, [0, 1, 2, 3, 5, 6])


def test_data_association_in_a_profile_needs_the_filter_tracker() -> None:
    with pytest.raises(ValueError, match="data_association: needs model.tracker: filter"):
        LNetParams(data_association=True)
    assert LNetParams(model=LNetConfig(tracker="filter"), data_association=True).data_association


def test_copies_of_a_streaming_tracker_share_the_runner_and_keep_their_own_state() -> None:
    """Gymnasium records a wrapper's arguments by deep copy (PoseObservation's tracker): the filter's learned priors
    must not reach the state with a graph attached, and the runner (a compiled one cannot be copied) is shared."""
    import copy  # noqa: PLC0415

    from mor.lnet.streaming import StreamingTracker  # noqa: PLC0415

    runner = _runner(config=SMALL.model_copy(update={"tracker": "filter", "visibility": True}))
    stream = StreamingTracker(runner, 2)
    copied = copy.deepcopy(stream)
    assert copied.runner is runner and copied.state is not stream.state
