"""Stage ``calibrate_lnet``: fit the uncertainty scales on the validation split, for the profile's tracking rule.

The PoseNet runs once over the validation episodes; the tracker is replayed on its estimates for every setting
tried. With the filter tracker, both tracking rules (with and without data association) are calibrated (the
measurement noise, then the scales: ``mor.lnet.evaluate.calibrate``) and scored on validation, side by side in
``tracking_rules``: the evidence for ``lnet.data_association`` (the model card's table). For the chosen rule the
scales are also fitted by the other criterion (``lnet.calibration.criterion``: the NLL, or the coverage) and
both are scored on validation, in ``criteria``.
"""

from __future__ import annotations

import time
from dataclasses import asdict
from typing import Any

from mor.config import Profile
from mor.lnet.calibration import check_scales
from mor.lnet.evaluate import CRITERIA, calibrate, frame_estimates, headline, metrics, tracked_calibration
from pipelines import paths
from pipelines.io import write_json
from pipelines.lnet_io import load_trained


def run(profile: Profile) -> dict[str, Any]:
    started = time.perf_counter()
    runner = load_trained(profile, paths.LNET / "model.pt", calibrated=False)
    episodes = frame_estimates(runner.model, paths.LEROBOT / "validation", profile.lnet.calibration.max_episodes,
                               runner.device)  # the PoseNet once; the tracker is replayed per rule and noise
    chosen, criterion = profile.lnet.data_association, profile.lnet.calibration.criterion
    rules = (not chosen, chosen) if runner.config.tracker == "filter" else (chosen,)  # the chosen one last: kept
    fits = {}
    for rule in rules:
        runner.model.use_data_association(rule)
        fits[rule] = calibrate(runner.model, episodes, criterion)
    predictions, calibration, tried = fits[chosen]
    check_scales(calibration, paths.LNET_CALIBRATION)
    after = {rule: metrics(fitted.apply(p, p.confusable)) for rule, (p, fitted, _) in fits.items()}
    by_criterion = {name: calibration if name == criterion else tracked_calibration(runner.model, predictions, name)
                    for name in CRITERIA}  # the chosen rule's tracking, each criterion's scales
    payload = {**asdict(calibration), "dataset_version": runner.dataset_version, "criterion": criterion,
               "fitted_on": {"split": "validation", "frames": int(len(predictions.frame))},
               "measurement_noise_error_m": tried,
               "validation_before": metrics(predictions)["coverage"],
               "validation_after": after[chosen]["coverage"],
               "tracking_rules": {("with" if rule else "without") + "_data_association": {
                   **asdict(fitted), "validation_after": headline(after[rule])}
                   for rule, (_, fitted, _) in fits.items()},
               "criteria": {name: {**asdict(fitted), "validation_after": headline(
                   after[chosen] if name == criterion else metrics(fitted.apply(predictions, predictions.confusable)))}
                   for name, fitted in by_criterion.items()},
               "seconds": round(time.perf_counter() - started, 1)}
    write_json(paths.LNET_CALIBRATION, payload)
    return payload
