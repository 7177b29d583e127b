"""Where a Pick skill goes wrong, step by step: what the world offered at each step and how likely the skill was
to PICK there.

Each step of a Pick episode falls in one of ``STEP_CLASSES``, judged from the simulator's state (``mor.sim.rules``,
what PICK would take now): the target within PICK's reach and in view, another object so, the target in view but
beyond reach, or the target out of view. A skill that has learned Pick PICKs in the first class and not in the
others; one that never PICKs (its PICK probability near 0 everywhere), or PICKs as often wherever it is, has not.
The probe plays the skill as the protocol does (``Skill.choose``: one generator per episode).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from mor.eval.stats import paired_difference
from mor.policy.hierarchy import Skill
from mor.sim.rules import Action, pick_candidate, visible

STEP_CLASSES: tuple[str, ...] = ("target in reach", "another object in reach", "target in view beyond reach",
                                 "target out of view")


def step_class(env: gym.Env) -> str:
    """The ``STEP_CLASSES`` entry of a Pick env's current state."""
    base = env.unwrapped
    candidate, goal = pick_candidate(base.state), base.goal_object
    if candidate == goal:
        return STEP_CLASSES[0]
    if candidate >= 0:
        return STEP_CLASSES[1]
    return STEP_CLASSES[2] if visible(base.state, goal) else STEP_CLASSES[3]


def _batch(observation: Any) -> Any:
    """One observation (a vector (D,) or a dict of arrays) as a batch of one."""
    if isinstance(observation, dict):
        return {key: np.asarray(value)[None] for key, value in observation.items()}
    return np.asarray(observation)[None]


def probe_pick(env: gym.Env, skill: Skill, episodes: int, seed: int) -> dict[str, Any]:
    """Play ``episodes`` Pick episodes (reset seeds ``seed``, ``seed`` + 1, ...) of ``skill`` in ``env`` (a Pick
    env with the skill's observation and ``action_masks()``). Returns the success rate, the share of episodes in
    which the target was ever within reach, the median closest approach to the target (m), per step class its
    steps and the mean probability of PICK there, and each episode's success (``outcomes``, 0 or 1)."""
    successes, reached, closest = [], [], []
    pick: dict[str, list[float]] = {name: [] for name in STEP_CLASSES}
    for episode in range(episodes):
        observation, _ = env.reset(seed=seed + episode)
        rng = np.random.default_rng(seed + episode)
        done, ever, nearest, info = False, False, np.inf, {}
        while not done:
            base = env.unwrapped
            nearest = min(nearest, float(np.linalg.norm(base.state.floor_positions[base.goal_object]
                                                        - base.state.agent_pose[:2])))
            name = step_class(env)
            ever |= name == STEP_CLASSES[0]
            probabilities = skill.probabilities(_batch(observation), env.action_masks()[None])[0]
            pick[name].append(float(probabilities[Action.PICK]))
            action = int(skill.choose(probabilities[None], [rng])[0])
            observation, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
        successes.append(bool(info["metrics"]["success"]))
        reached.append(ever)
        closest.append(nearest)
    return {"episodes": episodes, "seed": seed, "success": float(np.mean(successes)),
            "target_ever_in_reach": float(np.mean(reached)), "median_closest_m": float(np.median(closest)),
            "steps": {name: len(values) for name, values in pick.items()},
            "pick_probability": {name: float(np.mean(values)) if values else None for name, values in pick.items()},
            "outcomes": [int(s) for s in successes]}


def against_probe(result: dict[str, Any], other: dict[str, Any], source: str) -> dict[str, Any]:
    """``result``'s success minus ``other``'s (a probe of the same episodes, read from ``source``), per episode:
    {"file", "success" (the other's), "difference": {"mean", "ci95", "verdict"}} (``stats.paired_difference``)."""
    return {"file": source, "success": other["success"],
            "difference": paired_difference(result["outcomes"], other["outcomes"])}
