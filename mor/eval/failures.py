"""How each evaluation episode ended, from the simulator's state: the failure taxonomy of the results card.

``EndingDiary`` wraps a MOR task environment (Gymnasium's way to add to ``info``): it watches every step and, when
the episode ends, names its ending in ``info["ending"]`` (``ENDINGS`` lists them per task). The agent never reads
it: the evaluation copies it into the episode's record, and the results rows count the endings.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from mor.policy.hierarchy import SKILL_HORIZON
from mor.sim import metrics
from mor.sim.catalog import object_class
from mor.sim.rules import Action, visible
from mor.sim.tasks import DropEnv, PickEnv, RearrangeEnv

#: every ending of each evaluation task, success first
ENDINGS: dict[str, tuple[str, ...]] = {
    "pick": ("success", "picked another object of the same colour", "picked an object of another colour",
             "PICK with nothing in reach, target never seen", "PICK with nothing in reach, target seen earlier",
             "obstructed", "horizon, target never seen", "horizon, target seen"),
    "drop": ("success", "dropped off target", "DROP blocked", "obstructed", "horizon"),
    "rearrange": ("success", "obstructed", "horizon, a skill never ended", "horizon, a placed object picked again",
                  "horizon, an object dropped off target", "horizon, other"),
}
#: steps after which a skill that has not ended counts as stuck: the longest of the skills' own task horizons
SKILL_HORIZON_STEPS = max(SKILL_HORIZON.values())


class EndingDiary(gym.Wrapper):
    """A MOR Pick, Drop or Rearrange environment whose last ``info`` of an episode holds ``ending``."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        base = env.unwrapped
        self.task = ("pick" if isinstance(base, PickEnv) else "drop" if isinstance(base, DropEnv)
                     else "rearrange" if isinstance(base, RearrangeEnv) else None)
        if self.task is None:
            raise TypeError(f"EndingDiary: {type(base).__name__} is not a MOR task environment")
        self._reset_diary()

    def _reset_diary(self) -> None:
        self.target_seen = False
        self.steps = self.last_event_step = 0
        self.repicked = self.dropped_off = 0

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        observation, info = self.env.reset(**kwargs)
        self._reset_diary()
        self._watch()
        return observation, info

    def step(self, action: int) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        picking = self.task == "rearrange" and int(action) == Action.PICK  # only then can a placed object move
        fixed_before = self._fixed() if picking else None
        observation, reward, terminated, truncated, info = self.env.step(action)
        self.steps += 1
        if info["picked"] >= 0 or info["dropped"] >= 0:
            self.last_event_step = self.steps
        if info["picked"] >= 0 and fixed_before is not None and fixed_before[info["picked"]]:
            self.repicked += 1
        if info["dropped"] >= 0 and not self._fixed()[info["dropped"]]:
            self.dropped_off += 1
        self._watch()
        if terminated or truncated:
            info = {**info, "ending": self._ending(int(action), info, truncated and not terminated)}
        return observation, reward, terminated, truncated, info

    def _fixed(self) -> Any:
        """(n,) bool: each object lies on the floor within the success radius of its target (``metrics.is_fixed``)."""
        base = self.env.unwrapped
        return metrics.is_fixed(base.state.floor_positions, base.layout.target_positions) & base.state.on_floor()

    def _watch(self) -> None:
        """Remember whether the Pick target has been in view (the first-person camera's field of view)."""
        if self.task == "pick":
            self.target_seen |= visible(self.env.unwrapped.state, self.env.unwrapped.goal_object)

    def _ending(self, action: int, info: dict[str, Any], horizon: bool) -> str:
        success = bool(info["metrics"]["success"])
        if success:
            return "success"
        if info["obstructed"]:
            return "obstructed"
        seen = "seen" if self.target_seen else "never seen"
        if self.task == "pick":
            if horizon:
                return f"horizon, target {seen}"
            if info["picked"] >= 0:
                classes = self.env.unwrapped.layout.object_classes
                same = object_class(classes[info["picked"]]).colour == object_class(
                    classes[self.env.unwrapped.goal_object]).colour
                return "picked another object of the same colour" if same else "picked an object of another colour"
            return f"PICK with nothing in reach, target {'seen earlier' if self.target_seen else 'never seen'}"
        if self.task == "drop":
            if horizon:
                return "horizon"
            return "DROP blocked" if info["drop_blocked"] or action != Action.DROP else "dropped off target"
        if self.steps - self.last_event_step >= SKILL_HORIZON_STEPS:
            return "horizon, a skill never ended"
        if self.repicked:
            return "horizon, a placed object picked again"
        return "horizon, an object dropped off target" if self.dropped_off else "horizon, other"


def count_endings(records: list[dict[str, Any]]) -> dict[str, dict[str, int]]:
    """{task: {ending: episodes}} over the records that name their ending (every ending of ``ENDINGS`` listed)."""
    counts = {task: dict.fromkeys(endings, 0) for task, endings in ENDINGS.items()}
    for record in records:
        if record.get("ending") is not None:
            counts[record["task"]][record["ending"]] += 1
    return {task: found for task, found in counts.items() if any(found.values())}


def sum_endings(parts: list[dict[str, dict[str, int]]]) -> dict[str, dict[str, int]]:
    """The endings of several training runs' rows (``count_endings`` each) added up."""
    total: dict[str, dict[str, int]] = {}
    for part in parts:
        for task, found in part.items():
            for ending, count in found.items():
                total.setdefault(task, dict.fromkeys(ENDINGS[task], 0))[ending] += count
    return total
