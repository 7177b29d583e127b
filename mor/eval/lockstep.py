"""Playing many evaluation episodes of a learned method in lockstep: N environments at once through the one
hierarchy loop (``mor.policy.hierarchy.SkillHierarchy``), one tracker pass and one forward per policy per step.

Each environment plays its episodes from their own reset seeds, and the skills draw from a generator seeded by the
episode, so a record does not depend on which slot or batch played it (up to floating-point differences of batched
inference).
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

from mor.eval.failures import EndingDiary
from mor.policy.envs import make_task_env
from mor.policy.features import Encode
from mor.policy.hierarchy import Decide, EpisodeKey, Skill, SkillHierarchy
from mor.policy.names import PLAYED_BY, WorldTask
from mor.policy.observations import BatchTracker
from mor.sim.config import SimConfig


def play_lockstep(
    task: WorldTask, keys: list[tuple[EpisodeKey, int]], sim: SimConfig, tracker: BatchTracker, skills: dict[str, Skill],
    decide: Decide | None, encode: Encode, n_envs: int, **env_kwargs: Any,
) -> Iterator[tuple[EpisodeKey, dict[str, Any]]]:
    """Play ``keys`` ((key, reset seed) pairs) of ``task`` (pick, drop or rearrange) with the skills, fed by
    ``encode`` (and, for rearrange, ``decide``); yield (key, {metrics, steps, return, ending}) as each episode ends
    (``ending``: ``mor.eval.failures.EndingDiary``'s).
    ``tracker`` must keep ``min(n_envs, len(keys))`` environments; ``env_kwargs`` go to the environments (e.g.
    ``horizon``)."""
    envs = [EndingDiary(make_task_env(task, sim, tracker.needs_frames, **env_kwargs))
            for _ in range(min(n_envs, len(keys)))]
    try:
        yield from SkillHierarchy(envs, tracker, skills, encode, PLAYED_BY[task]).play(keys, decide)
    finally:
        for env in envs:
            env.close()
