"""The names of the world's tasks and of the policies that play them (no heavy imports: ``mor.config`` reads
them)."""

from __future__ import annotations

from typing import Literal

#: the world's tasks (paper section 3.2): ``MOR/Pick-v0``, ``MOR/Drop-v0``, ``MOR/Rearrange-v0``
WorldTask = Literal["pick", "drop", "rearrange"]
WORLD_TASKS: tuple[WorldTask, ...] = ("pick", "drop", "rearrange")
#: the policies of the hierarchy: the pick and drop skills, and the decision policy
Task = Literal["pick", "drop", "decision"]
TASKS: tuple[Task, ...] = ("pick", "drop", "decision")
#: the world's task each policy plays (the decision policy plays the full rearrangement, one decision at a time)
PLAYS: dict[Task, WorldTask] = dict(zip(TASKS, WORLD_TASKS, strict=True))
#: the policy that plays each of the world's tasks
PLAYED_BY: dict[WorldTask, Task] = {world: policy for policy, world in PLAYS.items()}
#: the rounds of a baseline skill's imitation start, beside its policy (``mor.policy.imitation``)
IMITATION_LOG = "imitation.csv"
