"""Stage ``calibrate_lnet``: fit the uncertainty scales on the validation split."""

from __future__ import annotations

from dataclasses import asdict
from typing import Any

from mor.config import Profile
from mor.lnet.evaluate import fit_calibration, metrics, predict
from pipelines import paths
from pipelines.io import write_json
from pipelines.lnet_io import load_trained


def run(profile: Profile) -> dict[str, Any]:
    model, device = load_trained(profile, paths.LNET / "model.pt")
    predictions = predict(model, paths.LEROBOT / "validation", profile.lnet.calibration.max_episodes, device)
    calibration = fit_calibration(predictions)
    payload = {**asdict(calibration), "fitted_on": {"split": "validation", "frames": int(len(predictions.frame))},
               "validation_before": metrics(predictions)["coverage"],
               "validation_after": metrics(calibration.apply(predictions))["coverage"]}
    write_json(paths.LNET_CALIBRATION, payload)
    return payload
