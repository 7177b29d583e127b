"""Validation names every bad file in one line, checks the rest, and feeds re-collection."""

from __future__ import annotations

import shutil
from pathlib import Path

from mor.data.collect import CollectionSpec, ProfileShape, collect
from mor.data.validate import validate


def test_clean_dataset_validates(tiny_dataset: tuple, tiny_collection: Path, tiny_spec: CollectionSpec) -> None:
    _, root, rows = tiny_dataset
    report = validate(rows, tiny_collection, (tiny_collection,), root, ProfileShape(tiny_spec), progress=False)
    assert report.ok, report.problems
    assert report.episodes_checked == len(rows)
    assert sum(split["episodes"] for split in report.splits.values()) == len(rows)


def test_truncated_and_corrupt_files_are_named_and_the_rest_checked(
    tiny_dataset: tuple, episodes_copy: Path, tiny_spec: CollectionSpec, tiny_episodes: int
) -> None:
    _, root, rows = tiny_dataset
    truncated, corrupt = episodes_copy / rows[0]["file"], episodes_copy / rows[1]["file"]
    truncated.write_bytes(truncated.read_bytes()[: truncated.stat().st_size // 2])
    data = bytearray(corrupt.read_bytes())
    data[len(data) // 2] ^= 0xFF
    corrupt.write_bytes(bytes(data))
    report = validate(rows, episodes_copy, (episodes_copy,), root, ProfileShape(tiny_spec), progress=False)
    assert report.rejected == [rows[0]["file"], rows[1]["file"]]
    assert report.episodes_checked == len(rows)
    assert all("\n" not in problem for problem in report.problems)
    assert truncated.name in report.problems[0] and corrupt.name in report.problems[1]
    # Re-collection redoes exactly the rejected files; then validation passes again.
    result = collect(tiny_spec, episodes_copy, tiny_episodes, workers=1, progress=False,
                     rejected=set(report.rejected))
    assert result["collected"] == 2
    assert validate(rows, episodes_copy, (episodes_copy,), root, ProfileShape(tiny_spec), progress=False).ok


def test_split_count_mismatch_is_reported(tiny_dataset: tuple, tiny_collection: Path, tmp_path: Path,
                                          tiny_spec: CollectionSpec) -> None:
    _, root, rows = tiny_dataset
    copy = Path(shutil.copytree(root, tmp_path / "lerobot"))
    shutil.rmtree(copy / "test")
    report = validate(rows, tiny_collection, (tiny_collection,), copy, ProfileShape(tiny_spec), progress=False)
    assert not report.ok
    assert any("split 'test'" in problem for problem in report.problems)
