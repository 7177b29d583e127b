"""The paper's tables render from results.json rows, every cell in its column, missing rows named."""

from __future__ import annotations

import pytest

from mor.errors import ConfigError
from mor.eval.paper import METRIC_NAMES
from mor.eval.tables import TABLES, budget_line, require_complete, table_markdown


def _row(method: str, value: float) -> dict:
    summary = {"mean": value, "std": 0.01, "ci95": [value - 0.02, value + 0.02]}
    return {"method": method, "encoder": None, "arena": "square", "policy_arena": "square", "n_objects": 3,
            "seeds": [0, 1], "episodes_per_seed": 2, "train_steps": {"pick": 10},
            "metrics": {name: summary for name in METRIC_NAMES}}


def test_a_table_has_every_cell_in_its_column_and_the_papers_numbers_labelled() -> None:
    rows = [_row("gt_pose", 0.9), _row("lnet", 0.2), _row("lnet_no_uncertainty", 0.1)]
    lines = table_markdown(TABLES[2], rows).splitlines()
    widths = {line.count("|") for line in lines if line.startswith("|")}
    assert len(widths) == 1  # header, separator and rows alike
    assert "(paper)" in lines[0]
    gt = next(line for line in lines if line.startswith("| Policy w/ GT poses"))
    assert "0.900 ± 0.010 [0.880, 0.920] ✓ | 0.795 ± 0.030" in gt  # ours beside the paper's Pick
    lnet = next(line for line in lines if line.startswith("| Ours"))
    assert "0.200 ± 0.010 [0.180, 0.220] ✗ | 0.707 ± 0.020" in lnet
    require_complete(TABLES[2], rows)


def test_the_budget_line_names_each_protocol_of_the_tables_rows_once() -> None:
    held_out = {**_row("gt_pose", 0.9), "seeds": [100, 101], "method": "gt_pose_held_out"}  # in no table
    line = budget_line([_row("gt_pose", 0.9), _row("lnet", 0.2), held_out, {**_row("oracle", 1.0), "seeds": [7]}],
                       TABLES[2])
    assert line.startswith("Evaluation: 2 seeds (0, 1) × 2 episodes per task. Training steps")
    assert "100" not in line and "(7)" not in line


def test_a_table_with_rows_missing_names_them_and_the_commands() -> None:
    with pytest.raises(ConfigError, match=r"Table 2: no results for .*mor eval run --method lnet_no_uncertainty"):
        require_complete(TABLES[2], [_row("gt_pose", 0.9), _row("lnet", 0.2)])
    assert "Not yet run: Policy w/o uncertainty" in table_markdown(TABLES[2], [_row("gt_pose", 0.9)])


def test_a_stale_row_is_marked_with_the_command_that_re_runs_it() -> None:
    rows = [_row("gt_pose", 0.9), {**_row("lnet", 0.2), "stale": True}, _row("lnet_no_uncertainty", 0.1)]
    table = table_markdown(TABLES[2], rows)
    assert "(lnet) † |" in next(line for line in table.splitlines() if line.startswith("| Ours"))
    assert "† Played by other policies or through another L-Net" in table
    assert "(`mor eval run --method lnet`)" in table and "lnet_no_uncertainty`" not in table.split("†")[-1]
    assert "†" not in table_markdown(TABLES[2], [_row("gt_pose", 0.9)])


def test_the_policy_card_compares_with_and_without_uncertainty_by_their_intervals() -> None:
    from mor.eval.policy_card import ablation_pair, uncertainty_comparison

    pair = ablation_pair("lnet")
    assert pair == ablation_pair("lnet_no_uncertainty") == ("lnet", "lnet_no_uncertainty")
    assert ablation_pair("gt_pose") is None
    lines = uncertainty_comparison([_row("lnet", 0.5), _row("lnet_no_uncertainty", 0.3), _row("gt_pose", 0.9)], pair)
    assert len(lines) == len(METRIC_NAMES)
    assert lines[0].endswith("| lnet higher |")
    assert lines[-1].endswith("| lnet higher (worse) |")  # %E: lower is better
    close = uncertainty_comparison([_row("lnet", 0.5), _row("lnet_no_uncertainty", 0.49)], pair)
    assert all(line.endswith("| no difference shown |") for line in close)
    assert uncertainty_comparison([_row("lnet", 0.5)], pair) == []


def test_the_policy_card_names_the_policy_each_skill_was_fine_tuned_from() -> None:
    from mor.eval.policy_card import policy_card_markdown

    params = {"n_envs": 8, "hidden": [4], "n_steps": 8, "batch_size": 8, "n_epochs": 1, "learning_rate": 0.1,
              "gamma": 0.9, "gae_lambda": 0.9, "clip_range": 0.2, "ent_coef": 0.0}
    summaries = {"pick": {"steps": 10, "wall_seconds_this_run": 1.0, "steps_per_second_this_run": 10.0,
                          "warm_start": True, "warm_start_from": "../../cards/policy/lnet/pick/policy.pth",
                          "params": params},
                 "drop": {"steps": 10, "wall_seconds_this_run": 1.0, "steps_per_second_this_run": 10.0,
                          "warm_start": False, "warm_start_from": None, "params": params}}
    card = policy_card_markdown("lnet", summaries, [], None, "tiny")
    assert "| pick | 10 | 1 s | 10.0 | `../../cards/policy/lnet/pick` |" in card
    assert "| drop | 10 | 1 s | 10.0 | – |" in card


def test_each_row_short_of_the_paper_is_named_with_its_learning_curves_and_its_lnet_error() -> None:
    from mor.eval.tables import shortfalls

    localisation = {"settings/polygon": {"agent_m": 0.1, "heading_deg": 2.0, "objects_visible_m": 0.5,
                                         "objects_in_reach_m": 0.2, "objects_seen_m": 0.3, "file": "settings/polygon/cards/lnet/metrics.json"}}
    zero_shot = {**_row("lnet", 0.2), "arena": "polygon", "workspace": "settings/polygon",
                 "train_steps": {"pick": 10, "drop": 10, "decision": 0}}
    fine_tuned = {**zero_shot, "policy_arena": "polygon"}
    good = _row("baseline_delta_pose", 0.9)["metrics"] | {"energy_remaining": _row("lnet", 0.1)["metrics"]["pick_success"]}
    baseline = {**_row("baseline_delta_pose", 0.9), "arena": "polygon", "policy_arena": "polygon", "metrics": good,
                "encoder": "nature_cnn", "workspace": "settings/polygon", "train_steps": {"pick": 5, "drop": 5}}
    lines = shortfalls(TABLES[3], [zero_shot, fine_tuned, baseline], localisation)
    assert len(lines) == 2  # the baseline is better than the paper's on every metric: not listed
    assert lines[0].startswith("- Table 3, Ours (lnet), policies trained in the square arena: zero-shot: Pick 0.200 (paper 0.538)")
    assert "[pick](../../cards/policy/lnet/pick/learning_curve.png)" in lines[0]  # played the main workspace's
    assert "[pick](../../settings/polygon/cards/policy/lnet/pick/learning_curve.png)" in lines[1]
    assert "decision" not in lines[1]  # not trained: no learning curve
    assert "`settings/polygon/cards/lnet/metrics.json`" in lines[1] and "objects in view 0.500 m" in lines[1]
    assert shortfalls(TABLES[3], [{**fine_tuned, "metrics": baseline["metrics"]}], localisation) == []


def test_a_baseline_plays_the_img_baselines_pick_and_its_own_drop() -> None:
    from mor.eval.methods import METHODS

    def names(owners: dict) -> dict:
        return {task: variant.name for task, variant in owners.items()}

    assert names(METHODS["baseline_landmark"].skill_owners()) == {"pick": "baseline_img", "drop": "baseline_landmark"}
    assert names(METHODS["lnet_nearest_rule"].skill_owners()) == {"pick": "lnet", "drop": "lnet"}
    assert set(METHODS["lnet"].skill_owners()) == {"pick", "drop", "decision"} and METHODS["oracle"].skill_owners() == {}
    assert METHODS["lnet_no_uncertainty"].uses_lnet and not METHODS["gt_pose"].uses_lnet


def test_a_rows_paper_reference_is_the_table_line_that_shows_it() -> None:
    from mor.eval.tables import paper_reference

    assert paper_reference(_row("lnet", 0.5))["pick_success"] == (0.707, 0.020)  # Table 1, "Ours"
    assert paper_reference({**_row("lnet", 0.5), "n_objects": 2})["rearrange_success"] == (0.592, 0.008)  # Table 4
    fine_tuned = {**_row("lnet", 0.5), "arena": "polygon", "policy_arena": "polygon"}
    assert paper_reference(fine_tuned)["pick_success"] == (0.545, 0.018)  # Table 3, fine-tuned
    assert paper_reference(_row("lnet_nearest_rule", 0.5)) is None


def test_the_mark_against_the_paper_follows_our_interval_not_our_mean() -> None:
    from mor.eval.tables import verdict

    paper = (0.5, 0.02)
    assert verdict({"mean": 0.6, "ci95": [0.55, 0.65]}, paper, "pick_success") == "better"
    assert verdict({"mean": 0.52, "ci95": [0.45, 0.60]}, paper, "pick_success") == "no difference"
    assert verdict({"mean": 0.4, "ci95": [0.35, 0.45]}, paper, "pick_success") == "worse"
    assert verdict({"mean": 0.4, "ci95": [0.35, 0.45]}, paper, "energy_remaining") == "better"  # lower is better



def test_held_out_episodes_sit_beside_the_protocol_row_of_the_same_training_run() -> None:
    from mor.eval.card import held_out_section

    protocol = {**_row("lnet", 0.5), "training_seeds": [0, 1],
                "runs": [{"training_seed": 0, "metrics": _row("lnet", 0.6)["metrics"]},
                         {"training_seed": 1, "metrics": _row("lnet", 0.4)["metrics"]}]}
    held = {**_row("lnet", 0.55), "seeds": [100, 101], "episodes": "held_out", "training_seeds": [0]}
    line = held_out_section([protocol, held])[-1]
    assert line.startswith("| `lnet` | [0] / [0] | [0, 1] / [100, 101] | 0.600 [0.580, 0.620] / 0.550 [0.530, 0.570]")
    both = held_out_section([protocol, {**held, "training_seeds": [0, 1]}])[-1]
    assert "| [0, 1] / [0, 1] |" in both and "0.500 [0.480, 0.520] / 0.550" in both
