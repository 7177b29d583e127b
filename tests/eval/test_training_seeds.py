"""Rows over training runs: the stratified bootstrap, the aggregation of per-run rows, and the comparisons."""

from __future__ import annotations

import numpy as np
import pytest

from mor.errors import ConfigError
from mor.eval.results import aggregate_runs, comparisons, method_row, row_name
from mor.eval.stats import probability_of_improvement, summarize_runs

METRICS = ("pick_success", "drop_success", "rearrange_success", "fixed_strict", "energy_remaining")


def _outcomes(p: float, seed: int, energy: float = 0.3) -> dict:
    rng = np.random.default_rng(seed)
    values = {m: {str(s): (rng.random(40) < p).astype(float).tolist() for s in range(2)} for m in METRICS}
    values["energy_remaining"] = {str(s): [energy] * 40 for s in range(2)}
    return values


def _row(method: str, training_seed: int, p: float, version: str | None = None, energy: float = 0.3) -> dict:
    return {"method": method, "encoder": None, "arena": "square", "policy_arena": "square", "n_objects": 3,
            "seeds": [0, 1], "episodes_per_seed": 40, "training_seed": training_seed, "workspace": ".",
            "metrics": {m: {"mean": p} for m in METRICS}, "outcomes": _outcomes(p, training_seed, energy),
            "played_by": {"policies": {}, "lnet_version": version}}


def test_the_interval_spans_the_runs_and_one_run_has_no_spread() -> None:
    runs = [{"0": [1.0] * 50, "1": [0.0] * 50}, {"0": [1.0] * 100}, {"0": [0.0] * 100}]
    summary, distribution = summarize_runs(runs, resamples=2000)
    assert summary["run_means"] == [0.5, 1.0, 0.0] and summary["mean"] == pytest.approx(0.5)
    assert summary["std"] == pytest.approx(0.5) and distribution.shape == (2000,)
    assert summary["ci95"][0] < 0.2 and summary["ci95"][1] > 0.8  # the runs disagree: a wide interval
    alone, _ = summarize_runs([{"0": [1.0, 0.0] * 50}], resamples=2000)
    assert alone["std"] == 0.0 and alone["ci95"][0] < 0.5 < alone["ci95"][1]


def test_probability_of_improvement_counts_ties_half() -> None:
    assert probability_of_improvement([[1.0, 1.0]], [[0.0, 0.0]]) == 1.0
    assert probability_of_improvement([[0.0, 1.0]], [[0.0, 1.0]]) == 0.5
    assert probability_of_improvement([[0.0]], [[1.0], [0.0]]) == 0.25


def test_runs_of_one_method_become_one_row_and_other_lnets_are_refused() -> None:
    rows = aggregate_runs([_row("lnet", 0, 0.5, "v1"), _row("lnet", 1, 0.7, "v1"), _row("gt_pose", 0, 0.9)], 500)
    lnet = next(row for row in rows if row["method"] == "lnet")
    assert lnet["training_seeds"] == [0, 1] and [run["training_seed"] for run in lnet["runs"]] == [0, 1]
    assert set(lnet["metrics"]["pick_success"]) >= {"mean", "std", "ci95", "iqm"}
    assert next(row for row in rows if row["method"] == "gt_pose")["training_seeds"] == [0]
    with pytest.raises(ConfigError, match=r"lnet: training seed 0 played through L-Net v1 but seed 1 through v2"):
        aggregate_runs([_row("lnet", 0, 0.5, "v1"), _row("lnet", 1, 0.5, "v2")])


def test_the_verdict_follows_the_interval_of_the_difference() -> None:
    better = aggregate_runs([_row("lnet", s, 0.9, energy=0.1) for s in range(3)]
                            + [_row("lnet_no_uncertainty", s, 0.3, energy=0.5) for s in range(3)], 500)
    found = {c["metric"]: c for c in comparisons(better, 500)}
    assert found["rearrange_success"]["verdict"] == "helps" and found["rearrange_success"]["difference"]["mean"] > 0.5
    assert found["energy_remaining"]["verdict"] == "helps"  # lower is better
    assert found["rearrange_success"]["probability_of_improvement"] > 0.7
    same = aggregate_runs([_row("lnet", s, 0.5) for s in range(3)] + [_row("lnet_no_uncertainty", s + 10, 0.5)
                                                                      for s in range(3)], 500)
    assert {c["verdict"] for c in comparisons(same, 500) if c["metric"] != "energy_remaining"} == {"no evidence"}
    worse = aggregate_runs([_row("lnet", 0, 0.1), _row("lnet_no_uncertainty", 0, 0.9)], 500)
    assert {c["metric"]: c for c in comparisons(worse, 500)}["pick_success"]["verdict"] == "hurts"


def test_a_held_out_row_is_not_compared_in_place_of_the_protocol_row() -> None:
    held_out = {**_row("lnet", 0, 0.1), "episodes": "held_out"}
    rows = aggregate_runs([_row("lnet", s, 0.9) for s in range(3)] + [held_out]
                          + [_row("lnet_no_uncertainty", s, 0.9) for s in range(3)], 500)
    found = {c["metric"]: c for c in comparisons(rows, 500)}
    assert found["pick_success"]["training_seeds"]["lnet"] == [0, 1, 2]
    assert found["pick_success"]["verdict"] == "no evidence"


def test_a_folders_protocol_and_held_out_rows_are_each_aggregated_over_their_own_runs(tmp_path) -> None:
    import json

    for seed in range(3):
        (tmp_path / f"{row_name('lnet', seed)}.json").write_text(json.dumps(_row("lnet", seed, 0.9)))
        held_out = {**_row("lnet", seed, 0.1), "episodes": "held_out"}
        (tmp_path / f"{row_name('lnet', seed, held_out=True)}.json").write_text(json.dumps(held_out))
    assert sorted(p.name for p in tmp_path.iterdir())[:2] == ["lnet.held_out.json", "lnet.json"]
    protocol, held = method_row(tmp_path, "lnet", 200), method_row(tmp_path, "lnet.held_out", 200)
    assert protocol["training_seeds"] == held["training_seeds"] == [0, 1, 2]
    assert protocol.get("episodes") is None and held["episodes"] == "held_out"
    assert protocol["metrics"]["pick_success"]["mean"] > 0.7 > 0.3 > held["metrics"]["pick_success"]["mean"]
    with pytest.raises(ConfigError, match=r"no row of 'lnet_search.held_out' \(lnet_search.held_out.json or "
                                          r"lnet_search.seed_S.held_out.json\); run mor eval run --method lnet_search"):
        method_row(tmp_path, "lnet_search.held_out", 200)


def test_the_card_says_where_a_compared_pair_trained_for_different_steps() -> None:
    from mor.eval.card import comparison_section

    def runs(method: str, pick_steps: int) -> list[dict]:
        return [{**_row(method, s, 0.5), "train_steps": {"pick": pick_steps, "drop": 100}} for s in range(2)]

    equal = comparison_section(comparisons(aggregate_runs(runs("lnet", 400) + runs("lnet_no_uncertainty", 400),
                                                          200), 200))
    assert not any("unequal budgets" in line for line in equal)
    unequal = comparison_section(comparisons(aggregate_runs(runs("lnet_search", 100) + runs("lnet", 400), 200),
                                             200))
    assert [line for line in unequal if "unequal budgets" in line] == [
        "- `lnet_search` against `lnet`: unequal budgets (steps, a / b: pick 100 / 400); the difference mixes what "
        "they observe with how long they trained."]


def test_mor_eval_compare_states_the_difference_of_two_folders_of_rows(tmp_path) -> None:
    """The same statistics as the results' comparisons, for any two rows: here gt_pose from two folders."""
    import json
    import re

    from typer.testing import CliRunner

    from pipelines.cli import app

    for folder, p in (("new", 0.95), ("old", 0.4)):
        (tmp_path / folder).mkdir()
        for seed in range(3):
            name = "gt_pose.json" if seed == 0 else f"gt_pose.seed_{seed}.json"
            (tmp_path / folder / name).write_text(json.dumps(_row("gt_pose", seed, p)))
    out = tmp_path / "compare.json"
    result = CliRunner().invoke(app, ["eval", "compare", f"{tmp_path / 'new'}:gt_pose", f"{tmp_path / 'old'}:gt_pose",
                                      "--out", str(out), "--profile", "tiny"])
    assert result.exit_code == 0, result.output
    assert re.search(r"rearrange_success: \+0\.\d{3} \[\+0\.\d{3}, \+0\.\d{3}\] helps", result.output), result.output
    written = json.loads(out.read_text())
    found = {c["metric"]: c for c in written["comparisons"]}
    assert written["metrics"][f"{tmp_path / 'new'}:gt_pose"]["pick_success"]["mean"] > 0.8  # each side's row too
    assert found["pick_success"]["training_seeds"][f"{tmp_path / 'new'}:gt_pose"] == [0, 1, 2]
    missing = CliRunner().invoke(app, ["eval", "compare", f"{tmp_path}:gt_pose", f"{tmp_path / 'old'}:gt_pose",
                                       "--profile", "tiny"])
    assert missing.exit_code == 2 and "no row of 'gt_pose'" in missing.stderr, missing.output
