"""Stage ``calibrate_lnet``: fit the uncertainty scales on the validation split."""

from __future__ import annotations

import time
from dataclasses import asdict
from typing import Any

from mor.config import Profile
from mor.lnet.evaluate import fit_calibration, metrics, predict
from pipelines import paths
from pipelines.io import write_json
from pipelines.lnet_io import load_trained


def run(profile: Profile) -> dict[str, Any]:
    started = time.perf_counter()
    runner = load_trained(profile, paths.LNET / "model.pt", calibrated=False)
    predictions = predict(runner.model, paths.LEROBOT / "validation", profile.lnet.calibration.max_episodes,
                          runner.device)
    calibration = fit_calibration(predictions)
    payload = {**asdict(calibration), "dataset_version": runner.dataset_version,
               "fitted_on": {"split": "validation", "frames": int(len(predictions.frame))},
               "validation_before": metrics(predictions)["coverage"],
               "validation_after": metrics(calibration.apply(predictions))["coverage"],
               "seconds": round(time.perf_counter() - started, 1)}
    write_json(paths.LNET_CALIBRATION, payload)
    return payload
