"""Stage ``train_lnet``: train the L-Net on the train split (early stopping on validation; resumes)."""

from __future__ import annotations

from typing import Any

from mor.config import Profile
from mor.data.manifest import manifest_version, read_manifest
from mor.lnet.figures import write_learning_curve
from mor.lnet.train import LOG, train
from mor.locking import writer_lock
from pipelines import paths


def run(profile: Profile) -> dict[str, Any]:
    import csv

    version = manifest_version(read_manifest(paths.MANIFEST))
    with writer_lock(paths.LNET, "mor train-lnet"):
        summary = train(profile.lnet.model, profile.lnet.train, paths.LEROBOT / "train",
                        paths.LEROBOT / "validation", paths.LNET, version)
        with open(paths.LNET / LOG) as log:
            rows = [{**row, "step": int(row["step"]), "loss": float(row["loss"])} for row in csv.DictReader(log)]
        write_learning_curve(paths.LNET / "learning_curve.png", rows)
    return summary
