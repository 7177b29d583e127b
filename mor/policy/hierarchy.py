"""The hierarchy of paper section 4.2: frozen pick and drop skills chained by a decision policy (a semi-MDP).

One decision = "rearrange object i next": the pick skill runs with goal i until it takes PICK (or its 150-step
horizon runs out), then, if the agent holds an object, the drop skill runs towards that object's target until
it takes DROP. When the agent already holds an object at a decision (a blocked drop), only the drop skill runs.
The decision's reward is the sum of the full task's rewards (Eq. 2) over its primitive steps; the episode
ends as the full task does (all placed, an obstruction, or 1,000 primitive steps). docs/assumptions.md,
"Policies", says why.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from gymnasium import spaces

from mor.policy.belief import PoseBelief
from mor.policy.features import Encode, ObservationLayout, observation_vector, pose_inputs
from mor.policy.names import Task
from mor.policy.observations import BatchTracker, observation_space, task_goal
from mor.policy.pick_gate import PickGate
from mor.sim.arena import Arena
from mor.sim.metrics import is_fixed
from mor.sim.rules import N_ACTIONS, Action
from mor.sim.tasks import DropEnv, PickEnv, RearrangeEnv

#: primitive steps a skill runs at most within the full task: its own task's horizon (150 in the paper)
SKILL_HORIZON: dict[str, int] = {"pick": PickEnv.default_horizon, "drop": DropEnv.default_horizon}


def skill_mask(task: Task) -> np.ndarray:
    """(5,) bool: the actions a skill may take; the same action the Pick/Drop env removes is masked."""
    removed = {"pick": PickEnv.removed_action, "drop": DropEnv.removed_action}[task]
    mask = np.ones(N_ACTIONS, dtype=bool)
    mask[removed] = False
    return mask


POLICY_FILE = "policy.pth"  # a trained policy for inference: ``mor.policy.policy_file`` (weights + architecture)


class Skill:
    """A frozen policy from sb3-contrib's MaskablePPO (a trained ``MaskablePPO`` or its
    ``MaskableActorCriticPolicy``): ``act(vector (D,), mask (A,), rng) -> action``; ``gate``: a Pick skill's PICK
    gate (``mor.policy.pick_gate``), applied to every mask it is given.

    deterministic: the most likely allowed action; otherwise an action drawn from the policy's distribution with
    the caller's generator (one per episode, seeded by the episode: the draws do not depend on batching).
    """

    def __init__(self, model: Any, deterministic: bool = True, gate: PickGate | None = None) -> None:
        self.policy = getattr(model, "policy", model)
        self.deterministic = deterministic
        self.gate = gate

    @classmethod
    def load(cls, path: Path, deterministic: bool = True) -> Skill:
        """The policy saved at ``path`` (a ``policy.pth``), loaded without unpickling (``mor.policy.policy_file``),
        with the PICK gate its signature (``meta.json`` beside it) records, if any."""
        from mor.policy.policy_file import load_policy_file  # noqa: PLC0415 - SB3 only where a policy is loaded

        return cls(load_policy_file(path), deterministic, PickGate.recorded(path.parent / "meta.json"))

    def act(self, vector: np.ndarray, mask: np.ndarray, rng: np.random.Generator | None = None) -> int:
        """vector (D,), mask (A,) -> one action."""
        return int(self.act_batch(vector[None], mask[None], None if rng is None else [rng])[0])

    def probabilities(self, vectors: np.ndarray, masks: np.ndarray) -> np.ndarray:
        """vectors (k, D) (or a dict of (k, ...) arrays), masks (k, A) bool -> (k, A) float64 the policy's action
        probabilities (0 where masked; PICK also where the skill's gate forbids it): one forward pass."""
        if self.gate is not None:
            masks = self.gate.mask(vectors, masks)
        observations, _ = self.policy.obs_to_tensor(vectors)
        with torch.no_grad():
            distribution = self.policy.get_distribution(observations, action_masks=masks)
        return distribution.distribution.probs.cpu().numpy().astype(np.float64)

    def act_batch(self, vectors: np.ndarray, masks: np.ndarray, rngs: list[np.random.Generator] | None = None
                  ) -> np.ndarray:
        """vectors (k, D) (or a dict of (k, ...) arrays), masks (k, A) bool -> actions (k,): one forward pass."""
        return self.choose(self.probabilities(vectors, masks), rngs)

    def choose(self, probabilities: np.ndarray, rngs: list[np.random.Generator] | None = None) -> np.ndarray:
        """(k, A) action probabilities (``probabilities``) -> actions (k,), as ``act_batch`` acts on them."""
        if self.deterministic or rngs is None:
            return probabilities.argmax(-1)
        return np.array([rng.choice(len(p), p=p / p.sum()) for p, rng in zip(probabilities, rngs, strict=True)])


def decision_mask(object_means: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """(..., n) bool: the objects a decision may choose, those not believed (by their means) to lie at their
    targets already (the success rule of ``mor.sim.metrics``); every object when all are believed placed."""
    mask = ~is_fixed(object_means, targets)
    return np.where(mask.any(-1, keepdims=True), mask, True)


def nearest_unfixed(belief: PoseBelief, targets: np.ndarray) -> int:
    """The rule-based decision: of the objects ``decision_mask`` allows, the nearest to the agent (means)."""
    objects = belief.object_mean[0]
    distances = np.linalg.norm(objects - belief.agent_mean[0], axis=-1)
    return int(np.argmin(np.where(decision_mask(objects, targets), distances, np.inf)))


@dataclass
class SkillChain:
    """One environment's place in the hierarchy: which skill runs (``task``; None: a decision is due), on which
    object (``index``: pick's goal object, or drop's held object whose target it drives to), for how many steps."""

    task: Task | None = None
    index: int = -1
    steps: int = 0

    def decide(self, choice: int, held: int, n_objects: int) -> None:
        """Start decision ``choice``: pick that object, or, when one is already held, drop it."""
        self.task, self.index, self.steps = ("drop", held, 0) if held < n_objects else ("pick", choice, 0)

    def goal(self, targets: np.ndarray) -> np.ndarray:
        """The running skill's goal as its observation layout wants it: pick () index, drop (2,) position."""
        return np.asarray(self.index) if self.task == "pick" else targets[self.index]

    def advance(self, action: int, held: int, n_objects: int) -> bool:
        """After the skill took ``action`` (and the env stepped): move on; True when the decision is over."""
        self.steps += 1
        if self.task == "pick" and (action == Action.PICK or self.steps >= SKILL_HORIZON["pick"]):
            if held < n_objects:
                self.task, self.index, self.steps = "drop", held, 0
                return False
            self.task = None
        elif self.task == "drop" and (action == Action.DROP or self.steps >= SKILL_HORIZON["drop"]):
            self.task = None
        return self.task is None


#: (beliefs of k envs, held (k,), targets (k, n, 2), last (k,): the object of each env's previous decision, -1
#: before the first) -> the object each should rearrange next (k,)
Decide = Callable[[PoseBelief, np.ndarray, np.ndarray, np.ndarray], np.ndarray]
EpisodeKey = Any  # what names an episode for the caller of ``SkillHierarchy.play`` (the protocol's (task, seed, e))


@dataclass
class Slot:
    """One environment of a ``SkillHierarchy`` (or one robot: no env): its latest observation and info, its place
    in the skill chain, the generator of its skills' draws (seeded by the episode), and its episode so far."""

    env: gym.Env | None
    key: EpisodeKey = None
    active: bool = False
    observation: dict[str, Any] = field(default_factory=dict)
    info: dict[str, Any] = field(default_factory=dict)
    chain: SkillChain = field(default_factory=SkillChain)
    rng: np.random.Generator = field(default_factory=np.random.default_rng)
    previous: int = -1  # the last primitive action; -1 at an episode's first observation
    starting: bool = True
    reward: float = 0.0  # of the last primitive step
    total: float = 0.0
    steps: int = 0
    terminated: bool = False  # at the last step
    truncated: bool = False

    @property
    def done(self) -> bool:
        """The episode ended at the last step."""
        return self.terminated or self.truncated

    @property
    def held(self) -> int:
        """The held object's index, n when none (the env's convention)."""
        return int(self.observation["held"])

    @property
    def targets(self) -> np.ndarray:
        """(n, 2) every object's target position, metres (the full task's goal)."""
        return np.asarray(self.observation["target_positions"])

    def outcome(self) -> dict[str, Any]:
        """The finished episode: the task's metrics, its primitive steps and return, and how it ended where the
        environment says (``info["ending"]``, e.g. ``mor.eval.failures.EndingDiary``)."""
        return {"metrics": dict(self.info["metrics"]), "steps": self.steps, "return": self.total,
                **({"ending": self.info["ending"]} if "ending" in self.info else {})}


class SkillPolicy:
    """The policy half of the hierarchy over N slots, with no environment in it: the decisions that are due, then
    each active slot's next action (one batched forward per skill), then each slot's chain moved on.
    ``SkillHierarchy`` runs it over simulated environments, the robot controller (``mor.robot.policy``) on a robot.

    task ``decision``: the full task; a decision starts a slot's skill chain, which runs the pick skill, then the
    drop skill (``SkillChain``). ``pick`` / ``drop``: that skill alone on its own task, with the goal the task
    gives. ``encode`` turns k slots into the skills' batched input (the pose layout's vectors, or a baseline's
    pixels). A slot's draws come from its own generator, so what it plays does not depend on the slot or the batch.
    """

    def __init__(self, skills: dict[str, Skill], encode: Encode, task: Task, arena: Arena) -> None:
        self.skills, self.encode, self.task, self.arena = skills, encode, task, arena

    def due(self, slots: list[Slot]) -> list[int]:
        """The active slots of the full task whose next decision is due."""
        return [i for i, s in enumerate(slots) if s.active and self.task == "decision" and s.chain.task is None]

    @staticmethod
    def decide(slot: Slot, choice: int) -> None:
        """Start decision ``choice`` (an object index) in ``slot``."""
        slot.chain.decide(int(choice), slot.held, len(slot.targets))

    def decide_due(self, slots: list[Slot], belief: PoseBelief, decide: Decide) -> None:
        """Every due decision, by ``decide`` for those slots at once."""
        due = self.due(slots)
        if due:
            chosen = [slots[i] for i in due]
            choices = decide(belief.take(np.array(due)), np.array([s.held for s in chosen]),
                             np.stack([s.targets for s in chosen]), np.array([s.chain.index for s in chosen]))
            for slot, choice in zip(chosen, choices, strict=True):
                self.decide(slot, choice)

    def actions(self, slots: list[Slot], belief: PoseBelief) -> dict[int, int]:
        """Each active slot's next primitive action (its skill running): one batched forward per skill."""
        actions: dict[int, int] = {}
        for skill in ("pick", "drop"):
            group = [i for i, s in enumerate(slots)
                     if s.active and (s.chain.task if self.task == "decision" else self.task) == skill]
            if not group:
                continue
            chosen = [slots[i] for i in group]
            inputs = self.encode(skill, [s.observation for s in chosen], [s.info for s in chosen],
                                 belief.take(np.array(group)), np.stack([self._goal(s, skill) for s in chosen]),
                                 self.arena)
            masks = np.stack([skill_mask(skill)] * len(group))
            picked = self.skills[skill].act_batch(inputs, masks, [s.rng for s in chosen])
            actions.update(zip(group, (int(a) for a in picked), strict=True))
        return actions

    def advance(self, slot: Slot, action: int) -> None:
        """After ``slot`` took ``action`` (its observation now the next one): its chain moves on."""
        if self.task == "decision":
            slot.chain.advance(action, slot.held, len(slot.targets))

    def _goal(self, slot: Slot, skill: str) -> np.ndarray:
        return slot.chain.goal(slot.targets) if self.task == "decision" else task_goal(slot.observation, skill)


class SkillHierarchy:
    """The one loop of the skill hierarchy (paper section 4.2), a ``SkillPolicy`` over N environments in lockstep:
    one tracker pass (one L-Net forward) and one batched forward per skill per primitive step.

    Evaluation and the policy video ``play`` episodes through it; training's decision env
    (``HierarchicalRearrange``) drives one slot with ``start``/``observe``/``decide``/``step``.
    """

    def __init__(self, envs: list[gym.Env], tracker: BatchTracker, skills: dict[str, Skill], encode: Encode,
                 task: Task) -> None:
        self.slots = [Slot(env) for env in envs]
        self.tracker = tracker
        self.policy = SkillPolicy(skills, encode, task, envs[0].unwrapped.arena)
        self.belief: PoseBelief | None = None

    @property
    def arena(self) -> Arena:
        return self.policy.arena

    def start(self, i: int, seed: int | None, key: EpisodeKey = None, options: dict[str, Any] | None = None) -> None:
        """Begin an episode in slot ``i`` (reset seed ``seed``; None continues the env's and the draws' generators)."""
        slot = self.slots[i]
        slot.observation, slot.info = slot.env.reset(seed=seed, options=options)
        if seed is not None:
            slot.rng = np.random.default_rng(seed)
        slot.key, slot.active, slot.starting, slot.terminated, slot.truncated = key, True, True, False, False
        slot.chain, slot.previous, slot.reward, slot.total, slot.steps = SkillChain(), -1, 0.0, 0.0, 0

    def stop(self, i: int) -> None:
        """Leave slot ``i`` idle (the tracker sees its last observation again, as an episode's first)."""
        self.slots[i].active, self.slots[i].starting = False, True

    def observe(self) -> PoseBelief:
        """The tracker's beliefs of all N slots after their latest step (or reset)."""
        slots = self.slots
        self.belief = self.tracker.observe([s.observation for s in slots], [s.info for s in slots],
                                           np.array([s.previous for s in slots]), np.array([s.starting for s in slots]))
        return self.belief

    def decide(self, i: int, choice: int) -> None:
        """Start decision ``choice`` (an object index) in slot ``i``."""
        self.policy.decide(self.slots[i], choice)

    def step(self) -> list[int]:
        """One primitive step of every active slot (each with its skill running): the slots whose episode ended."""
        ended = []
        for i, action in self.policy.actions(self.slots, self.belief).items():
            slot = self.slots[i]
            slot.observation, reward, terminated, truncated, slot.info = slot.env.step(action)
            slot.previous, slot.starting = action, False
            slot.reward, slot.total, slot.steps = float(reward), slot.total + float(reward), slot.steps + 1
            slot.terminated, slot.truncated = bool(terminated), bool(truncated)
            if slot.done:
                ended.append(i)
            else:
                self.policy.advance(slot, action)
        return ended

    def play(self, episodes: list[tuple[EpisodeKey, int]], decide: Decide | None,
             on_step: Callable[[SkillHierarchy], None] | None = None) -> Iterator[tuple[EpisodeKey, dict[str, Any]]]:
        """Play ``episodes`` ((key, reset seed) pairs) over the slots, each slot taking the next queued episode
        when its own ends; yield (key, ``Slot.outcome``) as each ends. ``decide`` chooses the full task's objects;
        ``on_step`` sees the hierarchy after every observation (e.g. a video recorder)."""
        queue = list(episodes)
        for i in range(len(self.slots)):
            self._next(i, queue)
        while any(s.active for s in self.slots):
            belief = self.observe()
            if on_step is not None:
                on_step(self)
            self.policy.decide_due(self.slots, belief, decide)
            for i in self.step():
                yield self.slots[i].key, self.slots[i].outcome()
                self._next(i, queue)

    def _next(self, i: int, queue: list[tuple[EpisodeKey, int]]) -> None:
        if queue:
            key, seed = queue.pop(0)
            self.start(i, seed, key)
        else:
            self.stop(i)


class HierarchicalRearrange(gym.Env):
    """The decision policy's environment: ``MOR/Rearrange-v0`` seen one decision at a time, a ``SkillHierarchy`` of
    one slot.

    observation_space: Box (D,) the ``decision`` layout of ``mor.policy.features``; action_space: Discrete(n),
    the object to rearrange next. ``info`` carries the full task's ``metrics`` at the end and
    ``primitive_steps``, the environment steps this decision took. ``tracker``: a tracker of one environment.
    ``layout``: the decision's observation layout; ``encode``: what the skills read (default: the pose policies'
    ``pose_inputs`` in ``layout``; a baseline's ``mor.policy.baselines.baseline_inputs``).
    """

    metadata = {"render_modes": []}

    def __init__(self, env: gym.Env, tracker: BatchTracker, pick: Skill, drop: Skill,
                 layout: ObservationLayout, encode: Encode | None = None) -> None:
        if not isinstance(env.unwrapped, RearrangeEnv):
            raise TypeError(f"HierarchicalRearrange needs MOR/Rearrange-v0, got {type(env.unwrapped).__name__}")
        self.env, self.layout = env, layout
        self.hierarchy = SkillHierarchy([env], tracker, {"pick": pick, "drop": drop}, encode or pose_inputs(layout),
                                        "decision")
        self.slot = self.hierarchy.slots[0]
        self.n_objects = env.unwrapped.config.n_objects
        self.observation_space = observation_space("decision", self.n_objects, layout)
        self.action_space = spaces.Discrete(self.n_objects)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        self.hierarchy.start(0, seed, options=options)
        self.hierarchy.observe()
        return self._decision_vector(), self.slot.info

    def step(self, action: int) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if isinstance(action, bool | np.bool_) or not self.action_space.contains(action):
            raise ValueError(f"decision {action!r} is not an object index in [0, {self.n_objects})")
        self.hierarchy.decide(0, int(action))
        total, steps = 0.0, 0
        while True:
            self.hierarchy.step()
            self.hierarchy.observe()
            total, steps = total + self.slot.reward, steps + 1
            if self.slot.done or self.slot.chain.task is None:
                info = {**self.slot.info, "primitive_steps": steps}
                return self._decision_vector(), total, self.slot.terminated, self.slot.truncated, info

    def action_masks(self) -> np.ndarray:
        """(n,) bool: ``decision_mask`` of the current belief (objects believed placed are not chosen again)."""
        return decision_mask(self.belief.object_mean[0], self.slot.targets)

    def close(self) -> None:
        self.env.close()

    @property
    def belief(self) -> PoseBelief:
        """The tracker's belief after the latest primitive step (batch 1)."""
        return self.hierarchy.belief

    def _decision_vector(self) -> np.ndarray:
        return observation_vector(self.belief, np.array([self.slot.held]), "decision", self.slot.targets[None],
                                  self.layout, self.hierarchy.arena)[0]
