"""Playing many evaluation episodes of a learned method in lockstep: N environments at once, one tracker pass
(one L-Net forward) and one forward per policy per step for all of them.

Each environment plays its episodes from their own reset seeds with deterministic policies, so a record does not
depend on which slot or batch played it (up to floating-point differences of batched inference).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mor.policy.belief import PoseBelief
from mor.policy.envs import make_task_env
from mor.policy.features import Encode
from mor.policy.names import Task
from mor.policy.hierarchy import Skill, SkillChain, skill_mask
from mor.policy.observations import BatchTracker, task_goal
from mor.sim.config import SimConfig

#: (beliefs of k envs, held (k,), targets (k, n, 2), last (k,): the object of each env's previous decision, -1
#: before the first) -> the object each should rearrange next (k,)
Decide = Callable[[PoseBelief, np.ndarray, np.ndarray, np.ndarray], np.ndarray]
EpisodeKey = tuple[Any, ...]


@dataclass
class _Slot:
    env: Any
    key: EpisodeKey | None = None
    observation: dict[str, Any] = field(default_factory=dict)
    info: dict[str, Any] = field(default_factory=dict)
    chain: SkillChain = field(default_factory=SkillChain)
    rng: np.random.Generator = field(default_factory=np.random.default_rng)
    previous: int = -1
    starting: bool = True
    total: float = 0.0
    steps: int = 0


def play_lockstep(
    task: str, keys: list[tuple[EpisodeKey, int]], sim: SimConfig, tracker: BatchTracker, skills: dict[Task, Skill],
    decide: Decide | None, encode: Encode, n_envs: int, **env_kwargs: Any,
) -> Iterator[tuple[EpisodeKey, dict[str, Any]]]:
    """Play ``keys`` ((key, reset seed) pairs) of ``task`` (pick, drop or rearrange) with the skills, fed by
    ``encode`` (and, for rearrange, ``decide``); yield (key, {metrics, steps, return}) as each episode ends. ``tracker`` must keep
    ``min(n_envs, len(keys))`` environments; ``env_kwargs`` go to the environments (e.g. ``horizon``)."""
    queue = list(keys)
    env_task = "decision" if task == "rearrange" else task
    slots = [_Slot(make_task_env(env_task, sim, tracker.needs_frames, **env_kwargs))
             for _ in range(min(n_envs, len(queue)))]
    for slot in slots:
        _start(slot, queue)
    try:
        while any(slot.key is not None for slot in slots):
            belief = tracker.observe([s.observation for s in slots], [s.info for s in slots],
                                     np.array([s.previous for s in slots]), np.array([s.starting for s in slots]))
            active = [i for i, s in enumerate(slots) if s.key is not None]
            if task == "rearrange":
                _decide(slots, [i for i in active if slots[i].chain.task is None], belief, decide)
            actions = _act(slots, active, belief, task, skills, encode)
            for i in active:
                finished = _advance(slots[i], task, actions[i])
                if finished is not None:
                    yield finished
                    _start(slots[i], queue)
    finally:
        for slot in slots:
            slot.env.close()


def _start(slot: _Slot, queue: list[tuple[EpisodeKey, int]]) -> None:
    """Begin the next queued episode in ``slot`` (or leave it idle, replaying its last observation)."""
    slot.starting = True
    if not queue:
        slot.key = None
        return
    slot.key, seed = queue.pop(0)
    slot.observation, slot.info = slot.env.reset(seed=seed)
    slot.rng = np.random.default_rng(seed)  # the skills' draws: the same as HierarchicalRearrange's
    slot.chain, slot.previous, slot.total, slot.steps = SkillChain(), -1, 0.0, 0


def _decide(slots: list[_Slot], due: list[int], belief: PoseBelief, decide: Decide) -> None:
    if not due:
        return
    held = np.array([slots[i].observation["held"] for i in due])
    targets = np.stack([slots[i].observation["target_positions"] for i in due])
    n_objects = targets.shape[1]
    last = np.array([slots[i].chain.index for i in due])
    for i, choice in zip(due, decide(belief.take(np.array(due)), held, targets, last), strict=True):
        slots[i].chain.decide(int(choice), int(slots[i].observation["held"]), n_objects)


def _act(slots: list[_Slot], active: list[int], belief: PoseBelief, task: str, skills: dict[Task, Skill],
         encode: Encode) -> dict[int, int]:
    """Each active slot's next primitive action: one batched forward per skill."""
    actions: dict[int, int] = {}
    for skill_task in ("pick", "drop"):
        group = [i for i in active if (slots[i].chain.task if task == "rearrange" else task) == skill_task]
        if not group:
            continue
        if task == "rearrange":
            goals = np.stack([slots[i].chain.goal(np.asarray(slots[i].observation["target_positions"])) for i in group])
        else:
            goals = np.stack([task_goal(slots[i].observation, skill_task) for i in group])
        inputs = encode(skill_task, [slots[i].observation for i in group], [slots[i].info for i in group],
                        belief.take(np.array(group)), goals, slots[group[0]].env.arena)
        masks = np.stack([skill_mask(skill_task)] * len(group))
        chosen = skills[skill_task].act_batch(inputs, masks, [slots[i].rng for i in group])
        actions.update(zip(group, chosen.tolist(), strict=True))
    return actions


def _advance(slot: _Slot, task: str, action: int) -> tuple[EpisodeKey, dict[str, Any]] | None:
    """Step ``slot``'s env with ``action``; the finished episode's (key, outcome), or None while it runs."""
    slot.observation, reward, terminated, truncated, slot.info = slot.env.step(action)
    slot.previous, slot.starting = action, False
    slot.total, slot.steps = slot.total + float(reward), slot.steps + 1
    if terminated or truncated:
        return slot.key, {"metrics": dict(slot.info["metrics"]), "steps": slot.steps, "return": slot.total}
    if task == "rearrange":
        n_objects = len(slot.observation["object_classes"])
        slot.chain.advance(action, int(slot.observation["held"]), n_objects)
    return None
