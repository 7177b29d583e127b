"""``mor ablate-lnet``: variants of the L-Net (``mor.lnet.params.ABLATIONS``) at an equal step budget."""

from __future__ import annotations

from typing import Any

from mor.config import Profile
from mor.data.manifest import manifest_version, read_manifest
from mor.errors import MorError
from mor.lnet.calibration_file import chosen_calibration
from mor.lnet.calibration_fit import calibrate
from mor.lnet.checkpoint import signature
from mor.lnet.evaluate import metrics
from mor.lnet.figures import write_since_seen
from mor.lnet.filter import TrackingSettings
from mor.lnet.params import ABLATIONS, TrainParams
from mor.lnet.predict import frame_estimates, predict
from mor.lnet.runtime import load_lnet
from mor.lnet.train import BEST, pick_device, train
from pipelines import paths
from pipelines.io import write_json

ABLATION = paths.DATASETS / "lnet_ablation"
REPORTED = ("nll", "agent_position_error_m", "heading_error_deg", "object_position_error_m",
            "object_error_by_steps_since_seen", "coverage")


def run(profile: Profile, study: str, steps: int, episodes: int, pretrain_steps: int | None = None
        ) -> dict[str, Any]:
    """Train each variant of ``study`` for ``pretrain_steps`` PoseNet steps (None: the profile's) and ``steps``
    window steps (same seed, data and other parameters), calibrate each
    on validation, score each on the first ``episodes`` test episodes (the filter variants tracked with the profile's
    ``lnet.data_association``); writes ``<ABLATION>/<study>/results.json``
    and ``since_seen.png`` (median object error against frames since last seen, one line per variant)."""
    if study not in ABLATIONS:
        raise MorError(f"--study: unknown study {study!r}; choose one of {', '.join(ABLATIONS)}")
    version = manifest_version(read_manifest(paths.MANIFEST))
    device = pick_device()
    pretrain = profile.lnet.train.pretrain_steps if pretrain_steps is None else pretrain_steps
    base = profile.lnet.train.model_copy(update={"max_steps": steps, "pretrain_steps": pretrain, "patience": 10**6})
    results: dict[str, Any] = {"study": study, "steps": steps, "pretrain_steps": pretrain, "test_episodes": episodes, "dataset_version": version,
                               "data_association": profile.lnet.data_association,
                               "negative_information": profile.lnet.negative_information}
    for name, overrides in ABLATIONS[study].items():
        params = base.model_copy(update={k: v for k, v in overrides.items() if k in TrainParams.model_fields})
        config = profile.lnet.model.model_copy(update={k: v for k, v in overrides.items()
                                                       if k not in TrainParams.model_fields})
        out = ABLATION / study / name
        summary = train(config, params, paths.LEROBOT / "train", paths.LEROBOT / "validation", out, version, device)
        model = load_lnet(out / BEST, device, signature(config, version, summary["image_size"]), calibrated=False).model
        filtering = config.tracker == "filter"
        model.use_tracking(TrackingSettings(data_association=profile.lnet.data_association and filtering,
                                            gate=profile.lnet.gate,
                                            negative_information=profile.lnet.negative_information and filtering
                                            and config.visibility))
        _, calibration, _, _ = calibrate(model, frame_estimates(model, paths.LEROBOT / "validation", episodes, device),
                                         settings=chosen_calibration(profile.lnet.chosen_settings()).stated)
        test = predict(model, paths.LEROBOT / "test", episodes, device)
        scored = metrics(calibration.scales.apply(test, test.confusable))
        results[name] = {key: scored[key] for key in REPORTED}
        results[name].update(best_validation_loss=summary["best_validation_loss"], train_seconds=summary["seconds"],
                             overrides=overrides, calibration=calibration.values())
        write_json(ABLATION / study / "results.json", results)  # after each variant: a partial study is readable
    curves = {name: results[name]["object_error_by_steps_since_seen"] for name in ABLATIONS[study]}
    title = f"L-Net ablation '{study}' at {pretrain} + {steps} steps: object error vs time since seen (test)"
    write_since_seen(ABLATION / study / "since_seen.png", curves, title)
    # The committed copy, which the model card shows (outside cards/lnet, which the eval stage rewrites whole).
    write_json(paths.LNET_ABLATION_CARD / f"{study}.json", results)
    write_since_seen(paths.LNET_ABLATION_CARD / f"{study}.png", curves, title)
    return results
