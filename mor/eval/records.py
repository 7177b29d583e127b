"""The per-episode records of an evaluation: one JSON line per episode, each checked against ``EpisodeRecord`` and
sealed with a digest of its content and of what played it (``<name>.played_by.json``), so that an edited or foreign
line is one error naming the file and line, never a wrong table.

A last line cut short by a kill (not JSON, no newline at the end) is dropped: its episode is played again.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from mor.atomic import atomic_output
from mor.errors import ConfigError
from mor.policy.names import WORLD_TASKS, WorldTask
from mor.sim.config import format_validation_error
from mor.sim.rollout import episode_seed

EvalTask = WorldTask  # every world task is scored: Pick and Drop on their own, Rearrange with the whole hierarchy
EVAL_TASKS: tuple[str, ...] = WORLD_TASKS
#: the five metrics of paper Table 1: name -> (the task whose records hold it, its key in their ``metrics``)
METRICS = {"pick_success": ("pick", "success"), "drop_success": ("drop", "success"),
           "rearrange_success": ("rearrange", "success"), "fixed_strict": ("rearrange", "fixed_strict"),
           "energy_remaining": ("rearrange", "energy_remaining")}


class EpisodeRecord(BaseModel):
    """One played episode, as ``mor.eval.protocol.play_records`` yields it, plus its ``digest``."""

    model_config = ConfigDict(extra="forbid", strict=True)

    method: str
    task: EvalTask
    seed: int = Field(ge=0)
    episode: int = Field(ge=0)
    reset_seed: int
    metrics: dict[str, float]
    steps: int = Field(ge=0)
    return_: float = Field(alias="return")
    ending: str | None = None  # mor.eval.failures.ENDINGS; None for the scripted policies and older records
    digest: str

    @model_validator(mode="after")
    def _consistent(self) -> EpisodeRecord:
        missing = [key for task, key in METRICS.values() if task == self.task and key not in self.metrics]
        if missing:
            raise ValueError(f"metrics: a {self.task} record needs {', '.join(missing)}")
        if self.reset_seed != episode_seed(self.seed, self.episode):
            raise ValueError(f"reset_seed: {self.reset_seed} is not the reset seed of seed {self.seed}, "
                             f"episode {self.episode}")
        return self


def played_by_path(records_path: Path) -> Path:
    """Where ``claim_records`` stores what played the records at ``records_path``: ``<name>.played_by.json``."""
    return records_path.with_name(f"{records_path.stem}.played_by.json")


def record_digest(record: dict[str, Any], played_by: Any) -> str:
    """sha256 of the canonical JSON of ``record`` (without its ``digest``) and of ``played_by``."""
    content = {key: value for key, value in record.items() if key != "digest"}
    canonical = json.dumps({"record": content, "played_by": played_by}, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(canonical.encode()).hexdigest()


def seal(record: dict[str, Any], played_by: Any) -> dict[str, Any]:
    """``record`` with its ``digest`` (``record_digest``)."""
    return {**record, "digest": record_digest(record, played_by)}


def claim_records(records_path: Path, played_by: dict[str, Any]) -> None:
    """Record that ``played_by`` plays the episodes of ``records_path``; ConfigError naming both sides if records
    there were played by something else (or by something unrecorded), since resuming would mix the two."""
    sidecar = played_by_path(records_path)
    stated = _stated(records_path)
    if _lines(records_path) and stated != played_by:
        raise ConfigError(f"{records_path}: its records were played by {stated} but this run plays {played_by}; "
                          f"remove it and {sidecar.name} to evaluate anew")
    with atomic_output(sidecar) as partial:
        partial.write_text(json.dumps(played_by, indent=2, sort_keys=True) + "\n")


def read_records(path: Path) -> list[dict[str, Any]]:
    """The per-episode records of ``path``, each checked against ``EpisodeRecord`` and its digest (with what
    ``played_by_path`` says played them); ConfigError naming the file and line for any that is not."""
    lines = _lines(path)
    if not lines:
        return []
    played_by = _stated(path)
    return [_checked(path, number, record, played_by) for number, record in lines]


def _stated(records_path: Path) -> Any:
    """What ``played_by_path`` says played the records at ``records_path`` (None without it); ConfigError naming it
    when it is not JSON."""
    sidecar = played_by_path(records_path)
    if not sidecar.is_file():
        return None
    try:
        return json.loads(sidecar.read_bytes())
    except (json.JSONDecodeError, UnicodeDecodeError):
        raise ConfigError(f"{sidecar}: not JSON; delete it and {records_path.name} to play every episode "
                          f"again") from None


def _lines(path: Path) -> list[tuple[int, Any]]:
    """(line number, parsed JSON) of each line of ``path``, without a last line cut short by a kill; ConfigError
    for any other line that is not JSON."""
    if not path.is_file():
        return []
    text = path.read_bytes().decode(errors="replace")  # a damaged byte fails its line's JSON or digest
    lines = text.splitlines()
    parsed = []
    for number, line in enumerate(lines, start=1):
        try:
            parsed.append((number, json.loads(line)))
        except json.JSONDecodeError as error:
            if number == len(lines) and not text.endswith("\n"):
                break
            raise _bad(path, number, f"not JSON ({error.msg})") from None
    return parsed


def _checked(path: Path, number: int, record: Any, played_by: Any) -> dict[str, Any]:
    try:
        EpisodeRecord.model_validate(record)
    except ValidationError as error:
        first = error.errors()[0]
        if error.error_count() == 1 and first["loc"] == ("digest",) and first["type"] == "missing":
            raise _bad(path, number, "a record without its digest (written before records were sealed)") from None
        raise _bad(path, number, f"not an episode record ({format_validation_error(error, '')})") from None
    if record["digest"] != record_digest(record, played_by):
        raise _bad(path, number, f"the record does not match its digest (edited, or not played by what "
                                 f"{played_by_path(path).name} states)")
    return record


def _bad(path: Path, number: int, what: str) -> ConfigError:
    return ConfigError(f"{path}:{number}: {what}; delete that line to play its episode again, or delete the file "
                       f"and {played_by_path(path).name} to play every episode again")
