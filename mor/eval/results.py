"""Rows of ``cards/results/results.json``: one per method x setting, identified by ``ROW_KEYS``."""

from __future__ import annotations

from typing import Any

ROW_KEYS = ("method", "encoder", "arena", "policy_arena", "n_objects")


def arena_label(arena: str) -> str:
    """The results' name of a simulator arena: the square arena is the paper's rectangular one ("rect")."""
    return "rect" if arena == "square" else arena


def is_zero_shot(row: dict[str, Any]) -> bool:
    """A row of ``mor eval run --zero-shot``: policies trained in another arena (the main workspace's) played here."""
    return row["arena"] != row["policy_arena"]


def row_key(row: dict[str, Any]) -> tuple:
    return tuple(row.get(key) for key in ROW_KEYS)


def merge_rows(existing: list[dict[str, Any]], new: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """``existing`` with each row of ``new`` replacing the row of the same key (or added), in a stable order."""
    merged = {row_key(row): row for row in existing}
    merged.update({row_key(row): row for row in new})
    return sorted(merged.values(), key=lambda row: tuple(str(v) for v in row_key(row)))


def repoint_policy_digests(row: dict[str, Any], renamed: dict[str, str]) -> bool:
    """Replace, in ``row``'s ``played_by.policies``, each policy digest that ``renamed`` maps (old -> new: the same
    weights in a new file format); whether anything changed."""
    policies = (row.get("played_by") or {}).get("policies") or {}
    changed = {task: renamed[digest] for task, digest in policies.items() if digest in renamed}
    policies.update(changed)
    return bool(changed)
