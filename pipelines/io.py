"""Output helpers shared by the stages: JSON written whole or not at all."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

from mor.atomic import atomic_output


#: a JSON list of numbers only, as ``json.dumps(indent=2)`` spreads it over lines
_NUMBER_LIST = re.compile(r"\[\s*(-?[0-9][0-9.eE+-]*(?:,\s*-?[0-9][0-9.eE+-]*)*)\s*\]")


def write_json(path: Path, payload: dict[str, Any]) -> Path:
    """Write ``payload`` to ``path`` through a temporary name, then rename; indented, with each list of numbers on
    one line (a row's per-episode outcomes stay readable)."""
    text = _NUMBER_LIST.sub(lambda m: "[" + ", ".join(item.strip() for item in m.group(1).split(",")) + "]",
                            json.dumps(payload, indent=2))
    with atomic_output(path) as partial:
        partial.write_text(text + "\n")
    return path
