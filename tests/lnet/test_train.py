"""Training on the tiny dataset: it runs, resumes after an interruption, and refuses foreign checkpoints."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest
import torch

from mor.data.manifest import manifest_version, read_manifest
from mor.lnet.calibration_fit import fit_calibration
from mor.lnet.checkpoint import CheckpointMismatch, load_model, signature
from mor.lnet.evaluate import metrics
from mor.lnet.params import LNetConfig, TrainParams
from mor.lnet.predict import predict
from mor.lnet.train import BEST, CHECKPOINT, LOG, train

CONFIG = LNetConfig(feature_dim=32, mlp_hidden=32, lstm_hidden=32)
PARAMS = TrainParams(window=8, stride=8, batch_size=4, max_steps=4, eval_every=2, validation_windows=4,
                     num_workers=0)


def _steps(log: Path) -> list[int]:
    with open(log) as stream:
        return [int(row["step"]) for row in csv.DictReader(stream) if row["split"] == "train"]


def test_training_resumes_where_it_stopped(tiny_dataset: tuple, tmp_path: Path) -> None:
    manifest, root, _ = tiny_dataset
    version = manifest_version(read_manifest(manifest))
    first = train(CONFIG, PARAMS, root / "train", root / "validation", tmp_path, version, progress=False)
    assert first["steps"] == 4 and (tmp_path / CHECKPOINT).is_file() and (tmp_path / BEST).is_file()
    more = PARAMS.model_copy(update={"max_steps": 6})
    second = train(CONFIG, more, root / "train", root / "validation", tmp_path, version, progress=False)
    assert second["steps"] == 6
    assert _steps(tmp_path / LOG) == [1, 2, 3, 4, 5, 6]  # nothing redone, nothing skipped


def test_pretraining_runs_first_resumes_and_leaves_the_window_steps_to_follow(tiny_dataset: tuple,
                                                                               tmp_path: Path) -> None:
    manifest, root, _ = tiny_dataset
    version = manifest_version(read_manifest(manifest))
    first = PARAMS.model_copy(update={"pretrain_steps": 2, "pretrain_batch_size": 3, "max_steps": 1, "eval_every": 1})
    summary = train(CONFIG, first, root / "train", root / "validation", tmp_path, version, progress=False)
    assert summary["pretrain_steps"] == 2 and summary["steps"] == 1 and summary["pretrain_seconds"] > 0
    more = first.model_copy(update={"pretrain_steps": 3, "max_steps": 2})  # no pretraining once windows began
    again = train(CONFIG, more, root / "train", root / "validation", tmp_path, version, progress=False)
    assert again["pretrain_steps"] == 2 and again["steps"] == 2 and again["pretrain_seconds"] is None
    with open(tmp_path / LOG) as stream:
        rows = [(row["split"], int(row["step"])) for row in csv.DictReader(stream) if row["split"] != "validation"]
    assert rows == [("pretrain", -1), ("pretrain", 0), ("train", 1), ("train", 2)]


def test_a_bfloat16_encoder_trains_float32_weights_to_another_result(tiny_dataset: tuple, tmp_path: Path) -> None:
    manifest, root, _ = tiny_dataset
    version = manifest_version(read_manifest(manifest))
    params = PARAMS.model_copy(update={"max_steps": 2})
    trained = {}
    for precision in ("float32", "bfloat16"):
        summary = train(CONFIG, params.model_copy(update={"encoder_precision": precision}), root / "train",
                        root / "validation", tmp_path / precision, version, progress=False)
        assert summary["encoder_precision"] == precision
        trained[precision] = load_model(tmp_path / precision / BEST, signature(CONFIG, version, 16),
                                        torch.device("cpu"))
    weights = {name: model.state_dict()["posenet.encoder.features.0.weight"] for name, model in trained.items()}
    assert all(w.dtype == torch.float32 for w in weights.values())  # master weights stay float32
    assert not torch.equal(weights["float32"], weights["bfloat16"])  # the same seed, other arithmetic
    assert not trained["bfloat16"].posenet.encoder_bfloat16  # inference chooses its own precision on load


def test_foreign_checkpoints_are_refused_with_both_sides_named(tiny_dataset: tuple, tmp_path: Path) -> None:
    manifest, root, _ = tiny_dataset
    version = manifest_version(read_manifest(manifest))
    train(CONFIG, PARAMS.model_copy(update={"max_steps": 2}), root / "train", root / "validation", tmp_path, version,
          progress=False)
    with pytest.raises(CheckpointMismatch, match="dataset_version is .* but this run's is other;") as error:
        load_model(tmp_path / BEST, signature(CONFIG, "other", 16), torch.device("cpu"))
    assert "\n" not in str(error.value)
    with pytest.raises(CheckpointMismatch, match="image_size is 16 but this run's is 64"):
        load_model(tmp_path / BEST, signature(CONFIG, version, 64), torch.device("cpu"))
    with pytest.raises(CheckpointMismatch, match="lstm_hidden"):
        load_model(tmp_path / BEST, signature(CONFIG.model_copy(update={"lstm_hidden": 8}), version, 16),
                   torch.device("cpu"))


def test_a_checkpoint_from_before_a_config_field_existed_loads_with_its_default(
    tiny_dataset: tuple, tmp_path: Path,
) -> None:
    manifest, root, _ = tiny_dataset
    version = manifest_version(read_manifest(manifest))
    train(CONFIG, PARAMS.model_copy(update={"max_steps": 1}), root / "train", root / "validation", tmp_path, version,
          progress=False)
    saved = torch.load(tmp_path / BEST, weights_only=False)
    del saved["config"]["object_head"]  # as written before the option existed
    torch.save(saved, tmp_path / "old.pt")
    model = load_model(tmp_path / "old.pt", signature(CONFIG, version, 16), torch.device("cpu"))
    assert model.config.object_head == "global" and model.posenet.attention is None
    with pytest.raises(CheckpointMismatch, match="object_head"):
        load_model(tmp_path / "old.pt", signature(CONFIG.model_copy(update={"object_head": "attention"}), version, 16),
                   torch.device("cpu"))


def test_predict_calibrate_and_score_whole_episodes(tiny_dataset: tuple, tmp_path: Path) -> None:
    manifest, root, rows = tiny_dataset
    version = manifest_version(read_manifest(manifest))
    train(CONFIG, PARAMS.model_copy(update={"max_steps": 2}), root / "train", root / "validation", tmp_path, version,
          progress=False)
    model = load_model(tmp_path / BEST, signature(CONFIG, version, 16), torch.device("cpu"))
    predictions = predict(model, root / "test", 10, torch.device("cpu"), progress=False)
    assert len(predictions.frame) == sum(r["n_frames"] for r in rows if r["split"] == "test")
    result = metrics(fit_calibration(predictions).scales.apply(predictions, predictions.confusable))
    assert 0.0 <= result["coverage"]["agent_position"]["2sigma"] <= 1.0
    assert result["agent_position_error_m"]["median"] >= 0.0


def test_the_same_seed_and_params_train_the_same_weights(tiny_dataset: tuple, tmp_path: Path) -> None:
    """The default profile's recipe at toy sizes: its model (filter tracker, attention head, visibility), a
    bfloat16 encoder, pretraining, window steps and a data-loading worker process."""
    manifest, root, _ = tiny_dataset
    version = manifest_version(read_manifest(manifest))
    config = CONFIG.model_copy(update={"tracker": "filter", "object_head": "attention", "visibility": True,
                                       "detach_visibility": True})
    params = PARAMS.model_copy(update={"pretrain_steps": 2, "pretrain_batch_size": 3, "max_steps": 3,
                                       "num_workers": 1, "encoder_precision": "bfloat16"})
    trained = [load_model(tmp_path / name / BEST, signature(config, version, 16), torch.device("cpu")).state_dict()
               for name in ("first", "second")
               if train(config, params, root / "train", root / "validation", tmp_path / name, version,
                        progress=False)]
    differ = [key for key in trained[0] if not torch.equal(trained[0][key], trained[1][key])]
    assert not differ, f"two runs with one seed differ in {len(differ)} tensors, e.g. {differ[:3]}"
