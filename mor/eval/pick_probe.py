"""Where a Pick skill goes wrong, step by step: what the world offered at each step and how likely the skill was
to PICK there.

Each step of a Pick episode falls in one of ``STEP_CLASSES``, judged from the simulator's state (``mor.sim.rules``,
what PICK would take now): the target within PICK's reach and in view, another object so, the target in view but
beyond reach, or the target out of view. A skill that has learned Pick PICKs in the first class and not in the
others; one that never PICKs (its PICK probability near 0 everywhere), or PICKs as often wherever it is, has not.
The probe plays the skill as the protocol does (``Skill.choose``: one generator per episode).

Two more views of the failures: what an obstructed MOVE hit (the target, another object, a wall), and, for a skill
that reads a pose belief, how wrong and how honest the belief about the target was while the target was in view, by
how far away it truly was. Under ``FLOOR_IN_SIGHT_M`` the camera's lower edge no longer shows where the target meets
the floor.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from mor.eval.stats import paired_difference
from mor.policy.hierarchy import Skill
from mor.sim.rules import CAMERA_FOV, NO_OBSTACLE, WALL, Action, first_obstacle, pick_candidate, visible
from mor.sim.scene import CAMERA_HEIGHT

STEP_CLASSES: tuple[str, ...] = ("target in reach", "another object in reach", "target in view beyond reach",
                                 "target out of view")


OBSTACLES: tuple[str, ...] = ("the target", "another object", "a wall")
#: metres: the nearest floor point in the first-person camera's view (its height over the tangent of half its
#: vertical field of view, which equals the horizontal one)
FLOOR_IN_SIGHT_M: float = CAMERA_HEIGHT / float(np.tan(CAMERA_FOV / 2.0))
#: edges (m) of the true agent-to-target distances the belief's errors are grouped by; the last bin is open
RANGE_EDGES_M: tuple[float, ...] = (0.0, round(FLOOR_IN_SIGHT_M, 2), 0.7, 1.0, 1.5, 2.5)
#: Mahalanobis distance squared inside which a 2-D Gaussian holds 95% of its mass (chi-square, 2 degrees of freedom)
CHI2_95_2D: float = 5.991
#: metres: a belief without covariance this close to the truth is exact (float32 rounding of positions)
_EXACT_M = 1e-5
#: metres: how far a MOVE is searched for what blocked it (the motion noise's mean + 6 standard deviations)
_MOVE_SEARCH_SIGMAS = 6.0


def step_class(env: gym.Env) -> str:
    """The ``STEP_CLASSES`` entry of a Pick env's current state."""
    base = env.unwrapped
    candidate, goal = pick_candidate(base.state), base.goal_object
    if candidate == goal:
        return STEP_CLASSES[0]
    if candidate >= 0:
        return STEP_CLASSES[1]
    return STEP_CLASSES[2] if visible(base.state, goal) else STEP_CLASSES[3]


def obstacle_class(env: gym.Env) -> str:
    """The ``OBSTACLES`` entry a MOVE straight ahead from a Pick env's current state would hit first (a state whose
    MOVE was just obstructed: something lies within the longest MOVE)."""
    base = env.unwrapped
    hit = first_obstacle(base.state, base.arena, base.noise.move_mean + _MOVE_SEARCH_SIGMAS * base.noise.move_std)
    if hit == NO_OBSTACLE:
        raise RuntimeError("obstacle_class: nothing lies within the longest MOVE ahead; call it after an obstructed MOVE")
    return OBSTACLES[2] if hit == WALL else OBSTACLES[0] if hit == base.goal_object else OBSTACLES[1]


def target_belief_error(env: gym.Env) -> tuple[float, float, float, float, float] | None:
    """Where ``env`` keeps a pose belief (``belief``, e.g. ``PoseObservation``) and the Pick target is in view: (true
    distance, believed minus true distance, position error, the belief's σ along its widest axis, all m; the
    target's Mahalanobis distance squared under the belief's covariance). None otherwise."""
    base, belief = env.unwrapped, getattr(env, "belief", None)
    if belief is None or not visible(base.state, base.goal_object):
        return None
    goal = base.goal_object
    truth, mean = base.state.floor_positions[goal], belief.object_mean[0, goal].astype(np.float64)
    covariance = belief.object_cov[0, goal].astype(np.float64)
    distance = float(np.linalg.norm(truth - base.state.agent_pose[:2]))
    believed = float(np.linalg.norm(mean - belief.agent_mean[0]))
    error = truth - mean
    if np.linalg.det(covariance) > 0:
        mahalanobis = float(error @ np.linalg.solve(covariance, error))
    else:  # no stated uncertainty (the truth's belief): it holds the target where it is exact (to float32's rounding)
        mahalanobis = 0.0 if np.linalg.norm(error) < _EXACT_M else np.inf
    return distance, believed - distance, float(np.linalg.norm(error)), float(np.sqrt(np.linalg.eigvalsh(
        covariance)[-1])), mahalanobis


def belief_by_range(samples: list[tuple[float, float, float, float, float]]) -> list[dict[str, Any]]:
    """``target_belief_error`` samples grouped by ``RANGE_EDGES_M``: per bin its steps, the median signed range
    error, position error and widest σ (m), and the share of steps whose target lay inside the belief's 95%
    ellipse (an honest belief: about 0.95)."""
    rows = np.asarray(samples, np.float64).reshape(-1, 5)
    edges = (*RANGE_EDGES_M, np.inf)
    bins = []
    for low, high in zip(edges[:-1], edges[1:], strict=True):
        inside = rows[(rows[:, 0] >= low) & (rows[:, 0] < high)]
        bins.append({"from_m": low, "to_m": None if np.isinf(high) else high, "steps": len(inside),
                     **({"median_range_error_m": float(np.median(inside[:, 1])),
                         "median_position_error_m": float(np.median(inside[:, 2])),
                         "median_sigma_m": float(np.median(inside[:, 3])),
                         "inside_95_ellipse": float(np.mean(inside[:, 4] <= CHI2_95_2D))} if len(inside) else {})})
    return bins


def _batch(observation: Any) -> Any:
    """One observation (a vector (D,) or a dict of arrays) as a batch of one."""
    if isinstance(observation, dict):
        return {key: np.asarray(value)[None] for key, value in observation.items()}
    return np.asarray(observation)[None]


def probe_pick(env: gym.Env, skill: Skill, episodes: int, seed: int) -> dict[str, Any]:
    """Play ``episodes`` Pick episodes (reset seeds ``seed``, ``seed`` + 1, ...) of ``skill`` in ``env`` (a Pick
    env with the skill's observation and ``action_masks()``). Returns the success rate, the share of episodes in
    which the target was ever within reach, the median closest approach to the target (m), per step class its
    steps and the mean probability of PICK there, each episode's success (``outcomes``, 0 or 1), how many episodes
    an obstructed MOVE ended by what it hit (``obstructed_by``) and, where the env keeps a pose belief, the target
    belief's errors by true distance (``target_belief_by_range``, ``belief_by_range``; empty bins otherwise)."""
    successes, reached, closest = [], [], []
    obstructed_by = dict.fromkeys(OBSTACLES, 0)
    beliefs: list[tuple[float, float, float, float, float]] = []
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
            if (sample := target_belief_error(env)) is not None:
                beliefs.append(sample)
            probabilities = skill.probabilities(_batch(observation), env.action_masks()[None])[0]
            pick[name].append(float(probabilities[Action.PICK]))
            action = int(skill.choose(probabilities[None], [rng])[0])
            observation, _, terminated, truncated, info = env.step(action)
            if info["obstructed"]:  # an obstructed MOVE leaves the world as it was: ask what was ahead now
                obstructed_by[obstacle_class(env)] += 1
            done = terminated or truncated
        successes.append(bool(info["metrics"]["success"]))
        reached.append(ever)
        closest.append(nearest)
    return {"episodes": episodes, "seed": seed, "success": float(np.mean(successes)),
            "target_ever_in_reach": float(np.mean(reached)), "median_closest_m": float(np.median(closest)),
            "steps": {name: len(values) for name, values in pick.items()},
            "pick_probability": {name: float(np.mean(values)) if values else None for name, values in pick.items()},
            "outcomes": [int(s) for s in successes], "obstructed_by": obstructed_by,
            "target_belief_by_range": belief_by_range(beliefs)}


def against_probe(result: dict[str, Any], other: dict[str, Any], source: str) -> dict[str, Any]:
    """``result``'s success minus ``other``'s (a probe of the same episodes, read from ``source``), per episode:
    {"file", "success" (the other's), "difference": {"mean", "ci95", "verdict"}} (``stats.paired_difference``)."""
    return {"file": source, "success": other["success"],
            "difference": paired_difference(result["outcomes"], other["outcomes"])}
