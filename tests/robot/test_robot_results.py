"""Scoring sim-as-robot runs: a loop's row, its place in results.json, and the card's verdict on the targets."""

from __future__ import annotations

import json
from pathlib import Path

from mor.robot.card import verdict, write_robot_card
from mor.robot.results import loop_row, merge_row, same_episodes


def _record(seed: int, episode: int, success: float) -> dict:
    return {"loop": "aruco_topdown", "method": "gt_pose", "seed": seed, "episode": episode, "reset_seed": 0,
            "metrics": {"success": success}, "steps": 10, "gave_up": False, "frames_without_pose": 1,
            "position_error_mm": [1.0, 3.0], "heading_error_deg": [0.5, 1.5], "step_ms": [10.0, 30.0]}


def test_a_loop_row_and_its_verdict(tmp_path: Path) -> None:
    records = [_record(seed, episode, float(episode != 1)) for seed in (0, 1) for episode in range(3)]
    row = loop_row(records, resamples=200)
    assert row["episodes"] == 6 and row["episodes_by_seed"] == {"0": 3, "1": 3}
    assert abs(row["rearrange_success"]["mean"] - 4 / 6) < 1e-9 and len(row["rearrange_success"]["ci95"]) == 2
    assert row["pose_error"]["agent_position_m"] == 0.002 and row["pose_error"]["heading_deg"] == 1.0
    assert (row["step_latency_ms"], row["frames_without_pose"]) == (20.0, 6)
    same = same_episodes({(r["seed"], r["episode"]): 1.0 for r in records}, records, resamples=200)
    assert same["episodes_whose_success_differs"] == 2 and same["rearrange_success"]["mean"] == 1.0

    reference = {"metrics": {"rearrange_success": {"mean": 0.65, "ci95": [0.6, 0.7]}}}
    assert verdict(row, reference) == ("success within 0.05: met; position <= 0.02 m: met; heading <= 2 deg: met; "
                                       ">= 100 episodes: MISSED")
    path = tmp_path / "results.json"
    merge_row(path, {**row, "rearrange_success": {**row["rearrange_success"], "mean": 0.0}})
    merge_row(path, {**row, "loop": "fpv_lnet"})
    document = merge_row(path, row)  # replaces the first
    assert [(r["loop"], r["rearrange_success"]["mean"]) for r in json.loads(path.read_text())["loops"]] == [
        ("aruco_topdown", row["rearrange_success"]["mean"]), ("fpv_lnet", row["rearrange_success"]["mean"])]
    assert verdict(document["loops"][1], reference) == "success inside the row's interval: met"  # 0.667
    card = write_robot_card(tmp_path / "README.md", document, {"gt_pose": reference}, "run.gif")
    assert "![sim-as-robot episode](run.gif)" in card.read_text()
