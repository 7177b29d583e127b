"""The model card's tables from the stage outputs."""

from __future__ import annotations

from mor.lnet.card import criterion_table, precision_table, tracking_rule_table


def test_the_tracking_rule_table_has_one_row_per_rule_from_its_own_calibration() -> None:
    def rule(seen: float, scale: float, **fitted: float) -> dict:
        return {"object_scale": scale, **fitted, "validation_after": {
            "objects_seen_median_m": seen, "objects_visible_median_m": 0.25, "agent_median_m": 0.12,
            "nll_objects": 1.6, "coverage_objects_seen": {"1sigma": 0.74, "2sigma": 0.939, "3sigma": 0.965}}}

    rows = tracking_rule_table({"with_data_association": rule(0.2, 1.28, shared_colour_scale=0.9, noise_own=0.25,
                                                              noise_shared=32.0),
                                "without_data_association": rule(0.216, 2.149)})  # a calibration from before
    assert len(rows) == 4 and rows[0].count("|") == rows[1].count("|") == rows[2].count("|")
    assert rows[2] == ("| with data association | 0.200 | 0.250 | 0.120 | 1.600 | 0.740 / 0.939 / 0.965 | 1.280 / "
                       "0.900 | 0.25 / 32 |")
    assert rows[3].startswith("| without data association | 0.216 |") and rows[3].endswith("| 2.149 / – | 1 / 1 |")


def test_the_precision_table_has_one_row_per_encoder_precision() -> None:
    scored = {"objects_seen_median_m": 0.18, "objects_visible_median_m": 0.22, "agent_median_m": 0.12,
              "heading_median_deg": 1.375, "nll_objects": 1.0,
              "coverage_objects_seen": {"1sigma": 0.57, "2sigma": 0.9, "3sigma": 0.98}}
    rows = precision_table({"float32": scored, "bfloat16": {**scored, "objects_seen_median_m": 0.19}})
    assert len(rows) == 4 and rows[0].count("|") == rows[1].count("|") == rows[3].count("|")
    assert rows[2] == "| float32 | 0.180 | 0.220 | 0.120 | 1.000 | 0.570 / 0.900 / 0.980 | 1.38 |"
    assert rows[3].startswith("| bfloat16 | 0.190 |")


def test_the_criterion_table_shows_each_criterion_s_multipliers_and_test_coverage() -> None:
    levels = {"1sigma": 0.4, "2sigma": 0.86, "3sigma": 0.99}
    scored = {"coverage_objects_seen": levels, "coverage_agent": levels, "coverage_heading": levels,
              "nll_objects": 1.0, "nll_heading": -1.5}
    fitted = {"agent_scale": 0.96, "object_scale": 0.9, "shared_colour_scale": 2.26, "kappa_scale": 1.918}
    stated = {**scored, "coverage_objects_seen_stated": {"1sigma": 0.39, "2sigma": 0.87, "3sigma": 0.985},
              "coverage_objects_unseen_stated": {"1sigma": 0.41, "2sigma": 0.85, "3sigma": 0.98},
              "nll_objects_stated": 0.7}
    rows = criterion_table({"nll": fitted, "coverage": {**fitted, "kappa_scale": 2.2},
                            "nll+lost": {**fitted, "lost_own": 0.08, "lost_shared": 0.31, "search_find": 0.62}},
                           {"nll": scored, "coverage": scored, "nll+lost": stated}, "nll+lost")
    assert len(rows) == 5 and len({row.count("|") for row in rows}) == 1
    assert rows[2].startswith("| nll | 0.960 | 0.900 / 2.260 | – | – | 1.918 | 0.400 / 0.860 / 0.990 | – | – |")
    assert rows[3].startswith("| coverage | 0.960 |") and "| 2.200 |" in rows[3] and rows[3].endswith("| -1.500 |")
    assert rows[4].startswith("| nll+lost (used) | 0.960 | 0.900 / 2.260 | 0.080 / 0.310 | 0.62 | 1.918 | "
                              "0.400 / 0.860 / 0.990 | 0.390 / 0.870 / 0.985 | 0.410 / 0.850 / 0.980 |")
    assert "| 1.000 / 0.700 |" in rows[4]
