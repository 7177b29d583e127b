"""Output helpers shared by the stages: JSON written whole or not at all."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from mor.atomic import atomic_output


def write_json(path: Path, payload: dict[str, Any]) -> Path:
    """Write ``payload`` to ``path`` through a temporary name, then rename."""
    with atomic_output(path) as partial:
        partial.write_text(json.dumps(payload, indent=2) + "\n")
    return path
