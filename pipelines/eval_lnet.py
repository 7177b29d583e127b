"""Stage ``eval_lnet``: test-split metrics before and after calibration, figures, the model card."""

from __future__ import annotations

import shutil
import time
from pathlib import Path
from typing import Any

import numpy as np

from mor.atomic import atomic_folder
from mor.config import Profile
from mor.data.manifest import manifest_version, read_manifest
from mor.data.sequences import SequenceWindows
from mor.lnet.calibration_file import calibration_from_values
from mor.lnet.card import read_json, render_model_card, write_model_card
from mor.lnet.evaluate import calibrated_metrics, headline, metrics
from mor.lnet.figures import (
    write_estimate_gif,
    write_estimate_strip,
    write_reliability_diagram,
    write_since_seen,
)
from mor.lnet.predict import predict, predict_live
from mor.lnet.predictions import Predictions, story
from mor.lnet.stated import StatedInputs, stated_inputs
from mor.locking import writer_lock
from mor.sim.arena import Arena
from pipelines import paths
from pipelines.io import write_json
from pipelines.lnet_io import load_trained

ORACLE_SEED = 1000  # episode seeds 1e9 + i: disjoint from the collection's (seed 0: 0 .. 1e6 - 1)


def run(profile: Profile) -> dict[str, Any]:
    """Evaluate the trained L-Net and write its model card ``cards/lnet/``, published as a whole (``atomic_folder``:
    a kill never leaves a truncated model.pt, or new weights beside old metrics), one writer at a time."""
    with writer_lock(paths.LNET_CARD, "mor eval-lnet"), atomic_folder(paths.LNET_CARD, keep_existing=True) as card:
        return _write_card(profile, card)


def _write_card(profile: Profile, card: Path) -> dict[str, Any]:
    """``run``'s work: the metrics, figures, weights and README of the model card, into the folder ``card``."""
    started = time.perf_counter()
    runner = load_trained(profile, paths.LNET / "model.pt")
    calibration = runner.fitted
    manifest = read_manifest(paths.MANIFEST)
    predictions = predict(runner.model, paths.LEROBOT / "test", profile.lnet.eval_episodes, runner.device)
    arena = Arena.build(profile.sim.arena, profile.sim.arena_size)
    settings = calibration.stated  # its chosen settings: the not-found width, the look cap, the grid's spacing
    inputs = stated_inputs(predictions, arena, settings)  # the objects' stated belief (mor.lnet.lost, mor.lnet.search)

    def scored(p: Predictions, p_inputs: StatedInputs) -> dict[str, Any]:
        return {"before_calibration": metrics(p), "after_calibration": calibrated_metrics(p, calibration, p_inputs)}

    result = {"dataset_version": manifest_version(manifest), "calibration": calibration.values(),
              **scored(predictions, inputs)}
    chosen = runner.encoder_precision  # the other precision on the same frames, for lnet.encoder_precision's choice
    other = "bfloat16" if chosen == "float32" else "float32"
    runner.model.use_encoder_precision(other)
    reduced = predict(runner.model, paths.LEROBOT / "test", profile.lnet.eval_episodes, runner.device)
    runner.model.use_encoder_precision(chosen)
    result["encoder_precision"] = {chosen: headline(result["after_calibration"]),
                                   other: headline(calibrated_metrics(reduced, calibration,
                                                                      stated_inputs(reduced, arena, settings)))}
    criteria = {name: calibration_from_values(values)  # each criterion's scales, on the test split
                for name, values in read_json(paths.LNET_CALIBRATION).get("criteria", {}).items()}
    result["calibration_criteria"] = {name: headline(result["after_calibration"] if fitted == calibration else
                                                     calibrated_metrics(predictions, fitted, inputs))
                                      for name, fitted in criteria.items()}
    # Real runs of the test split (its episodes are numbered in manifest order), reported on their own.
    test_sources = [row["source"] for row in manifest.to_pylist() if row["split"] == "test"]
    real = np.isin(predictions.episode, [i for i, source in enumerate(test_sources) if source == "real"])
    result["real"] = scored(predictions.select(real), inputs.select(real)) if real.any() else None
    if profile.lnet.oracle_episodes:  # the episodes the policies will produce: oracle-driven, tracked live
        live = predict_live(runner, profile.sim, "oracle", profile.lnet.oracle_episodes, ORACLE_SEED)
        result["oracle"] = {"seed": ORACLE_SEED, **scored(live, stated_inputs(live, arena, settings))}
    result["seconds"] = round(time.perf_counter() - started, 1)  # the metrics; the figures below are not counted
    write_json(card / "metrics.json", result)

    reliability = {f"{name} ({when})": result[key]["reliability"][name]
                   for key, when in (("before_calibration", "before"), ("after_calibration", "after"))
                   for name in ("agent_position", "objects_seen", "heading")}
    if calibration.stated.lost_own or calibration.stated.lost_shared is not None:  # lost probabilities: stated
        reliability["objects_seen (after, stated)"] = result["after_calibration"]["stated"]["reliability_objects_seen"]
    if calibration.stated.search_find is not None:  # a search belief for objects not found: their own curve
        reliability["objects_unseen (after, stated)"] = result["after_calibration"]["stated"][
            "reliability_objects_unseen"]
    write_reliability_diagram(card / "reliability.png", np.asarray(result["before_calibration"]["reliability"]
                              ["nominal"]), {k: np.asarray(v) for k, v in reliability.items()},
                              "L-Net reliability on the test split")
    shown_episode, frames = story(predictions)
    episode = SequenceWindows(paths.LEROBOT / "test", window=None)[shown_episode]
    rows = predictions.episode == shown_episode
    shown = calibration.scales.apply(predictions, predictions.confusable).select(rows)
    truth = {"agent_poses": episode["agent_pose"].numpy(), "object_positions": episode["object_positions"].numpy(),
             "object_classes": episode["object_classes"].numpy()}
    estimate = {name: getattr(shown, name) for name in ("agent_mean", "agent_tril", "heading", "kappa",
                                                        "object_mean", "object_tril")}
    images = episode["images"].numpy()
    write_estimate_strip(card / "estimates_strip.png", arena, truth, estimate, frames, images)
    write_estimate_gif(card / "estimates.gif", arena, truth, estimate, images, fps=5, every=2)
    curves = {"test": result["after_calibration"]["object_error_by_steps_since_seen"]}
    if "oracle" in result:
        curves["oracle-driven"] = result["oracle"]["after_calibration"]["object_error_by_steps_since_seen"]
    write_since_seen(card / "since_seen.png", curves, "L-Net object error against time since the object was seen")
    ablation_path = paths.LNET_ABLATION_CARD / "tracker.json"
    ablation = read_json(ablation_path) if ablation_path.is_file() else None
    shutil.copyfile(paths.LNET / "learning_curve.png", card / "learning_curve.png")
    shutil.copyfile(paths.LNET / "model.pt", card / "model.pt")
    shutil.copyfile(paths.LNET_CALIBRATION, card / "calibration.json")
    text = render_model_card(result, profile.lnet.model_dump(mode="json") | {"sim": profile.sim.model_dump()},
                             read_json(paths.LNET_CALIBRATION), read_json(paths.LNET / "train_summary.json"),
                             {"reliability": "reliability.png", "strip": "estimates_strip.png",
                              "gif": "estimates.gif", "learning_curve": "learning_curve.png",
                              "since_seen": "since_seen.png", "ablation": "../lnet_ablation/tracker.png"}, ablation)
    write_model_card(card / "README.md", text)
    return result
