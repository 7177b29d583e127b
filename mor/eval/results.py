"""Rows of ``cards/results/results.json``: one per method x setting, identified by ``ROW_KEYS``."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from mor.errors import ConfigError
from mor.eval.methods import (NEAREST_RULE_VARIANTS, RULE_SUFFIX, method_spec, policy_digests, policy_folders,
                              policy_root)
from mor.eval.failures import sum_endings
from mor.eval.paper import LOWER_IS_BETTER
from mor.eval.stats import probability_of_improvement, summarize_runs, verdict
from mor.policy.variants import OURS, VARIANTS
from mor.policy.workspace import Workspace

#: a row's identity; ``episodes`` is None for the protocol's evaluation seeds, "held_out" for others
#: (``mor eval run --seeds``)
ROW_KEYS = ("method", "encoder", "arena", "policy_arena", "n_objects", "episodes")


#: the suffix of a row's name (and of its records') on held-out episodes
HELD_OUT = ".held_out"


def row_name(method: str, training_seed: int = 0, held_out: bool = False) -> str:
    """The name of a row's file and of its records: ``method``, with ``.seed_S`` for a training seed S > 0 and
    ``.held_out`` for held-out evaluation seeds (``mor eval run --seeds``)."""
    return method + (f".seed_{training_seed}" if training_seed else "") + (HELD_OUT if held_out else "")


def is_zero_shot(row: dict[str, Any]) -> bool:
    """A row of ``mor eval run --zero-shot``: policies trained in another arena (the main workspace's) played here."""
    return row["arena"] != row["policy_arena"]


def row_key(row: dict[str, Any]) -> tuple:
    return tuple(row.get(key) for key in ROW_KEYS)


def in_row_order(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """``rows`` in a stable order: by ``row_key``."""
    return sorted(rows, key=lambda row: tuple(str(v) for v in row_key(row)))


def repoint_policy_digests(row: dict[str, Any], renamed: dict[str, str]) -> bool:
    """Replace, in ``row``'s ``played_by.policies``, each policy digest that ``renamed`` maps (old -> new: the same
    weights in a new file format); whether anything changed."""
    policies = (row.get("played_by") or {}).get("policies") or {}
    changed = {task: renamed[digest] for task, digest in policies.items() if digest in renamed}
    policies.update(changed)
    return bool(changed)


def gather_rows(rows_folders: dict[str, Path], profile_name: str, resamples: int = 10_000) -> list[dict[str, Any]]:
    """The rows of profile ``profile_name``, from the row files alone: the ``*.json`` rows in ``rows_folders``
    (workspace name -> its ``cards/results/rows`` folder; each training run's, ``aggregate_runs``), each marked
    with the ``workspace`` it was evaluated in, in ``in_row_order``. A row whose file is gone is gone."""
    found = [{**json.loads(path.read_text()), "workspace": workspace}
             for workspace, folder in rows_folders.items() for path in sorted(folder.glob("*.json"))]
    return in_row_order(aggregate_runs([row for row in found if row.get("profile") == profile_name], resamples))


def stale_row(row: dict[str, Any], workspace: Workspace, lnet_identity: Callable[[Path], str]) -> bool:
    """Whether ``row`` (evaluated in ``workspace``) was played by other policies or through another L-Net than the
    ones committed now: an L-Net row whose ``lnet_version`` is not ``lnet_identity(workspace.lnet_card)`` (a row from
    before rows recorded it counts as stale), or a row whose recorded policy digests differ from its policy files'."""
    if row.get("runs"):
        return any(stale_row({**row, **run, "runs": None}, workspace, lnet_identity) for run in row["runs"])
    method = method_spec(row["method"])
    played_by = row.get("played_by") or {}
    if method.uses_lnet and played_by.get("lnet_version") != lnet_identity(workspace.lnet_card):
        return True
    if not played_by.get("policies"):
        return False
    root = policy_root(workspace, is_zero_shot(row))
    return played_by["policies"] != policy_digests(policy_folders(method, root, row.get("training_seed", 0)))


def aggregate_runs(rows: list[dict[str, Any]], resamples: int = 10_000) -> list[dict[str, Any]]:
    """One row per ``ROW_KEYS`` key: a key with one training run keeps its row (``training_seeds`` [its seed]); a key
    with several (rows of ``mor eval run --training-seed``) becomes one row whose metrics are
    ``mor.eval.stats.summarize_runs`` over the runs' per-episode ``outcomes`` and whose ``runs`` keep each run's
    seed, metrics and what played it. ConfigError when the runs were played on other episodes, or through other
    L-Nets (naming both sides)."""
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for row in rows:
        groups.setdefault(row_key(row), []).append(row)
    aggregated = []
    for group in groups.values():
        group = sorted(group, key=lambda row: row.get("training_seed") or 0)
        if len(group) == 1:
            trained = method_spec(group[0]["method"]).variant is not None  # the scripted methods train nothing
            aggregated.append({**group[0], "training_seeds": [group[0].get("training_seed") or 0] if trained else []})
            continue
        aggregated.append(_aggregate(group, resamples))
    return aggregated


def _aggregate(group: list[dict[str, Any]], resamples: int) -> dict[str, Any]:
    first = group[0]
    name = first["method"]
    for row in group[1:]:
        for field in ("seeds", "episodes_per_seed"):
            if row[field] != first[field]:
                raise ConfigError(f"{name}: its training runs were evaluated on other episodes ({field} "
                                  f"{first[field]} against {row[field]}); re-run mor eval run for every seed")
        versions = ((first.get("played_by") or {}).get("lnet_version"), (row.get("played_by") or {}).get(
            "lnet_version"))
        if versions[0] != versions[1]:
            raise ConfigError(f"{name}: training seed {first['training_seed']} played through L-Net {versions[0]} "
                              f"but seed {row['training_seed']} through {versions[1]}; one row aggregates one "
                              "L-Net's runs: retrain and re-evaluate the stale seed")
    missing = [row["training_seed"] for row in group if not row.get("outcomes")]
    if missing:
        raise ConfigError(f"{name}: the rows of training seeds {missing} hold no per-episode outcomes (evaluated "
                          "before rows kept them); re-run mor eval run --training-seed S for them")
    metrics = {metric: summarize_runs([row["outcomes"][metric] for row in group], resamples)[0]
               for metric in first["metrics"]}
    runs = [{"training_seed": row["training_seed"], "metrics": row["metrics"], "played_by": row.get("played_by"),
             "wall_seconds": row.get("wall_seconds")} for row in group]
    kept = {key: value for key, value in first.items() if key not in ("outcomes", "played_by", "training_seed")}
    return {**kept, "metrics": metrics, "failures": sum_endings([row.get("failures") or {} for row in group]),
            "training_seeds": [row["training_seed"] for row in group], "runs": runs,
            "outcomes_by_run": [row["outcomes"] for row in group]}


def run_outcomes(row: dict[str, Any]) -> list[dict[str, dict[str, list[float]]]]:
    """Each training run's per-episode outcomes of a row ({metric: {evaluation seed: values}} per run)."""
    return row.get("outcomes_by_run") or ([row["outcomes"]] if row.get("outcomes") else [])


#: the pairs a results file compares (a, b): each variant with its uncertainty against its ablation (paper Table 2),
#: ours against each end-to-end baseline (paper Table 1), each variant that reads the stated belief against the one
#: that reads its Gaussian only, and each learned decision against the nearest-unfixed-object rule
COMPARED: tuple[tuple[str, str], ...] = (
    *((variant.ablation_of, name) for name, variant in VARIANTS.items() if variant.ablation_of),
    *((OURS.name, name) for name, variant in VARIANTS.items() if variant.is_baseline),
    *((name, other) for name, variant in VARIANTS.items() if variant.search for other, plain in VARIANTS.items()
      if (plain.source, plain.uncertainty, plain.search) == (variant.source, variant.uncertainty, False)),
    *((name, name + RULE_SUFFIX) for name in NEAREST_RULE_VARIANTS),
)


def comparisons(rows: list[dict[str, Any]], resamples: int = 10_000) -> list[dict[str, Any]]:
    """For each pair of ``COMPARED`` with both protocol rows (not held-out) in the main setting and per-episode
    outcomes, each metric's difference a - b: its mean and a 95% interval (the two rows' ``summarize_runs``
    distributions, drawn independently), the probability of improvement, and the verdict the interval gives:
    ``helps`` (a better: the interval above 0, below 0 for a metric where lower is better), ``hurts`` (the other
    way) or ``no evidence``."""
    main = {row["method"]: row for row in rows if row.get("workspace", ".") == "." and not is_zero_shot(row)
            and row.get("episodes") != "held_out"}
    return [entry for a, b in COMPARED if a in main and b in main and run_outcomes(main[a]) and run_outcomes(main[b])
            for entry in compare(main[a], main[b], resamples)]


def compare(row_a: dict[str, Any], row_b: dict[str, Any], resamples: int = 10_000,
            names: tuple[str, str] | None = None) -> list[dict[str, Any]]:
    """Each metric's difference between two rows with per-episode outcomes (``comparisons``' entries; ``names``:
    what to call a and b, their methods by default)."""
    a, b = names or (row_a["method"], row_b["method"])
    found = []
    for metric in row_a["metrics"]:
        runs_a = [run[metric] for run in run_outcomes(row_a)]
        runs_b = [run[metric] for run in run_outcomes(row_b)]
        summary_a, dist_a = summarize_runs(runs_a, resamples, seed=1)
        summary_b, dist_b = summarize_runs(runs_b, resamples, seed=2)
        low, high = (float(x) for x in np.percentile(dist_a - dist_b, [2.5, 97.5]))
        sign = -1.0 if metric in LOWER_IS_BETTER else 1.0
        found.append({
            "a": a, "b": b, "metric": metric, "training_seeds": {a: row_a.get("training_seeds"),
                                                                 b: row_b.get("training_seeds")},
            "train_steps": {a: row_a.get("train_steps"), b: row_b.get("train_steps")},
            "difference": {"mean": summary_a["mean"] - summary_b["mean"], "ci95": [low, high]},
            "probability_of_improvement": probability_of_improvement(
                *(([np.concatenate(list(run.values())) * sign for run in runs]) for runs in (runs_a, runs_b))),
            "verdict": verdict(low, high, metric in LOWER_IS_BETTER)})
    return found


def method_row(folder: Path, method: str, resamples: int = 10_000) -> dict[str, Any]:
    """``method``'s protocol row from the row files in ``folder`` (``method.json`` and ``method.seed_S.json``,
    aggregated over its training runs), or, where ``method`` ends in ``.held_out``, its row on held-out episodes
    (``row_name``'s ``.held_out`` files); ConfigError naming the folder when it holds none."""
    base = method.removesuffix(HELD_OUT)
    held_out = base != method
    files = [folder / f"{row_name(base, 0, held_out)}.json", *sorted(folder.glob(f"{base}.seed_*.json"))]
    rows = [row for row in (json.loads(path.read_text()) for path in files if path.is_file())
            if (row.get("episodes") == "held_out") == held_out]
    if not rows:
        suffix = HELD_OUT if held_out else ""
        raise ConfigError(f"{folder}: no row of {method!r} ({base}{suffix}.json or {base}.seed_S{suffix}.json); run "
                          f"mor eval run --method {base}{' --seeds ...' if held_out else ''} first")
    return aggregate_runs(rows, resamples)[0]
