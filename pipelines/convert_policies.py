"""``mor policy convert``: committed policy files from SB3's pickled format to MOR's safe one, once."""

from __future__ import annotations

import json
from pathlib import Path

from mor.eval.results import repoint_policy_digests
from pipelines import paths
from pipelines.io import write_json


def run(files: list[Path]) -> list[tuple[Path, str, str]]:
    """Rewrite each SB3-pickled policy file of ``files`` in MOR's safe format (weights bit-identical; this unpickles
    them: the user trusts them), and re-point the results rows that recorded the old files' digests
    (``cards/results/rows`` of this workspace and of every setting) at the new ones. Returns (file, old digest,
    new digest) for each file converted; files already safe are skipped."""
    from mor.lnet.runtime import file_digest  # noqa: PLC0415 - torch only where needed
    from mor.policy.policy_file import convert_sb3_policy, is_sb3_pickle  # noqa: PLC0415

    converted = []
    for path in files:
        if is_sb3_pickle(path):
            old = file_digest(path)
            convert_sb3_policy(path)
            converted.append((path, old, file_digest(path)))
    renamed = {old: new for _, old, new in converted}
    for rows in (paths.RESULTS_CARD / "rows", *sorted(paths.SETTINGS.glob(f"*/{paths.RESULTS_CARD}/rows"))):
        for path in sorted(rows.glob("*.json")):
            row = json.loads(path.read_text())
            if repoint_policy_digests(row, renamed):
                write_json(path, row)
    return converted
