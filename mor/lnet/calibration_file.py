"""``calibration.json``, beside the checkpoint it belongs to: what ``mor calibrate-lnet`` fitted for it on
validation (``mor.lnet.calibration_fit``), read by whoever loads the checkpoint (``mor.lnet.runtime.load_lnet``).

It holds three records, as flat JSON fields: the scales of the stated uncertainty (``mor.lnet.calibration``:
``agent_scale``, ``object_scale``, ``kappa_scale``, ``shared_colour_scale``), the tracking settings they were fitted
with (``mor.lnet.filter.TrackingSettings``: ``data_association``, ``noise_own``, ``noise_shared``, ``gate``,
``negative_information``) and
the stated belief's parameters (``mor.lnet.stated.StatedParams``: ``lost_own``, ``lost_shared``, ``search_find``,
and the chosen ``not_found_sigma``, ``search_max_looks``, ``arena_grid_spacing``). A file without some of them
predates them and was fitted without them: they read as their defaults.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

from mor.errors import MorError
from mor.lnet.calibration import Calibration
from mor.lnet.filter import TrackingSettings
from mor.lnet.params import TRACKING_RULES
from mor.lnet.stated import StatedParams

CALIBRATION_FILE = "calibration.json"
#: the ``TrackingSettings`` fields a profile chooses (``lnet.<name>``) rather than the calibration fitting them
TRACKING_CHOSEN: tuple[str, ...] = (*TRACKING_RULES, "gate")


@dataclass(frozen=True)
class FittedCalibration:
    """What a ``calibration.json`` holds (the module docstring); ``FittedCalibration()`` is an uncalibrated run's:
    identity scales, default tracking, the Gaussian alone."""

    scales: Calibration = field(default_factory=Calibration)
    tracking: TrackingSettings = field(default_factory=TrackingSettings)
    stated: StatedParams = field(default_factory=StatedParams)

    def values(self) -> dict[str, Any]:
        """The flat JSON fields of ``calibration.json`` (scales, then tracking, then the stated belief's)."""
        scales, tracking, stated = (asdict(part) for part in (self.scales, self.tracking, self.stated))
        shared = scales.pop("shared_colour_scale")
        return {**scales, "data_association": tracking.pop("data_association"), "shared_colour_scale": shared,
                **tracking, **stated}


def recorded_settings(fitted: FittedCalibration) -> dict[str, Any]:
    """The tracking-time settings a run chooses in its profile (``LNetParams.chosen_settings``: the tracking rules,
    the filter's gate, and the stated belief's ``StatedParams.CHOSEN``: the not-found width, the search belief's
    look cap, the arena grid's spacing) that ``fitted`` was fitted with."""
    return {**{name: getattr(fitted.tracking, name) for name in TRACKING_CHOSEN},
            **{name: getattr(fitted.stated, name) for name in StatedParams.CHOSEN}}


def chosen_calibration(chosen: dict[str, Any], tracking: TrackingSettings | None = None,
                       stated: StatedParams | None = None) -> FittedCalibration:
    """A calibration with the chosen settings ``chosen`` (``recorded_settings``' keys, each optional) over
    ``tracking`` and ``stated`` (None: the defaults), identity scales: what a run tracks with before (or without)
    calibrate-lnet's fit."""
    tracking, stated = tracking or TrackingSettings(), stated or StatedParams()
    return FittedCalibration(
        tracking=replace(tracking, **{key: chosen[key] for key in TRACKING_CHOSEN if key in chosen}),
        stated=replace(stated, **{key: chosen[key] for key in StatedParams.CHOSEN if key in chosen}))


def _optional(value: Any) -> float | None:
    return None if value is None else float(value)


def calibration_from_values(values: dict[str, Any]) -> FittedCalibration:
    """The ``FittedCalibration`` a ``calibration.json`` (or one of its ``criteria``) records; ValueError, KeyError
    or TypeError where a field is missing or of the wrong kind."""
    rules = {rule: values.get(rule, False) for rule in TRACKING_RULES}
    for rule, value in rules.items():
        if not isinstance(value, bool):
            raise TypeError(f"{rule} must be true or false, got {value!r}")
    max_looks = values.get("search_max_looks", StatedParams.search_max_looks)
    if isinstance(max_looks, bool) or not isinstance(max_looks, int):
        raise TypeError(f"search_max_looks must be an integer, got {max_looks!r}")
    return FittedCalibration(
        Calibration(*(float(values[key]) for key in ("agent_scale", "object_scale", "kappa_scale")),
                    shared_colour_scale=_optional(values.get("shared_colour_scale"))),
        TrackingSettings(rules["data_association"], float(values.get("noise_own", 1.0)),
                         float(values.get("noise_shared", 1.0)), float(values.get("gate", TrackingSettings.gate)),
                         rules["negative_information"]),
        StatedParams(float(values.get("lost_own", 0.0)), _optional(values.get("lost_shared")),
                     _optional(values.get("search_find")),
                     float(values.get("not_found_sigma", StatedParams.not_found_sigma)),
                     max_looks,
                     float(values.get("arena_grid_spacing", StatedParams.arena_grid_spacing))))


def read_calibration(path: Path, dataset_version: str | None = None) -> FittedCalibration:
    """The calibration in the JSON file at ``path`` (written by ``mor calibrate-lnet``); one clear error if
    unusable, or if it records a dataset version other than ``dataset_version`` (the checkpoint's)."""
    try:
        values = json.loads(Path(path).read_text())
        calibration = calibration_from_values(values)
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


def check_scales(calibration: FittedCalibration, path: Path) -> None:
    """One clear error unless every scale and measurement-noise multiplier is a positive finite number (NaN
    estimates give NaN scales), every lost probability lies in [0, 1) and the search belief's find probability in
    [0, 1]."""
    scales, tracking, stated = calibration.scales, calibration.tracking, calibration.stated
    positive = (scales.agent_scale, scales.object_scale, scales.kappa_scale, tracking.noise_own, tracking.noise_shared,
                scales.object_scale if scales.shared_colour_scale is None else scales.shared_colour_scale)
    if not all(math.isfinite(scale) and scale > 0 for scale in positive):
        raise MorError(f"{path}: calibration scales must be positive and finite, got {calibration.values()}; run mor "
                       "calibrate-lnet (non-finite scales come from non-finite estimates on validation)")
    lost = (stated.lost_own, stated.lost_own if stated.lost_shared is None else stated.lost_shared)
    if not all(0.0 <= weight < 1.0 for weight in lost):
        raise MorError(f"{path}: lost_own and lost_shared must lie in [0, 1), got {lost}; run mor calibrate-lnet")
    if stated.search_find is not None and not 0.0 <= stated.search_find <= 1.0:
        raise MorError(f"{path}: search_find must lie in [0, 1], got {stated.search_find}; run mor calibrate-lnet")
