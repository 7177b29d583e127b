"""The paper's Tables 1-4 as views of ``cards/results/results.json``: our rows beside the paper's numbers.

Every number of ours comes from a row of results.json (written by ``mor eval run``); the paper's come from
``mor.eval.paper`` and are labelled "paper". A table whose rows are not all there renders what exists and names
each missing row with the command that produces it (``require_complete`` turns that into one error instead).
"""

from __future__ import annotations

import posixpath
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from mor.errors import ConfigError
from mor.eval import paper
from mor.eval.methods import METHODS
from mor.eval.paper import LOWER_IS_BETTER, METRIC_NAMES
from mor.eval.results import is_zero_shot
from mor.sim.rules import PICK_RANGE

METRIC_LABELS = {"pick_success": "Pick", "drop_success": "Drop", "rearrange_success": "Rearr. success",
                 "fixed_strict": "%FS", "energy_remaining": "%E ↓"}


@dataclass(frozen=True)
class TableRow:
    """One line of a table: our row (selected by ``match`` from results.json) and the paper's row, if any."""

    label: str
    match: dict[str, Any]
    paper: tuple[tuple[float, float] | None, ...] | None = None
    command: str = ""


@dataclass(frozen=True)
class TableSpec:
    number: int
    title: str
    rows: list[TableRow] = field(default_factory=list)


#: a match value that accepts any value of that field (the baselines' encoder is the profile's)
ANY = object()


def _ours(method: str, **setting: Any) -> dict[str, Any]:
    return {"method": method, "arena": "square", "policy_arena": "square", "n_objects": 3, **setting}


def _eval(method: str, extra: str = "") -> str:
    return f"mor eval run --method {method}{extra}"


POLYGON_LNET = "mor --setting polygon collect / build-dataset / train-lnet / calibrate-lnet / eval-lnet"


def _in(setting: str, command: str) -> str:
    """``command`` (a ``mor ...`` line) run in setting ``setting``'s workspace."""
    return command.replace("mor ", f"mor --setting {setting} ", 1)


def _objects_row(n: int) -> TableRow:
    """Table 4's line for ``n`` objects: 3 is the main workspace's lnet row, the others a setting's."""
    if n == 3:
        return TableRow("3 objects: Ours (lnet)", _ours("lnet"), paper.TABLE4[3], _eval("lnet"))
    setting = f"objects_{n}"
    return TableRow(f"{n} object{'s' if n > 1 else ''}: Ours (lnet)", _ours("lnet", n_objects=n), paper.TABLE4[n],
                    _in(setting, "mor policy train --variant gt_pose; ") + _in(setting, "mor policy train --variant "
                                                                                 "lnet; ") + _in(setting, _eval("lnet")))


TABLES: dict[int, TableSpec] = {
    1: TableSpec(1, "Our methods and the baselines (paper Table 1)", [
        TableRow("Policy w/ GT poses (gt_pose)", _ours("gt_pose"), paper.TABLE1["Policy w/ GT poses"], _eval("gt_pose")),
        TableRow("Ours: L-Net + uncertainty (lnet)", _ours("lnet"), paper.TABLE1["Ours"], _eval("lnet")),
        *(TableRow(f"Baseline: CNN + {label} (paper: ResNet18 + {label})", _ours(name, encoder=ANY),
                   paper.TABLE1[f"ResNet18 + {label}"], f"mor policy train --variant {name}; {_eval(name)}")
          for name, label in (("baseline_img", "Img"), ("baseline_delta_pose", "ΔPose"),
                              ("baseline_landmark", "Landmark"))),
        TableRow("gt_pose sub-policies + nearest-object rule", _ours("gt_pose_nearest_rule"), None,
                 _eval("gt_pose_nearest_rule")),
        TableRow("lnet sub-policies + nearest-object rule", _ours("lnet_nearest_rule"), None, _eval("lnet_nearest_rule")),
        TableRow("Scripted oracle with GT poses (not learned)", _ours("oracle"), None, _eval("oracle")),
    ]),
    2: TableSpec(2, "With and without uncertainty (paper Table 2)", [
        TableRow("Policy w/ GT poses (gt_pose)", _ours("gt_pose"), paper.TABLE2["Policy w/ GT poses"], _eval("gt_pose")),
        TableRow("Policy w/o uncertainty (lnet_no_uncertainty)", _ours("lnet_no_uncertainty"),
                 paper.TABLE2["Policy w/o uncertainty"], _eval("lnet_no_uncertainty")),
        TableRow("Ours: policy + uncertainty (lnet)", _ours("lnet"), paper.TABLE2["Ours (Policy + uncertainty)"],
                 _eval("lnet")),
    ]),
    3: TableSpec(3, "The polygon arena: L-Net retrained there, policies zero-shot or fine-tuned (paper Table 3)", [
        TableRow("Baseline: CNN + ΔPose trained in the polygon arena (paper: ResNet50 + ΔPose)",
                 _ours("baseline_delta_pose", arena="polygon", policy_arena="polygon", encoder=ANY),
                 paper.TABLE3["ResNet50 + ΔPose"],
                 "mor --setting polygon policy train --variant baseline_img / --variant baseline_delta_pose; "
                 + _in("polygon", _eval("baseline_delta_pose"))),
        TableRow("Ours (lnet), policies trained in the square arena: zero-shot", _ours("lnet", arena="polygon"),
                 paper.TABLE3["W/o fine tuning"], f"{POLYGON_LNET}; " + _in("polygon", _eval("lnet", " --zero-shot"))),
        TableRow("Ours (lnet), policies fine-tuned in the polygon arena",
                 _ours("lnet", arena="polygon", policy_arena="polygon"), paper.TABLE3["Fine tuning"],
                 f"{POLYGON_LNET}; mor --setting polygon policy train --variant lnet; "
                 + _in("polygon", _eval("lnet"))),
    ]),
    4: TableSpec(4, "1 to 5 objects (paper Table 4)", [_objects_row(n) for n in range(1, 6)]),
}


def find_row(rows: list[dict[str, Any]], match: dict[str, Any]) -> dict[str, Any] | None:
    """The results row whose fields equal ``match`` (``ANY``: any value; the encoder is unset unless ``match``
    names one)."""
    wanted = {"encoder": None, "episodes": None, **match}  # the protocol's episodes unless ``match`` says otherwise
    for row in rows:
        if all(value is ANY or row.get(key) == value for key, value in wanted.items()):
            return row
    return None


def paper_reference(row: dict[str, Any]) -> dict[str, tuple[float, float] | None] | None:
    """The paper's numbers ({metric: (mean, std) or None}) beside ``row`` in the first table that shows it (the
    same method in another setting is another table's line), or None where the paper has no counterpart."""
    for spec in TABLES.values():
        for line in spec.rows:
            if line.paper is not None and find_row([row], line.match) is row:
                return dict(zip(METRIC_NAMES, line.paper, strict=True))
    return None


def row_label(line: TableRow, row: dict[str, Any]) -> str:
    """The line's label, with the encoder our row was trained with where it has one (the baselines)."""
    return f"{line.label} [ours: {row['encoder']}]" if row.get("encoder") else line.label


def missing_rows(spec: TableSpec, rows: list[dict[str, Any]]) -> list[TableRow]:
    return [line for line in spec.rows if find_row(rows, line.match) is None]


def require_complete(spec: TableSpec, rows: list[dict[str, Any]]) -> None:
    """ConfigError listing each row of ``spec`` missing from results.json and the command that produces it."""
    missing = missing_rows(spec, rows)
    if missing:
        listed = "; ".join(f"{line.label} ({line.command})" for line in missing)
        raise ConfigError(f"Table {spec.number}: no results for {listed}; run those, then mor eval results")


def _cell(summary: dict[str, Any] | None) -> str:
    if summary is None:
        return "–"
    low, high = summary["ci95"]
    return f"{summary['mean']:.3f} ± {summary['std']:.3f} [{low:.3f}, {high:.3f}]"


def _paper_cell(value: tuple[float, float] | None) -> str:
    return "–" if value is None else f"{value[0]:.3f} ± {value[1]:.3f}"


#: what a table's cells and marks mean; printed with every table (``mor eval tables``, the results card)
LEGEND = ("Cells: mean ± std over the evaluation seeds' means [95% bootstrap interval]. Marks against the paper's "
          "mean: ✓ our whole 95% interval is better (above it; below it for %E, where lower is better), ✗ our "
          "whole interval is worse, ≈ our interval contains the paper's mean (no difference shown). † a stale row "
          "(played by other policies or another L-Net than the committed ones). The (paper) columns are the "
          "paper's published numbers, not ours.")


def verdict(ours: dict[str, Any], theirs: tuple[float, float], metric: str) -> str:
    """"better" or "worse" when our whole 95% interval lies on that side of the paper's mean (%E: lower is
    better), "no difference" when it contains it."""
    low, high = ours["ci95"]
    above, below = low > theirs[0], high < theirs[0]
    if not (above or below):
        return "no difference"
    return "better" if above != (metric in LOWER_IS_BETTER) else "worse"


def _beats(ours: dict[str, Any] | None, theirs: tuple[float, float] | None, metric: str) -> str:
    if ours is None or theirs is None:
        return ""
    return {"better": " ✓", "worse": " ✗", "no difference": " ≈"}[verdict(ours, theirs, metric)]


def table_markdown(spec: TableSpec, rows: list[dict[str, Any]]) -> str:
    """Markdown of one table: for each metric our cell (mean ± std over seeds [95% CI]) and the paper's."""
    header = ["Method"] + [f"{METRIC_LABELS[m]} {side}" for m in METRIC_NAMES for side in ("ours", "(paper)")]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for line in spec.rows:
        row = find_row(rows, line.match)
        if row is None:
            continue
        cells = []
        for k, metric in enumerate(METRIC_NAMES):
            ours, theirs = row["metrics"].get(metric), line.paper[k] if line.paper else None
            cells.append(f"{_cell(ours)}{_beats(ours, theirs, metric)} | {_paper_cell(theirs)}")
        lines.append(f"| {row_label(line, row)}{' †' if row.get('stale') else ''} | " + " | ".join(cells) + " |")
    stale = [line for line in spec.rows if (row := find_row(rows, line.match)) is not None and row.get("stale")]
    if stale:
        lines.append("")
        lines.append("† Played by other policies or through another L-Net than the ones committed now (the "
                     "row's `played_by` in results.json); to re-run: " + "; ".join(
                         f"{line.label} (`{line.command}`)" for line in stale) + ".")
    missing = missing_rows(spec, rows)
    if missing:
        lines.append("")
        lines.append("Not yet run: " + "; ".join(f"{m.label} (`{m.command}`)" for m in missing) + ".")
    return "\n".join(lines)


def write_table_figure(spec: TableSpec, rows: list[dict[str, Any]], path: Path) -> Path | None:
    """Grouped bars per metric: each of our rows (95% CI as error bars) beside the paper's (± its std), in one
    colour per row; stale rows cross-hatched and named so; rows not run yet listed in the legend."""
    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415
    from matplotlib.patches import Patch  # noqa: PLC0415

    from mor.atomic import atomic_output  # noqa: PLC0415

    present = [(line, find_row(rows, line.match)) for line in spec.rows]
    present = [(line, row) for line, row in present if row is not None]
    if not present:
        return None
    figure, ax = plt.subplots(figsize=(11, 5.6))
    slots = sum(2 if line.paper else 1 for line, _ in present)
    width, x, slot = 0.8 / slots, np.arange(len(METRIC_NAMES)), 0
    handles = []
    for k, (line, row) in enumerate(present):
        colour = plt.get_cmap("tab10")(k % 10)
        means = np.array([row["metrics"][m]["mean"] for m in METRIC_NAMES])
        errors = np.array([[row["metrics"][m]["mean"] - row["metrics"][m]["ci95"][0],
                            row["metrics"][m]["ci95"][1] - row["metrics"][m]["mean"]] for m in METRIC_NAMES]).T
        bars = [(means, errors, 0.9, "xx" if row.get("stale") else None)]
        if line.paper:
            bars.append((np.array([v[0] if v else np.nan for v in line.paper]),
                         np.array([v[1] if v else 0.0 for v in line.paper]), 0.35, "//"))
        for means_k, errors_k, alpha, hatch in bars:  # edges keep a zero-height bar visible as a line at 0
            ax.bar(x + (slot - (slots - 1) / 2) * width, means_k, width, yerr=errors_k, hatch=hatch, capsize=2,
                   color=colour, alpha=alpha, edgecolor="black", linewidth=0.6)
            slot += 1
        label = row_label(line, row) + (" † stale" if row.get("stale") else "")
        handles.append(Patch(facecolor=colour, edgecolor="black", label=label))
    handles += [Patch(facecolor="white", edgecolor="black", label="solid: ours (95% interval)"),
                Patch(facecolor="white", edgecolor="black", hatch="//", label="hatched: the paper's (± its std)")]
    missing = missing_rows(spec, rows)
    if missing:
        handles.append(Patch(facecolor="none", edgecolor="none",
                             label="not run: " + ", ".join(m.label for m in missing)))
    ax.set_xticks(x, [METRIC_LABELS[m] for m in METRIC_NAMES])
    ax.set_ylim(-0.02, 1.05)
    ax.set_title(f"Table {spec.number}: {spec.title}")
    columns = 2 if max(len(h.get_label()) for h in handles) > 45 else 3  # long labels: fewer columns, all visible
    ax.legend(handles=handles, fontsize=7, ncol=columns, loc="upper center", bbox_to_anchor=(0.5, -0.07))
    ax.grid(axis="y", alpha=0.3)
    figure.tight_layout()
    with atomic_output(path) as partial:
        figure.savefig(partial, dpi=110, format="png")
    plt.close(figure)
    return path


def budget_line(rows: list[dict[str, Any]], spec: TableSpec) -> str:
    """What the table's rows were trained and evaluated with, from the rows themselves."""
    parts, present = [], [(line, find_row(rows, line.match)) for line in spec.rows]
    repeated = [row["method"] for _, row in present if row is not None]
    for line, row in present:
        if row is not None and row.get("train_steps"):
            steps = ", ".join(f"{k} {v:,}" for k, v in row["train_steps"].items())
            parts.append(f"{line.label if repeated.count(row['method']) > 1 else row['method']}: {steps}")
    evaluated = {(tuple(r["seeds"]), r["episodes_per_seed"]) for _, r in present if r is not None}
    protocol = "; ".join(f"{len(s)} seeds ({', '.join(map(str, s))}) × {e} episodes per task"
                         for s, e in sorted(evaluated)) or "–"
    return f"Evaluation: {protocol}. Training steps (decisions for the decision policy): " + ("; ".join(parts) or "–")


#: what the shortfall notes quote from an L-Net's metrics.json (``after_calibration``, medians on the test split)
LOCALISATION_KEYS = {"agent_m": (("agent_position_error_m",), "agent"),
                     "heading_deg": (("heading_error_deg",), "heading"),
                     "objects_visible_m": (("object_position_error_m", "visible"), "objects in view"),
                     "objects_in_reach_m": (("object_position_error_m", "visible_in_reach"),
                                            f"objects in view within PICK's {PICK_RANGE:g} m reach"),
                     "objects_seen_m": (("object_position_error_m", "seen"), "objects seen earlier")}


def localisation_headline(metrics: dict[str, Any]) -> dict[str, float]:
    """The medians ``LOCALISATION_KEYS`` names from an L-Net's metrics.json content."""
    headline = {}
    for key, (path, _) in LOCALISATION_KEYS.items():
        node = metrics["after_calibration"]
        for part in path:
            node = node[part]
        headline[key] = float(node["median"])
    return headline


def _learning_curves(row: dict[str, Any]) -> str:
    """Links (from ``cards/results/``) to the learning curves of the policies ``row``'s method played and trained."""
    method = METHODS[row["method"]]
    workspace = "." if is_zero_shot(row) else row.get("workspace", ".")  # zero-shot: the main workspace's policies
    trained = row.get("train_steps") or {}
    folder = posixpath.normpath(f"../../{workspace}/cards/policy")
    links = [f"[{task}]({folder}/{owner.name}/{task}/learning_curve.png)"
             for task, owner in method.skill_owners().items() if trained.get(task)]
    return ", ".join(links)


def _localisation(row: dict[str, Any], localisation: dict[str, dict[str, Any]]) -> str:
    """The L-Net error the row's method played with (its workspace's L-Net), or "" for a method without one."""
    found = localisation.get(row.get("workspace", "."))
    if not METHODS[row["method"]].uses_lnet or found is None:
        return ""
    medians = ", ".join(f"{label} {found[key]:.2f}°" if key == "heading_deg" else f"{label} {found[key]:.3f} m"
                        for key, (_, label) in LOCALISATION_KEYS.items())
    return f"; its L-Net (`{found['file']}`, test split after calibration, medians): {medians}"


def shortfalls(spec: TableSpec, rows: list[dict[str, Any]], localisation: dict[str, dict[str, Any]]) -> list[str]:
    """One line per row of ``spec`` not shown better than the paper's on some metric (``verdict``: worse, or no
    difference): those metrics, and the evidence of why (the learning curves of its policies; the localisation
    error of its L-Net in that setting).

    localisation: workspace ("." or "settings/NAME") -> ``localisation_headline`` plus its ``file``."""
    lines = []
    for line in spec.rows:
        row = find_row(rows, line.match)
        if row is None or line.paper is None:
            continue
        worse = [f"{METRIC_LABELS[m]} {row['metrics'][m]['mean']:.3f} (paper {theirs[0]:.3f})"
                 for m, theirs in zip(METRIC_NAMES, line.paper, strict=True)
                 if theirs is not None and m in row["metrics"] and verdict(row["metrics"][m], theirs, m) != "better"]
        if worse:
            curves = _learning_curves(row)
            lines.append(f"- Table {spec.number}, {row_label(line, row)}: " + ", ".join(worse)
                         + f". Learning curves: {curves or '–'}{_localisation(row, localisation)}.")
    return lines
