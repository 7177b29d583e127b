"""Stage ``validate``: every episode file and every split against the manifest; writes the report."""

from __future__ import annotations

from pathlib import Path

from mor.data.manifest import read_manifest
from mor.data.validate import ValidationReport, validate
from pipelines.io import write_json


def run(manifest_path: Path, episodes_dir: Path, datasets_root: Path, report_path: Path) -> ValidationReport:
    report = validate(read_manifest(manifest_path).to_pylist(), episodes_dir, datasets_root)
    write_json(report_path, report.to_json())
    return report
