"""The calibration of the L-Net's stated uncertainty: three multipliers, fitted on validation (``mor.lnet.evaluate``)
for one tracking rule (with or without the filter's data association, which it records), and stored as
``calibration.json`` beside the checkpoint they belong to."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TypeVar

from mor.errors import MorError

CALIBRATION_FILE = "calibration.json"
_T = TypeVar("_T")


@dataclass(frozen=True)
class Calibration:
    """Multipliers of the stated standard deviations (agent, objects) and of the heading concentration, and whether
    they were fitted (and so must be used) with the filter's data association."""

    agent_scale: float = 1.0
    object_scale: float = 1.0
    kappa_scale: float = 1.0
    data_association: bool = False

    def apply(self, estimates: _T) -> _T:
        """A copy of ``estimates`` (any dataclass with ``agent_tril``, ``object_tril`` and ``kappa``) with the
        Cholesky factors and the concentration scaled."""
        return replace(estimates, agent_tril=estimates.agent_tril * self.agent_scale,  # type: ignore[type-var]
                       object_tril=estimates.object_tril * self.object_scale, kappa=estimates.kappa * self.kappa_scale)


def read_calibration(path: Path, dataset_version: str | None = None) -> Calibration:
    """The scales in the JSON file at ``path`` (written by ``mor calibrate-lnet``; a file without
    ``data_association`` predates the rule and was fitted without it); one clear error if unusable, or if it
    records a dataset version other than ``dataset_version`` (the checkpoint's)."""
    try:
        values = json.loads(Path(path).read_text())
        calibration = Calibration(*(float(values[key]) for key in ("agent_scale", "object_scale", "kappa_scale")),
                                  data_association=values.get("data_association", False))
        if not isinstance(calibration.data_association, bool):
            raise TypeError(f"data_association must be true or false, got {calibration.data_association!r}")
    except FileNotFoundError:
        raise MorError(f"{path}: no calibration beside the checkpoint; run mor calibrate-lnet") from None
    except (ValueError, KeyError, TypeError) as error:
        raise MorError(f"{path}: not an L-Net calibration ({type(error).__name__}: {error}); run mor calibrate-lnet")\
            from None
    fitted_on = values.get("dataset_version")
    if dataset_version is not None and fitted_on is not None and fitted_on != dataset_version:
        raise MorError(f"{path}: calibration dataset_version is {fitted_on} but the checkpoint's is {dataset_version}; "
                       "run mor calibrate-lnet for this checkpoint")
    check_scales(calibration, path)
    return calibration


def check_scales(calibration: Calibration, path: Path) -> None:
    """One clear error unless every scale is a positive finite number (NaN estimates give NaN scales)."""
    scales = (calibration.agent_scale, calibration.object_scale, calibration.kappa_scale)
    if not all(math.isfinite(scale) and scale > 0 for scale in scales):
        raise MorError(f"{path}: calibration scales must be positive and finite, got {calibration}; run mor "
                       "calibrate-lnet (non-finite scales come from non-finite estimates on validation)")
