"""Stage ``calibrate_lnet``: fit the uncertainty scales on the validation split, for the profile's tracking rule.

The PoseNet runs once over the validation episodes; the tracker is replayed on its estimates for every setting
tried. With the filter tracker, both tracking rules (with and without data association) are calibrated (the
measurement noise, then the scales: ``mor.lnet.evaluate.calibrate``) and scored on validation, side by side in
``tracking_rules``: the evidence for ``lnet.data_association`` (the model card's table).
"""

from __future__ import annotations

import time
from dataclasses import asdict
from typing import Any

from mor.config import Profile
from mor.lnet.calibration import check_scales
from mor.lnet.evaluate import calibrate, frame_estimates, headline, metrics
from pipelines import paths
from pipelines.io import write_json
from pipelines.lnet_io import load_trained


def run(profile: Profile) -> dict[str, Any]:
    started = time.perf_counter()
    runner = load_trained(profile, paths.LNET / "model.pt", calibrated=False)
    episodes = frame_estimates(runner.model, paths.LEROBOT / "validation", profile.lnet.calibration.max_episodes,
                               runner.device)  # the PoseNet once; the tracker is replayed per rule and noise
    chosen = profile.lnet.data_association
    rules = (not chosen, chosen) if runner.config.tracker == "filter" else (chosen,)  # the chosen one last: kept
    fits = {}
    for rule in rules:
        runner.model.use_data_association(rule)
        fits[rule] = calibrate(runner.model, episodes)
    predictions, calibration, tried = fits[chosen]
    check_scales(calibration, paths.LNET_CALIBRATION)
    after = {rule: metrics(fitted.apply(p, p.confusable)) for rule, (p, fitted, _) in fits.items()}
    payload = {**asdict(calibration), "dataset_version": runner.dataset_version,
               "fitted_on": {"split": "validation", "frames": int(len(predictions.frame))},
               "measurement_noise_error_m": tried,
               "validation_before": metrics(predictions)["coverage"],
               "validation_after": after[chosen]["coverage"],
               "tracking_rules": {("with" if rule else "without") + "_data_association": {
                   **asdict(fitted), "validation_after": headline(after[rule])}
                   for rule, (_, fitted, _) in fits.items()},
               "seconds": round(time.perf_counter() - started, 1)}
    write_json(paths.LNET_CALIBRATION, payload)
    return payload
