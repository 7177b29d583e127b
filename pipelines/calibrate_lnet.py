"""Stage ``calibrate_lnet``: fit the uncertainty scales on the validation split, for the profile's tracking rule.

The PoseNet runs once over the validation episodes; the tracker is replayed on its estimates for every setting
tried. With the filter tracker, both tracking rules (with and without data association) are calibrated (the
measurement noise, then the scales: ``mor.lnet.calibration_fit.calibrate``) and scored on validation, side by side in
``tracking_rules``: the evidence for ``lnet.data_association`` (the model card's table). For the chosen rule the
scales are also fitted by the other criterion (``lnet.calibration.criterion``: the NLL, or the coverage), each
with and without the objects' lost probabilities and search belief (``lnet.calibration.lost_objects``,
``mor.lnet.lost``, ``mor.lnet.search``), and
all are scored on validation, in ``criteria`` (keyed ``nll``, ``coverage``, ``nll+lost``, ``coverage+lost``).
"""

from __future__ import annotations

import time
from typing import Any

from mor.config import Profile
from mor.lnet.calibration_file import check_scales, chosen_calibration
from mor.lnet.calibration_fit import CRITERIA, calibrate, criterion_name, tracked_calibration
from mor.lnet.evaluate import calibrated_metrics, headline, metrics
from mor.lnet.filter import TrackingSettings
from mor.lnet.predict import frame_estimates
from mor.lnet.stated import stated_inputs
from mor.locking import writer_lock
from mor.sim.arena import Arena
from pipelines import paths
from pipelines.io import write_json
from pipelines.lnet_io import load_trained


def run(profile: Profile) -> dict[str, Any]:
    """Calibrate the trained L-Net of ``datasets/lnet/`` into its ``calibration.json``, holding that folder's lock
    (shared with ``mor train-lnet``: the model is not replaced while it is calibrated)."""
    with writer_lock(paths.LNET, "mor calibrate-lnet"):
        return _calibrate(profile)


def _calibrate(profile: Profile) -> dict[str, Any]:
    """``run``'s work, under the lock."""
    started = time.perf_counter()
    runner = load_trained(profile, paths.LNET / "model.pt", calibrated=False)
    episodes = frame_estimates(runner.model, paths.LEROBOT / "validation", profile.lnet.calibration.max_episodes,
                               runner.device)  # the PoseNet once; the tracker is replayed per rule and noise
    chosen, criterion = profile.lnet.data_association, profile.lnet.calibration.criterion
    lost = profile.lnet.calibration.lost_objects
    arena = Arena.build(profile.sim.arena, profile.sim.arena_size)
    rules = (not chosen, chosen) if runner.config.tracker == "filter" else (chosen,)  # the chosen one last: kept
    settings = chosen_calibration(profile.lnet.chosen_settings()).stated  # the stated belief's chosen settings
    fits = {}
    for rule in rules:
        runner.model.use_tracking(TrackingSettings(data_association=rule, gate=profile.lnet.gate,
                                                   negative_information=profile.lnet.negative_information))
        fits[rule] = calibrate(runner.model, episodes, criterion, arena if lost else None, settings)
    predictions, calibration, tried, inputs = fits[chosen]
    check_scales(calibration, paths.LNET_CALIBRATION)
    after = {rule: calibrated_metrics(p, fitted, rule_inputs) for rule, (p, fitted, _, rule_inputs) in fits.items()}
    # for the criteria with lost probabilities (and search)
    inputs = inputs or stated_inputs(predictions, arena, settings)
    name = criterion_name(criterion, lost)
    by_criterion = {criterion_name(other, with_lost): calibration if criterion_name(other, with_lost) == name else
                    tracked_calibration(runner.model, predictions, other, inputs if with_lost else None)
                    for with_lost in (False, True) for other in CRITERIA}  # the chosen rule's tracking
    payload = {**calibration.values(), "dataset_version": runner.dataset_version, "criterion": name,
               "fitted_on": {"split": "validation", "frames": int(len(predictions.frame))},
               "measurement_noise_error_m": tried,
               "validation_before": metrics(predictions)["coverage"],
               "validation_after": after[chosen]["coverage"],
               "validation_after_stated": after[chosen]["stated"]["coverage"],
               "tracking_rules": {("with" if rule else "without") + "_data_association": {
                   **fitted.values(), "validation_after": headline(after[rule])}
                   for rule, (_, fitted, _, _) in fits.items()},
               "criteria": {other: {**fitted.values(), "validation_after": headline(
                   after[chosen] if other == name else calibrated_metrics(predictions, fitted, inputs))}
                   for other, fitted in by_criterion.items()},
               "seconds": round(time.perf_counter() - started, 1)}
    write_json(paths.LNET_CALIBRATION, payload)
    return payload
