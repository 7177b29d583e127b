"""A policy card (``cards/policy/<variant>/README.md``): what the variant's policies were trained with, their
learning curves, and the evaluation rows of the methods built on them beside the paper's numbers."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from mor.policy.variants import VARIANTS
from mor.eval.paper import LOWER_IS_BETTER, METRIC_NAMES
from mor.eval.tables import METRIC_LABELS, paper_reference

_PPO_KEYS = ("steps", "n_envs", "hidden", "n_steps", "batch_size", "n_epochs", "learning_rate", "gamma", "gae_lambda",
             "clip_range", "ent_coef")


def _metric_cell(summary: dict[str, Any]) -> str:
    low, high = summary["ci95"]
    return f"{summary['mean']:.3f} ± {summary['std']:.3f} [{low:.3f}, {high:.3f}]"


def ablation_pair(variant: str) -> tuple[str, str] | None:
    """(the variant with its uncertainty, the one without: ``Variant.ablation_of``) where ``variant`` is either;
    None for the others."""
    return next(((v.ablation_of, v.name) for v in VARIANTS.values() if v.ablation_of
                 and variant in (v.name, v.ablation_of)), None)


def uncertainty_comparison(rows: list[dict[str, Any]], pair: tuple[str, str]) -> list[str]:
    """Table lines comparing the rows of ``pair`` (with, without the uncertainty) metric by metric: which is better
    where their 95% intervals do not overlap, "no difference shown" where they do; [] when either row is missing."""
    found = {row["method"]: row for row in rows if row["method"] in pair}
    if len(found) < 2:
        return []
    lines = []
    for metric in METRIC_NAMES:
        with_, without = (found[name]["metrics"][metric] for name in pair)
        if with_["ci95"][0] > without["ci95"][1] or with_["ci95"][1] < without["ci95"][0]:
            higher = pair[0] if with_["mean"] > without["mean"] else pair[1]
            verdict = f"{higher} higher" + (" (worse)" if metric in LOWER_IS_BETTER else "")
        else:
            verdict = "no difference shown"
        lines.append(f"| {METRIC_LABELS[metric]} | {_metric_cell(with_)} | {_metric_cell(without)} | {verdict} |")
    return lines


def policy_card_markdown(variant: str, summaries: dict[str, dict[str, Any]], rows: list[dict[str, Any]],
                         video: str | None, profile: str, all_rows: list[dict[str, Any]] = ()) -> str:
    """summaries: task -> the training's summary.json; rows: results rows of the methods using this variant;
    all_rows: every results row (for the with/without-uncertainty comparison)."""
    lines = [f"# Policy card: `{variant}`", "",
             f"Profile `{profile}`. The pick and drop sub-policies (sb3-contrib MaskablePPO) and the decision policy "
             "that chains them (paper section 4.2); observation layout and choices in `docs/assumptions.md` "
             "(\"Policies\"). Load them with `mor.eval.methods.load_method`; evaluate with "
             f"`mor eval run --method {variant}`; watch one with `mor sim video --policy {variant}`.", "",
             "## Training", "",
             "| policy | steps | wall time (last run) | steps/s | fine-tuned from (relative to the workspace) | "
             + " | ".join(_PPO_KEYS[1:]) + " |",
             "|" + "---|" * (5 + len(_PPO_KEYS) - 1)]
    for task, summary in summaries.items():
        params = summary["params"]
        warm = f"`{Path(summary['warm_start_from']).parent.as_posix()}`" if summary.get("warm_start_from") else "–"
        rate = summary.get("steps_per_second_this_run") or "–"
        lines.append(f"| {task} | {summary['steps']:,} | {summary['wall_seconds_this_run']:.0f} s | {rate} | {warm} | "
                     + " | ".join(str(params[k]) for k in _PPO_KEYS[1:]) + " |")
    lines += ["", "Learning curves (success rate and return over the last 100 training episodes):", ""]
    lines += [f"![{task}]({task}/learning_curve.png)" for task in summaries
              if summaries[task].get("steps_per_second_this_run")]
    lines += ["", "## Evaluation", ""]
    if not rows:
        lines.append("Not evaluated yet: run `mor eval run --method " + variant + "` then `mor eval results`.")
    for row in rows:
        reference = paper_reference(row)
        run = (f", training run {row.get('training_seed') or 0}"
               + (", held-out evaluation seeds" if row.get("episodes") == "held_out" else ""))
        lines += [f"`{row['method']}`{run}: evaluation seeds {row['seeds']} × {row['episodes_per_seed']} episodes "
                  "per task "
                  "(mean ± std over seeds [95% bootstrap interval]); *paper* = the paper's published number.", "",
                  "| metric | ours | paper |", "|---|---|---|"]
        for metric in METRIC_NAMES:
            theirs = reference.get(metric) if reference else None
            paper_text = f"{theirs[0]:.3f} ± {theirs[1]:.3f}" if theirs else "–"
            lines.append(f"| {METRIC_LABELS[metric]} | {_metric_cell(row['metrics'][metric])} | {paper_text} |")
        lines.append("")
    pair = ablation_pair(variant)
    comparison = uncertainty_comparison(all_rows, pair) if pair else []
    if comparison:
        lines += [f"## Does the uncertainty help? (`{pair[0]}` against `{pair[1]}`, same episodes)", "",
                  f"| metric | {pair[0]} | {pair[1]} | verdict (95% intervals) |", "|---|---|---|---|", *comparison,
                  ""]
    if video:
        lines += ["## An episode", "", f"[{video}]({video}): first-person view (left) and top-down view (right): "
                  "the truth as stars, the policy's belief as 2σ ellipses (zero for a policy on the true poses)."]
    return "\n".join(lines) + "\n"


def write_policy_card(folder: Path, variant: str, summaries: dict[str, dict[str, Any]], rows: list[dict[str, Any]],
                      video: str | None, profile: str, all_rows: list[dict[str, Any]] = ()) -> Path:
    from mor.atomic import atomic_output  # noqa: PLC0415

    with atomic_output(folder / "README.md") as partial:
        partial.write_text(policy_card_markdown(variant, summaries, rows, video, profile, all_rows))
    return folder / "README.md"
