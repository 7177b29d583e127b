"""The random-action scheme of data collection: a persistent random walk with picks and drops.

A uniform random walk over MOVE/TURN barely leaves its start (its displacement grows like sqrt(steps), and turns
undo each other). Instead the walker alternates *runs* (a geometric number of MOVEs straight ahead) with *turns*
(a uniform number of 10-degree turns in one direction), which covers the arena (see the card's coverage map).
With probability ``approach_probability`` a new run instead heads for the nearest object, so that objects get
picked up often enough.
It picks up a pickable object with probability ``pick_probability`` per step, and drops what it holds with
probability ``drop_probability`` per step once it has carried it ``min_carry_steps``, so the data shows objects
that move. It reads ground truth (``info``) only to choose actions, never to change what is recorded; a MOVE that
would be obstructed becomes a turn, so episodes rarely end early.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from pydantic import Field

from mor.params_model import ParamsModel
from mor.sim.arena import Arena
from mor.sim.geometry import bearing
from mor.sim.rules import Action, MotionNoise, WorldState, drop_free, drop_point, move_obstructed, pick_candidate


class ExplorationParams(ParamsModel):
    """Knobs of the random walk (steps are actions)."""

    mean_run_steps: float = Field(10.0, ge=1.0, description="mean MOVEs per run (geometric)")
    max_turn_steps: int = Field(9, ge=1, le=36, description="turns between runs ~ U{1..max} (9: at most 90 deg)")
    pick_probability: float = Field(0.5, ge=0.0, le=1.0, description="P(PICK) per step when one is possible")
    drop_probability: float = Field(0.08, ge=0.0, le=1.0, description="P(DROP) per step while carrying")
    min_carry_steps: int = Field(5, ge=0, description="steps to carry before a DROP")
    approach_probability: float = Field(
        0.4, ge=0.0, le=1.0, description="P(a new run heads for the nearest object) when holding nothing")


class ExplorationPolicy:
    """``policy(observation, info) -> action``; seeded, one instance per episode."""

    def __init__(self, arena: Arena, params: ExplorationParams, seed: int, noise: MotionNoise | None = None) -> None:
        self.arena, self.params = arena, params
        self.noise = noise or MotionNoise()
        self.rng = np.random.default_rng([seed, 7])
        self._run = self._turn = self._carried = 0
        self._turn_action = Action.TURN_LEFT

    def _start_turn(self) -> None:
        self._turn = int(self.rng.integers(1, self.params.max_turn_steps + 1))
        self._turn_action = Action.TURN_LEFT if self.rng.random() < 0.5 else Action.TURN_RIGHT

    def _start_segment(self, state: WorldState) -> None:
        """A random turn then a random run; or, sometimes, a turn and a run towards the nearest object."""
        floor = state.floor_positions[state.on_floor()]
        if state.held < 0 and len(floor) and self.rng.random() < self.params.approach_probability:
            distances = np.linalg.norm(floor - state.agent_pose[:2], axis=1)
            target = floor[int(np.argmin(distances))]
            angle = bearing(state.agent_pose, target)
            self._turn = int(round(abs(angle) / self.noise.turn_mean))
            self._turn_action = Action.TURN_LEFT if angle > 0 else Action.TURN_RIGHT
            self._run = max(1, int(np.min(distances) / self.noise.move_mean) - 4)
            return
        self._start_turn()
        self._run = int(self.rng.geometric(1.0 / self.params.mean_run_steps))

    def __call__(self, observation: dict[str, Any], info: dict[str, Any]) -> int:
        state = WorldState(np.asarray(info["agent_pose"], float), np.asarray(info["object_positions"], float),
                           int(info["held"]))
        if state.held < 0 and pick_candidate(state) >= 0 and self.rng.random() < self.params.pick_probability:
            self._carried = 0
            return int(Action.PICK)
        if state.held >= 0:
            self._carried += 1
            if (self._carried >= self.params.min_carry_steps and self.rng.random() < self.params.drop_probability
                    and drop_free(state, self.arena, drop_point(state.agent_pose))):
                return int(Action.DROP)
        if self._turn == 0 and self._run == 0:
            self._start_segment(state)
        if self._turn > 0:
            self._turn -= 1
            return int(self._turn_action)
        if move_obstructed(state, self.arena, self.noise.move_mean + 3.0 * self.noise.move_std):
            self._run = 0
            self._start_turn()
            self._turn -= 1
            return int(self._turn_action)
        self._run -= 1
        return int(Action.MOVE)
