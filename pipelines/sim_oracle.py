"""Stage ``oracle``: the ground-truth oracle's metrics on every task (mean +- std over seeds)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from mor.config import Profile
from mor.sim import TASKS
from mor.sim.rollout import evaluate
from pipelines.io import write_json


def run(profile: Profile, tasks: list[str], episodes: int, seeds: list[int], out: Path) -> dict[str, Any]:
    """Evaluate the oracle on ``tasks`` and write ``out``; returns what was written."""
    results = {
        task: evaluate(TASKS[task][0], "oracle", episodes, seeds, profile.sim.model_dump()) for task in tasks
    }
    payload = {"tasks": results}
    write_json(out, payload)
    return payload
