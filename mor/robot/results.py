"""Scoring sim-as-robot runs: one JSON line per episode, and a loop's row of ``cards/robot/results.json``.

Episodes are the evaluation's (reset seed ``episode_seed(seed, episode)``, ``mor.sim.rollout``), so a row compares
with the method's row of ``cards/results/rows/`` played on the same episodes. A row holds the rearrangement
success (mean over episodes, std over seed means, a 95% BCa bootstrap interval over episodes:
``mor.eval.stats.summarize``), the pose estimate's errors against the truth over every step with a pose (medians,
metres and degrees) and the controller's step time (pose source and policy, milliseconds).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from mor.atomic import atomic_output
from mor.eval.stats import summarize
from mor.robot.sim_robot import SimEpisode

#: The sim-as-robot loops: the pose source each one uses.
LOOPS: dict[str, str] = {"aruco_topdown": "aruco", "fpv_lnet": "lnet"}


def episode_record(loop: str, method: str, seed: int, episode: int, reset_seed: int, played: SimEpisode
                   ) -> dict[str, Any]:
    """One episode's JSON line: its metrics, steps, whether the controller gave up, and per step with a pose the
    agent position error (mm), heading error (degrees) and step time (ms), rounded to 0.01."""
    return {"loop": loop, "method": method, "seed": seed, "episode": episode, "reset_seed": reset_seed,
            "metrics": played.metrics, "steps": played.steps, "gave_up": played.gave_up,
            "frames_without_pose": played.frames_without_pose,
            "position_error_mm": np.round(np.asarray(played.position_errors) * 1e3, 2).tolist(),
            "heading_error_deg": np.round(np.rad2deg(played.heading_errors), 2).tolist(),
            "step_ms": np.round(np.asarray(played.step_seconds) * 1e3, 2).tolist()}


def read_records(path: Path) -> list[dict[str, Any]]:
    """The JSON lines of ``path`` (none when it does not exist; a line cut short by a kill is dropped)."""
    if not path.is_file():
        return []
    records = []
    for line in path.read_text().splitlines():
        try:
            records.append(json.loads(line))
        except json.JSONDecodeError:
            continue
    return records


def _median(values: list[float], scale: float = 1.0, digits: int = 4) -> float | None:
    return round(float(np.median(values)) * scale, digits) if values else None


def loop_row(records: list[dict[str, Any]], resamples: int) -> dict[str, Any]:
    """The row of one (loop, method): success with its interval, pose errors and step times (see the module)."""
    by_seed: dict[int, list[float]] = {}
    for record in records:
        by_seed.setdefault(record["seed"], []).append(float(record["metrics"]["success"]))
    every = {key: [v for record in records for v in record[key]]
             for key in ("position_error_mm", "heading_error_deg", "step_ms")}
    return {
        "loop": records[0]["loop"], "method": records[0]["method"], "episodes": len(records),
        "episodes_by_seed": {str(seed): len(values) for seed, values in sorted(by_seed.items())},
        "rearrange_success": summarize(by_seed, resamples),
        "pose_error": {"agent_position_m": _median(every["position_error_mm"], 1e-3, 5),
                       "agent_position_m_p90": (round(float(np.percentile(every["position_error_mm"], 90)) * 1e-3, 5)
                                                if every["position_error_mm"] else None),
                       "heading_deg": _median(every["heading_error_deg"], digits=3),
                       "steps_with_pose": len(every["position_error_mm"])},
        "step_latency_ms": _median(every["step_ms"], digits=2),
        "steps": int(sum(record["steps"] for record in records)),
        "frames_without_pose": int(sum(record["frames_without_pose"] for record in records)),
        "episodes_given_up": int(sum(record["gave_up"] for record in records)),
    }


def same_episodes(success: dict[tuple[int, int], float], records: list[dict[str, Any]],
                  resamples: int) -> dict[str, Any]:
    """The evaluation's success on the loop's own episodes (``success``: (seed, episode) -> success, e.g.
    ``mor.robot.policy.evaluation_success``) summarised as the loop's, and on how many episodes the two differ."""
    by_seed: dict[int, list[float]] = {}
    for record in records:
        by_seed.setdefault(record["seed"], []).append(success[(record["seed"], record["episode"])])
    differ = sum(success[(r["seed"], r["episode"])] != float(r["metrics"]["success"]) for r in records)
    return {"rearrange_success": summarize(by_seed, resamples), "episodes_whose_success_differs": int(differ)}


def merge_row(path: Path, row: dict[str, Any]) -> dict[str, Any]:
    """``path``'s ``{"loops": [...]}`` with ``row`` in place of the row of the same loop and method."""
    document = json.loads(path.read_text()) if path.is_file() else {"loops": []}
    rows = [r for r in document["loops"] if (r["loop"], r["method"]) != (row["loop"], row["method"])]
    document["loops"] = sorted([*rows, row], key=lambda r: (list(LOOPS).index(r["loop"]), r["method"]))
    with atomic_output(path) as partial:
        partial.write_text(json.dumps(document, indent=2) + "\n")
    return document


__all__ = ["LOOPS", "episode_record", "loop_row", "merge_row", "read_records", "same_episodes"]
