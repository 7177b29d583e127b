"""Stage ``validate``: every episode file and every split against the manifest; writes the report."""

from __future__ import annotations

from mor.config import Profile
from mor.data.manifest import read_manifest
from mor.data.validate import ValidationReport, validate
from mor.timing import timed
from pipelines import paths
from pipelines.shapes import profile_shape
from pipelines.io import write_json


def run(profile: Profile) -> ValidationReport:
    """Validate the manifest's episodes (each decoded whole, in the profile's build workers, and compared with
    ``profile``'s data-shaping params) and splits; write the report with its wall time in seconds (also when
    problems were found)."""
    seconds: dict[str, float] = {}
    with timed(seconds, "validate"):
        report = validate(read_manifest(paths.MANIFEST).to_pylist(), paths.DATASETS, paths.EPISODE_FOLDERS,
                          paths.LEROBOT, profile_shape(profile), workers=profile.build.workers)
    write_json(paths.VALIDATION_REPORT, {**report.to_json(), "seconds": seconds["validate"]})
    return report
