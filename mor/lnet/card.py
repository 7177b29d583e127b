"""The L-Net's model card (Markdown with Hugging Face front matter), generated from the run's files."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import yaml

from mor.atomic import atomic_output
from mor.sim.rules import PICK_RANGE



_ERROR_ROWS = (("agent position (m)", ("agent_position_error_m",), 3),
               ("heading (deg)", ("heading_error_deg",), 2),
               ("objects in view now (m)", ("object_position_error_m", "visible"), 3),
               (f"objects in view within PICK's reach, ≤ {PICK_RANGE:g} m (m)",
                ("object_position_error_m", "visible_in_reach"), 3),
               ("objects seen earlier (m)", ("object_position_error_m", "seen"), 3),
               ("of which sharing their colour with another object, not held (m)",
                ("object_position_error_m", "seen_confusable"), 3),
               ("objects not yet seen (m)", ("object_position_error_m", "unseen"), 3),
               ("all objects (m)", ("object_position_error_m", "all"), 3))
_COVERAGE_GROUPS = ("agent_position", "heading", "objects_visible", "objects_seen", "objects_seen_confusable",
                    "objects_unseen")
_STATED_GROUPS = ("objects_seen", "objects_unseen")


def _get(d: dict, path: tuple[str, ...]) -> Any:
    for key in path:
        d = d.get(key, {}) if isinstance(d, dict) else {}
    return d


def _number(value: Any, digits: int) -> str:
    return "–" if value is None or value == {} or value != value else f"{float(value):.{digits}f}"


def error_table(block: dict[str, Any]) -> list[str]:
    """Median / 90th percentile / count of each error of one ``metrics`` block, as Markdown rows."""
    rows = ["| quantity | median | 90th percentile | frames |", "| --- | --- | --- | --- |"]
    for name, path, digits in _ERROR_ROWS:
        summary = _get(block, path)
        rows.append(f"| {name} | {_number(summary.get('median'), digits)} | {_number(summary.get('p90'), digits)} | "
                    f"{summary.get('count', '–')} |")
    return rows


def distance_table(columns: dict[str, dict[str, Any]]) -> list[str]:
    """Median error of the objects in view, per bin of their distance from the agent, one column per block."""
    bins = next(iter(columns.values()))["object_error_in_view_by_distance"]["bin_start"]
    edges = [f"{low:g}–{high:g} m" for low, high in zip(bins[:-1], bins[1:], strict=True)] + [f"≥ {bins[-1]:g} m"]
    rows = [f"| distance | {' | '.join(f'{name}: median (m) / frames' for name in columns)} |",
            "| --- |" + " --- |" * len(columns)]
    for k, edge in enumerate(edges):
        cells = [f"{_number(b['object_error_in_view_by_distance']['median_m'][k], 3)} / "
                 f"{b['object_error_in_view_by_distance']['count'][k]}" for b in columns.values()]
        rows.append(f"| {edge} | " + " | ".join(cells) + " |")
    return rows


def sightings_table(columns: dict[str, dict[str, Any]]) -> list[str]:
    """Objects seen earlier (not held): median error and 1/2/3-sigma coverage per bin of how many frames they have
    been in view so far, one column per named ``metrics`` block."""
    bins = next(iter(columns.values()))["objects_seen_by_sightings"]["bin_start"]
    edges = [f"{low}" if high - low == 1 else f"{low}–{high - 1}" for low, high in zip(bins[:-1], bins[1:],
                                                                                         strict=True)]
    edges.append(f"≥ {bins[-1]}")
    rows = [f"| frames in view so far | {' | '.join(f'{name}: median (m) / median d² / 1σ / 2σ / 3σ / count' for name in columns)} |",
            "| --- |" + " --- |" * len(columns)]
    for k, edge in enumerate(edges):
        cells = [" / ".join([_number(b["objects_seen_by_sightings"]["median_m"][k], 3),
                             _number(b["objects_seen_by_sightings"]["median_d2"][k], 2),
                             *(_number(b["objects_seen_by_sightings"][f"{j}sigma"][k], 3) for j in (1, 2, 3)),
                             str(b["objects_seen_by_sightings"]["count"][k])]) for b in columns.values()]
        rows.append(f"| {edge} | " + " | ".join(cells) + " |")
    return rows


def coverage_table(columns: dict[str, dict[str, Any]]) -> list[str]:
    """The NLLs and the 1/2/3-sigma coverage of each group, one column per named ``metrics`` block."""
    rows = [f"| metric | {' | '.join(columns)} |", "| --- |" + " --- |" * len(columns)]
    for name in ("agent_position", "heading", "objects"):
        rows.append(f"| NLL {name} | " + " | ".join(_number(_get(b, ("nll", name)), 3) for b in columns.values())
                    + " |")
    for group in _COVERAGE_GROUPS:
        for k in (1, 2, 3):
            rows.append(f"| coverage {group} {k}σ | " + " | ".join(
                _number(_get(b, ("coverage", group, f"{k}sigma")), 3) for b in columns.values()) + " |")
    if any("stated" in b for b in columns.values()):  # the objects' stated belief (mor.lnet.lost)
        rows.append("| NLL objects, stated | " + " | ".join(
            _number(_get(b, ("stated", "nll_objects")), 3) for b in columns.values()) + " |")
        for group in _STATED_GROUPS:
            for k in (1, 2, 3):
                rows.append(f"| coverage {group}, stated {k}σ | " + " | ".join(
                    _number(_get(b, ("stated", "coverage", group, f"{k}sigma")), 3) for b in columns.values())
                    + " |")
    return rows


def ablation_table(results: dict[str, Any]) -> list[str]:
    """One row per variant of an ``mor ablate-lnet`` study: the headline errors and coverage after calibration."""
    rows = ["| variant | agent (m) | heading (deg) | objects in view (m) | objects seen earlier (m) | objects "
            "unseen (m) | objects seen 1σ/2σ/3σ | NLL objects | train s |", "| --- |" + " --- |" * 8]
    for name, r in results.items():
        if not isinstance(r, dict) or "nll" not in r:
            continue
        errors = r["object_position_error_m"]
        seen = "/".join(_number(r["coverage"]["objects_seen"][f"{k}sigma"], 2) for k in (1, 2, 3))
        rows.append(f"| {name} | {r['agent_position_error_m']['median']:.3f} | {r['heading_error_deg']['median']:.2f}"
                    f" | {_number(errors.get('visible', {}).get('median'), 3)} | {errors['seen']['median']:.3f} | "
                    f"{_number(errors.get('unseen', {}).get('median'), 3)} | {seen} | {r['nll']['objects']:.3f} | "
                    f"{_number(r.get('train_seconds'), 0)} |")
    return rows


def _object_calibration(calibration: dict[str, Any]) -> str:
    """The objects' part of a calibration in words: their σ scale(s) and, when fitted, the filter's measurement
    noise multipliers."""
    shared = calibration.get("shared_colour_scale")
    scales = (f"objects σ × {calibration['object_scale']:.3f}" if shared is None else
              f"objects σ × {calibration['object_scale']:.3f} (of their own colour) and × {shared:.3f} (sharing "
              "their colour with another object of the episode)")
    lost = _lost_cell(calibration)
    if lost != "–":
        scales += f"; lost with probability {lost} (own / shared colour: the object anywhere in the arena)"
    if calibration.get("search_find") is not None:
        scales += (f"; objects not found yet: the search belief, one look finding the object with probability "
                   f"{calibration['search_find']:.2f}")
    noise = (calibration.get("noise_own", 1.0), calibration.get("noise_shared", 1.0))
    if noise == (1.0, 1.0):
        return scales
    return (f"{scales}; the filter's object measurement noise × {noise[0]:g} (own colour) and × {noise[1]:g} "
            "(shared colour), chosen from powers of two by the validation error of the objects seen earlier")


def _lost_cell(calibration: dict[str, Any]) -> str:
    """A calibration's lost probabilities (own / shared colour) as one cell; "–" where none was fitted."""
    own, shared = calibration.get("lost_own", 0.0), calibration.get("lost_shared")
    if not own and shared is None:
        return "–"
    return f"{own:.3f} / {own if shared is None else shared:.3f}"  # None: the same as own


_HEADLINE_COLUMNS = ("objects seen earlier, median (m) | in view, median (m) | agent, median (m) | object NLL | "
                     "objects seen earlier, 1σ / 2σ / 3σ")


def _levels(coverage: dict[str, float]) -> str:
    """A coverage block's 1σ / 2σ / 3σ as one cell."""
    return " / ".join(f"{coverage[f'{k}sigma']:.3f}" for k in (1, 2, 3))


def _headline_cells(r: dict[str, Any]) -> str:
    """The cells of ``_HEADLINE_COLUMNS`` from a ``mor.lnet.evaluate.headline``."""
    return (f"{r['objects_seen_median_m']:.3f} | {r['objects_visible_median_m']:.3f} | {r['agent_median_m']:.3f} | "
            f"{r['nll_objects']:.3f} | {_levels(r['coverage_objects_seen'])}")


def tracking_rule_table(rules: dict[str, dict[str, Any]]) -> list[str]:
    """One row per tracking rule of ``calibration.json``'s ``tracking_rules``: errors, NLL and coverage on
    validation after that rule's own calibration."""
    rows = [f"| rule | {_HEADLINE_COLUMNS} | objects σ × (own / shared colour) | measurement noise × (own / "
            "shared colour) |", "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for name, rule in rules.items():
        rows.append(f"| {name.replace('_', ' ')} | {_headline_cells(rule['validation_after'])} | "
                    f"{rule['object_scale']:.3f} / {_number(rule.get('shared_colour_scale'), 3)} | "
                    f"{rule.get('noise_own', 1.0):g} / {rule.get('noise_shared', 1.0):g} |")
    return rows


def precision_table(precisions: dict[str, dict[str, Any]]) -> list[str]:
    """One row per encoder precision of ``metrics.json``'s ``encoder_precision`` (test split, after calibration)."""
    rows = [f"| encoder | {_HEADLINE_COLUMNS} | heading, median (°) |", "| --- | --- | --- | --- | --- | --- | --- |"]
    rows += [f"| {name} | {_headline_cells(r)} | {r['heading_median_deg']:.2f} |" for name, r in precisions.items()]
    return rows


def criterion_table(criteria: dict[str, dict[str, Any]], scored: dict[str, dict[str, Any]], chosen: str
                    ) -> list[str]:
    """One row per calibration criterion: its multipliers (``calibration.json``'s ``criteria``) and the test
    split's coverage and NLL under them (``metrics.json``'s ``calibration_criteria``); ``chosen`` is marked."""
    rows = ["| criterion | agent σ × | objects σ × (own / shared colour) | objects lost (own / shared colour) | "
            "search: one look finds | κ × | objects seen earlier, Gaussian 1σ / 2σ / 3σ | objects seen earlier, "
            "stated 1σ / 2σ / 3σ | objects not yet seen, stated 1σ / 2σ / 3σ | agent, 1σ / 2σ / 3σ | heading, "
            "1σ / 2σ / 3σ | object NLL, Gaussian / stated | heading NLL |",
            "| --- |" + " --- |" * 12]
    for name, fitted in criteria.items():
        r = scored[name]
        stated, unseen = r.get("coverage_objects_seen_stated"), r.get("coverage_objects_unseen_stated")
        rows.append(f"| {name}{' (used)' if name == chosen else ''} | {fitted['agent_scale']:.3f} | "
                    f"{fitted['object_scale']:.3f} / {_number(fitted.get('shared_colour_scale'), 3)} | "
                    f"{_lost_cell(fitted)} | {_number(fitted.get('search_find'), 2)} | {fitted['kappa_scale']:.3f} | "
                    f"{_levels(r['coverage_objects_seen'])} | {_levels(stated) if stated else '–'} | "
                    f"{_levels(unseen) if unseen else '–'} | {_levels(r['coverage_agent'])} | "
                    f"{_levels(r['coverage_heading'])} | {r['nll_objects']:.3f} / "
                    f"{_number(r.get('nll_objects_stated'), 3)} | {r['nll_heading']:.3f} |")
    return rows


def render_model_card(metrics: dict[str, Any], params: dict[str, Any], calibration: dict[str, Any],
                      train_summary: dict[str, Any], figures: dict[str, str],
                      ablation: dict[str, Any] | None = None) -> str:
    """The card's text; every number comes from the dicts passed in (the stage's own outputs, and the committed
    results of ``mor ablate-lnet --study tracker`` when given)."""
    before, after = metrics["before_calibration"], metrics["after_calibration"]
    tracker = params["model"].get("tracker", "lstm")
    tracker_name = "LSTM" if tracker == "lstm" else "belief filter"
    front = {"license": "apache-2.0", "library_name": "pytorch", "tags": ["mor", "localization", "uncertainty",
             "robotics", tracker], "datasets": [f"mor-dataset-{metrics['dataset_version']}"],
             "pipeline_tag": "robotics"}
    nominal = before["coverage"]
    oracle, real = metrics.get("oracle"), metrics.get("real")
    seconds = train_summary.get("seconds")
    lines = [
        "---", yaml.safe_dump(front, sort_keys=False).strip(), "---", "",
        f"# MOR L-Net (PoseNet + {tracker_name})", "",
        "Estimates the robot's global position (bivariate Gaussian), heading (von Mises) and every object's position "
        "(bivariate Gaussians) from first-person RGB frames, the object class ids, the held-object index and "
        f"{'the previous action' if params['model']['use_actions'] or tracker == 'filter' else 'no action input'} "
        "(paper section 4.1; trained with the NLL of Eq. 5 plus the squared errors of the means, see "
        "docs/assumptions.md). "
        + ("The tracker is the paper's LSTM." if tracker == "lstm" else
           "The tracker is a differentiable world-frame Gaussian belief (`mor/lnet/filter.py`): a motion model "
           "learned from the previous action corrected by the PoseNet's fix, and per object a belief that stays on "
           "the floor, follows the agent while held, lands 1.5 m ahead on a drop, and is updated by the PoseNet's "
           "measurement weighted by its predicted visibility behind a Mahalanobis gate.")
        + (" Whole episodes are tracked with data association: a measurement that two slots claim (the PoseNet "
           "confuses objects of one colour) is shared by how well each belief explains it, and a doubtful update "
           "widens the belief (see 'Tracking rule' below)." if calibration.get("data_association") else "")
        + (" Objects that share their colour with another object of the episode (which the PoseNet confuses) get "
           "their own measurement noise and σ scale (see the calibration below and docs/assumptions.md)."
           if calibration.get("shared_colour_scale") is not None else "")
        + (" The PoseNet has a visibility head (BCE) and its ego object NLL counts only frames where the object "
           "is visible." if params["model"].get("visibility") else ""), "",
        f"- Dataset version: `{metrics['dataset_version']}`; test split: {before['episodes']} episodes, "
        f"{before['frames']} frames.",
        "- Training: " + (f"{train_summary['pretrain_steps']} PoseNet pretraining steps on single frames, then "
                          if train_summary.get("pretrain_steps") else "")
        + f"{train_summary['steps']} steps on windows, on {train_summary['device']}"
        + (f" ({seconds / 60:.1f} min wall time, {train_summary.get('torch_threads')} torch thread(s))"
           if seconds else "")
        + f", best validation loss {train_summary['best_validation_loss']:.3f}, early stop: "
        f"{train_summary['stopped_early']}.",
        f"- Calibration (fitted on validation): agent σ × {calibration['agent_scale']:.3f}, "
        + _object_calibration(calibration) + f", κ × {calibration['kappa_scale']:.3f}.", "",
        "## Errors on the test split (random-action episodes; means of the tracker's estimates)", "",
        *error_table(after), "",
        "'In view now': visible by the simulator's rule on this frame; 'seen earlier': visible or held at or before "
        "this frame; 'not yet seen': neither, so only the prior can answer.", "",
    ]
    by_distance = {"test": after} | ({"oracle-driven": oracle["after_calibration"]} if oracle else {})
    if all("object_error_in_view_by_distance" in block for block in by_distance.values()):
        lines += ["## Objects in view: error by distance", "",
                  f"An object far away is a few pixels of the frame; PICK reaches {PICK_RANGE:g} m.", "",
                  *distance_table(by_distance), ""]
    if oracle:
        lines += [f"## Errors on oracle-driven episodes ({oracle['after_calibration']['episodes']} Rearrange episodes, "
                  f"{oracle['after_calibration']['frames']} frames, tracked live by the streaming step)", "",
                  *error_table(oracle["after_calibration"]), ""]
    if real:
        lines += ["## Errors on real runs of the test split", "", *error_table(real["after_calibration"]), ""]
    columns = {"test, before": before, "test, after": after}
    if oracle:
        columns["oracle, after"] = oracle["after_calibration"]
    lines += [
        "## Likelihood and coverage", "",
        f"Nominal coverage: 2-D {nominal['nominal_2d']['1sigma']:.3f} / {nominal['nominal_2d']['2sigma']:.3f} / "
        f"{nominal['nominal_2d']['3sigma']:.3f}; heading {nominal['nominal_heading']['1sigma']:.3f} / "
        f"{nominal['nominal_heading']['2sigma']:.3f} / {nominal['nominal_heading']['3sigma']:.3f}.", "",
        *coverage_table(columns), "",
    ]
    if _lost_cell(calibration) != "–":
        lines += [f"'Stated': the objects' stated belief after calibration, their Gaussian or, with probability "
                  f"{_lost_cell(calibration)} (own / shared colour), anywhere in the arena; its kσ region is its "
                  "highest-density region of the 2-D kσ mass (`mor/lnet/lost.py`; the streaming step returns the "
                  "probability as `Estimates.object_lost`). The other object rows are its Gaussian alone.", ""]
    if calibration.get("search_find") is not None:
        share = after.get("stated", {}).get("searching_share", {})
        from mor.lnet.stated import StatedParams  # noqa: PLC0415 - the card module is torch-free elsewhere

        wider = calibration.get("not_found_sigma", StatedParams.not_found_sigma)  # absent: the default it used
        lines += [f"An object whose belief has not found it yet (wider than {wider:g} m) is stated by the search "
                  "belief instead: more likely where the estimated camera cone has not pointed, each look finding the "
                  f"object with probability {calibration['search_find']:.2f} (`mor/lnet/search.py`; the streaming "
                  "step marks those beliefs, `Estimates.object_searching`, and `SearchMap` keeps the looks in a "
                  "running loop). Beliefs stated by it on the test split: "
                  f"{_number(share.get('unseen'), 3)} of the objects not yet seen, {_number(share.get('seen'), 3)} "
                  "of those seen earlier.", ""]
    lines += [
        f"![reliability]({figures['reliability']})", "",
    ]
    by_sightings = {"test": after} | ({"oracle-driven": oracle["after_calibration"]} if oracle else {})
    if all("objects_seen_by_sightings" in block for block in by_sightings.values()):
        lines += ["### Objects seen earlier, by how many frames they have been in view so far (after calibration)",
                  "", "Objects not held now. d²: the squared Mahalanobis distance of the error under the stated "
                  "Gaussian; its median is 2 ln 2 = 1.39 where the stated uncertainty is honest. A median d² "
                  "below that (ellipses wider than most errors) together with a 3σ coverage below 0.989 (errors "
                  "beyond the stated tails) is a heavy-tailed error, which no single scale of a Gaussian covers at "
                  "all three levels (an NLL-fitted scale matches the mean of d², which the tail sets; see "
                  "'Calibration criterion' for the lost probabilities that cover the tail).", "",
                  *sightings_table(by_sightings), ""]
    lines += [
        f"![error against time since seen]({figures['since_seen']})", "",
    ]
    if calibration.get("tracking_rules"):
        lines += ["## Tracking rule: with and without data association (validation, each calibrated for itself)", "",
                  "The same trained weights; `mor calibrate-lnet` tracks the validation episodes both ways, fits "
                  "the measurement noise and the scales for each, and keeps the profile's `lnet.data_association`.",
                  "",
                  *tracking_rule_table(calibration["tracking_rules"]), ""]
    if metrics.get("calibration_criteria") and calibration.get("criteria"):
        lines += ["## Calibration criterion (test split)", "",
                  "The multipliers fitted on validation by the NLL (its optimum) and by the coverage (the 1σ / 2σ / "
                  "3σ coverage closest to nominal at its worst level), each with and without the objects' lost "
                  "probabilities (`+lost`: the stated belief of an object is its Gaussian, or with that probability "
                  "anywhere in the arena; its kσ region is its highest-density region of the 2-D kσ mass, "
                  "`mor/lnet/lost.py`; and the search belief of the objects not found yet, `mor/lnet/search.py`), "
                  "and the test split under each; `lnet.calibration.criterion` and "
                  "`lnet.calibration.lost_objects` choose which the L-Net uses. Without lost probabilities the "
                  "stated belief is the Gaussian.", "",
                  *criterion_table(calibration["criteria"], metrics["calibration_criteria"],
                                   calibration.get("criterion", "nll")), ""]
    if metrics.get("encoder_precision"):
        lines += ["## Encoder precision (test split, after calibration)", "",
                  "The same weights and calibration with the image encoder in float32 (as trained) and in bfloat16 "
                  "(`lnet.encoder_precision`; the heads and the tracker stay float32). `mor bench lnet` times both.",
                  "", *precision_table(metrics["encoder_precision"]), ""]
    if ablation:
        rule = ("the filter variants tracked with data association" if ablation.get("data_association") else
                "tracked without data association") + (
                    " and with negative information where they read visibility"
                    if ablation.get("negative_information") else "")
        pretrain = f"{ablation['pretrain_steps']} PoseNet + " if "pretrain_steps" in ablation else ""
        lines += [f"## Ablation: tracker and visibility loss at an equal budget ({pretrain}{ablation['steps']} "
                  "window steps each, "
                  f"first {ablation['test_episodes']} test episodes, after calibration, {rule})", "",
                  *ablation_table(ablation), "", "'train s' is wall time; the variants may have shared the "
                  "machine with other jobs, so it does not compare their costs.", "",
                  f"![ablation]({figures['ablation']})", ""]
    lines += [
        "## What the estimates look like", "",
        "Ground truth as stars, estimated 2σ ellipses, the heading's 95% sector (grey):", "",
        f"![estimates]({figures['strip']})", "", f"Animated: [{figures['gif']}]({figures['gif']})", "",
        f"![learning curve]({figures['learning_curve']})", "",
        "## Use", "",
        "```python\nfrom mor.lnet.runtime import load_lnet\n\nrunner = load_lnet(Path(\"cards/lnet/model.pt\"))  "
        "# reads calibration.json beside it\nstate = runner.initial_state(n_envs)\nestimates, state = runner.step("
        "images, object_classes, held, previous_actions, state)  # env observations, (N, ...)\n```", "",
        "Frames must have the training data's image size (checked at every step); `load_lnet(path, expected=...)` "
        "refuses a checkpoint of another config, tracker, dataset version or image size.", "",
        "## Intended use and limits", "",
        "- Trained on random-action episodes of the MOR simulator; its uncertainty is honest only for that data "
        "distribution (check the coverage after calibration before trusting it elsewhere, e.g. on real runs).",
        "- Objects never seen in an episode can only be guessed from the arena's prior: their errors are large by "
        "construction (see 'not yet seen').",
        "- Encoder trained from scratch (no pretrained weights are reachable here).", "",
        "## Parameters", "", "```yaml", yaml.safe_dump(params, sort_keys=False).strip(), "```", "",
    ]
    return "\n".join(lines)


def write_model_card(path: Path, text: str) -> Path:
    with atomic_output(path) as partial:
        partial.write_text(text)
    return path


def read_json(path: Path) -> dict[str, Any]:
    return json.loads(path.read_text())
