"""The robot's one door to the policy, evaluation and L-Net layers: a method's trained policies played as the
evaluation plays them, the L-Net's streaming tracker, and the belief they exchange.

Everything the controller takes from ``mor.policy``, ``mor.eval`` and ``mor.lnet`` is imported here and nowhere
else in ``mor.robot``, so that when those modules move, this file alone changes.
"""

from __future__ import annotations


import numpy as np

from mor.errors import ConfigError
from mor.eval.methods import METHODS, LoadedMethod, TrainedPolicies, load_method, method_spec
from mor.eval.protocol import decider, method_inputs, play_records
from mor.lnet.runtime import LNetRunner
from mor.policy.belief import PoseBelief
from mor.policy.hierarchy import SkillPolicy, Slot
from mor.policy.lnet_tracking import LNetBatchTracker
from mor.policy.params import ObservationParams
from mor.sim.arena import Arena
from mor.sim.config import SimConfig

#: The methods a robot can play: those that read a pose belief (the learned decision or the nearest rule).
ROBOT_METHODS: tuple[str, ...] = tuple(name for name, spec in METHODS.items()
                                       if spec.decision in ("learned", "nearest_rule"))


def robot_method(name: str) -> str:
    """``name`` if a robot can play it; ConfigError listing those it can otherwise."""
    method_spec(name)
    if name not in ROBOT_METHODS:
        raise ConfigError(f"--method: {name!r} does not read a pose belief (a pixel baseline or a scripted policy); "
                          f"choose one of {', '.join(ROBOT_METHODS)}")
    return name


def uses_lnet(method: str) -> bool:
    """Whether ``method`` observes through the L-Net (its policies were trained on its estimates)."""
    return method_spec(method).uses_lnet


def truth_belief(agent_pose: np.ndarray, object_positions: np.ndarray) -> PoseBelief:
    """A belief of one robot with zero uncertainty (what the ground truth's variant sees): agent_pose (3,), object_positions (n, 2)."""
    return PoseBelief.from_truth(agent_pose[None], object_positions[None])


def evaluation_success(loaded: LoadedMethod, sim: SimConfig, keys: list[tuple[int, int]], n_envs: int,
                       horizon: int | None) -> dict[tuple[int, int], float]:
    """The evaluation's own play (``mor.eval.protocol.play_records``) of a ``loaded`` method on the Rearrange episodes
    ``keys`` ((seed, episode) pairs): each one's success."""
    records = play_records(loaded, sim, [("rearrange", seed, episode) for seed, episode in keys], n_envs, horizon)
    return {(r["seed"], r["episode"]): float(r["metrics"]["success"]) for r in records}


class LNetTracker:
    """The L-Net's streaming step for one robot: ``observe(image (S, S, 3) uint8, object_classes (n,), held (env
    convention: n for none), previous action (-1 at the start), starting) -> PoseBelief`` (N = 1). arena: keep the
    search belief's looks too (for a policy that reads them, ``HierarchyPolicy.search_arena``)."""

    def __init__(self, runner: LNetRunner, arena: Arena | None = None) -> None:
        self._tracker = LNetBatchTracker(runner, 1, arena)

    def observe(self, image: np.ndarray, object_classes: np.ndarray, held: int, previous_action: int,
                starting: bool) -> PoseBelief:
        observation = {"image": image, "object_classes": np.asarray(object_classes), "held": held}
        return self._tracker.observe([observation], [{}], np.array([previous_action]), np.array([starting]))


class HierarchyPolicy:
    """A method's frozen skills and decision for one robot: the hierarchy's own ``SkillPolicy`` over one slot with
    no environment, so the robot plays exactly as the evaluation does (the decision when due, the pick skill until
    PICK, then the drop skill until DROP, the evaluation's masks and encoding).

    ``act(belief, held, targets)`` -> the next action; ``advance(action, held)`` after the robot executed it.
    held: the held object's index, -1 when none. targets (n, 2) metres.
    """

    def __init__(self, method: str, policies: TrainedPolicies, arena: Arena, n_objects: int,
                 features: ObservationParams) -> None:
        spec = method_spec(method)
        self.method, self.n_objects = method, n_objects
        #: the arena whose search looks the pose source must keep, where the policy reads the search belief
        self.search_arena = arena if spec.variant.search else None
        self._policy = SkillPolicy({"pick": policies.pick, "drop": policies.drop}, method_inputs(spec, features),
                                   "decision", arena)
        self._decide = decider(spec, policies, arena, features)
        self._slot = Slot(None)

    @classmethod
    def of(cls, loaded: LoadedMethod, sim: SimConfig) -> HierarchyPolicy:
        """A ``loaded`` method's committed policies (``mor.eval.methods.load_method``) in ``sim``'s world."""
        return cls(robot_method(loaded.method.name), loaded.policies, Arena.build(sim.arena, sim.arena_size),
                   sim.n_objects, loaded.features)

    def start(self, seed: int) -> None:
        """A new episode: no skill running; the skills' draws from a generator seeded by ``seed`` (as in
        evaluation, where it is the episode's reset seed)."""
        self._slot = Slot(None, active=True, rng=np.random.default_rng(seed))

    def _observe(self, held: int, targets: np.ndarray | None = None) -> None:
        """The slot's observation as the env gives it: held n when nothing is held."""
        self._slot.observation["held"] = held if held >= 0 else self.n_objects
        if targets is not None:
            self._slot.observation["target_positions"] = np.asarray(targets, np.float32)

    def act(self, belief: PoseBelief, held: int, targets: np.ndarray) -> int:
        """The next primitive action for one robot's ``belief`` (N = 1)."""
        self._observe(held, targets)
        self._policy.decide_due([self._slot], belief, self._decide)
        return self._policy.actions([self._slot], belief)[0]

    def advance(self, action: int, held: int) -> None:
        """After the robot executed ``action`` and now holds ``held`` (-1: nothing): the chain moves on."""
        self._observe(held)
        self._policy.advance(self._slot, action)

    @property
    def skill(self) -> str:
        """The running skill (pick, drop; after ``act``, the one that chose its action) or 'decision' when one is
        due."""
        return self._slot.chain.task or "decision"


__all__ = ["ROBOT_METHODS", "HierarchyPolicy", "LNetRunner", "LNetTracker", "LoadedMethod", "PoseBelief",
           "evaluation_success", "load_method", "robot_method", "truth_belief", "uses_lnet"]
