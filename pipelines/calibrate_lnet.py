"""Stage ``calibrate_lnet``: fit the uncertainty scales on the validation split, for the profile's tracking rule.

With the filter tracker, both tracking rules (with and without data association) are fitted and scored on
validation, side by side in ``tracking_rules``: the evidence for ``lnet.data_association`` (the model card's table).
"""

from __future__ import annotations

import time
from dataclasses import asdict, replace
from typing import Any

from mor.config import Profile
from mor.lnet.calibration import Calibration, check_scales
from mor.lnet.evaluate import Predictions, fit_calibration, metrics, predict
from mor.lnet.runtime import LNetRunner
from pipelines import paths
from pipelines.io import write_json
from pipelines.lnet_io import load_trained


def _fitted(runner: LNetRunner, profile: Profile, data_association: bool) -> tuple[Predictions, Calibration]:
    """Validation predictions with the given tracking rule and the calibration fitted on them."""
    runner.model.use_data_association(data_association)
    predictions = predict(runner.model, paths.LEROBOT / "validation", profile.lnet.calibration.max_episodes,
                          runner.device)
    return predictions, replace(fit_calibration(predictions), data_association=data_association)


def _headline(scored: dict[str, Any]) -> dict[str, Any]:
    """The figures the model card compares the tracking rules by, from ``metrics``."""
    errors = scored["object_position_error_m"]
    return {"objects_seen_median_m": errors["seen"]["median"], "objects_visible_median_m": errors["visible"]["median"],
            "agent_median_m": scored["agent_position_error_m"]["median"], "nll_objects": scored["nll"]["objects"],
            "coverage_objects_seen": scored["coverage"]["objects_seen"]}


def run(profile: Profile) -> dict[str, Any]:
    started = time.perf_counter()
    runner = load_trained(profile, paths.LNET / "model.pt", calibrated=False)
    chosen = profile.lnet.data_association
    rules = (chosen, not chosen) if runner.config.tracker == "filter" else (chosen,)
    fits = {rule: _fitted(runner, profile, rule) for rule in rules}
    predictions, calibration = fits[chosen]
    check_scales(calibration, paths.LNET_CALIBRATION)
    payload = {**asdict(calibration), "dataset_version": runner.dataset_version,
               "fitted_on": {"split": "validation", "frames": int(len(predictions.frame))},
               "validation_before": metrics(predictions)["coverage"],
               "validation_after": metrics(calibration.apply(predictions))["coverage"],
               "tracking_rules": {("with" if rule else "without") + "_data_association": {
                   **asdict(fitted), "validation_after": _headline(metrics(fitted.apply(rule_predictions)))}
                   for rule, (rule_predictions, fitted) in fits.items()},
               "seconds": round(time.perf_counter() - started, 1)}
    write_json(paths.LNET_CALIBRATION, payload)
    return payload
