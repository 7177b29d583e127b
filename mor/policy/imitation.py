"""Behaviour cloning from a scripted expert with DAgger rounds: where a pixel baseline's skill starts before PPO.

PPO from pixels never meets a rewarded PICK often enough to learn it (docs/results.md, "Why Pick from pixels does
not learn"): a PICK with nothing in reach ends the episode unpaid, so PPO drives PICK out first. Here the skill
first imitates an ``Expert`` built on ``mor.sim.oracle.Oracle``, which reads the true state.

- Round 0: the expert drives ``round_steps`` steps of the training envs; every observation the baseline sees is
  labelled with the expert's action.
- Each later round: the policy being cloned drives (sampling its masked distribution) and the expert labels what
  it meets (DAgger, Ross, Gordon and Bagnell, AISTATS 2011), so the labels cover the policy's own mistakes.
- After each round the actor trains on every label so far (kept in one ``LabelBuffer``): the expert action's
  negative log-likelihood under the masked distribution.
- Then the critic: the cloned policy drives one more round, and the value head (the critic's layers only, the
  shared encoder frozen) trains on the discounted returns of its own episodes, so that PPO's first advantages
  measure the policy it starts from rather than the expert's far better returns.

The expert's labels use what the baseline cannot see (where an object out of view lies); ``Expert`` searches as a
pixel policy must before it uses that. The rounds' figures (who drove, its success, the agreement with the expert
before training on the round, the trained head's loss, the wall seconds so far) go to ``imitation.csv``. Same seed, envs and parameters:
the same labels and weights.
"""

from __future__ import annotations

import csv
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from sb3_contrib.common.maskable.policies import MaskableActorCriticPolicy
from sb3_contrib.common.maskable.utils import get_action_masks
from stable_baselines3.common.vec_env import DummyVecEnv
from tqdm import tqdm

from mor.atomic import atomic_output
from mor.policy.params import ImitationParams
from mor.sim.oracle import Oracle
from mor.sim.rules import Action, visible
from mor.sim.tasks import DropEnv, PickEnv

LOG_FIELDS = ("round", "driver", "trains", "steps", "episodes", "success", "agreement", "labels", "action_nll", "value_mse",
              "seconds")


@dataclass
class Labelled:
    """Steps of a round: observations (dict of (T, ...) arrays), the oracle's actions (T,), the action masks (T, A)
    and the discounted return from each step (T,) of the episode that was driven."""

    observations: dict[str, np.ndarray]
    actions: np.ndarray
    masks: np.ndarray
    returns: np.ndarray

    def __len__(self) -> int:
        return len(self.actions)


class LabelBuffer:
    """Every round's labels in arrays allocated once for ``capacity`` steps: ``add`` copies a round in, ``labels``
    is a view of what is filled (no round is copied twice)."""

    def __init__(self, capacity: int) -> None:
        self.capacity, self.filled = capacity, 0
        self.arrays: Labelled | None = None

    def add(self, part: Labelled) -> None:
        """Append ``part`` (raises when the buffer would overflow)."""
        if self.arrays is None:
            def empty(array: np.ndarray) -> np.ndarray:
                return np.empty((self.capacity, *array.shape[1:]), array.dtype)
            self.arrays = Labelled({key: empty(value) for key, value in part.observations.items()},
                                   empty(part.actions), empty(part.masks), empty(part.returns))
        end = self.filled + len(part)
        if end > self.capacity:
            raise ValueError(f"imitation: {end} labels overflow the buffer of {self.capacity}")
        for key, value in part.observations.items():
            self.arrays.observations[key][self.filled:end] = value
        for name in ("actions", "masks", "returns"):
            getattr(self.arrays, name)[self.filled:end] = getattr(part, name)
        self.filled = end

    def labels(self) -> Labelled:
        """The labels added so far (views into the buffer)."""
        if self.arrays is None:
            raise ValueError("imitation: no labels yet")
        return Labelled({key: value[:self.filled] for key, value in self.arrays.observations.items()},
                        self.arrays.actions[:self.filled], self.arrays.masks[:self.filled],
                        self.arrays.returns[:self.filled])


class Expert:
    """The labels' source for one env: ``mor.sim.oracle.Oracle``, which reads the true state. With ``look_first``,
    in Pick it first turns left on the spot until the target is in view, as a policy that sees only its frame must
    search; from then on it is the oracle. With ``search_again`` as well, it turns left again whenever the target
    is out of view later in the episode, since a policy that sees only this frame cannot know where the target went
    (the oracle turns towards it). Either way it searches for at most ``FULL_TURN`` turns in an episode in all: a
    target that a full turn did not show is hidden from here, and the oracle drives. (The oracle alone turns at once
    towards a target out of view, which no frame tells.)"""

    FULL_TURN = 36  # TURN_LEFT steps of 10 degrees

    def __init__(self, env: gym.Env, look_first: bool, search_again: bool = False) -> None:
        base = env.unwrapped
        self.oracle, self.look_first, self.search_again = Oracle(base.arena, base.noise), look_first, search_again
        self.turns, self.seen = 0, False

    def reset(self) -> None:
        """A new episode begins."""
        self.oracle.reset()
        self.turns, self.seen = 0, False

    def act(self, env: gym.Env) -> int:
        """The next action in ``env``'s current state (Pick: towards its goal object; Drop: its target)."""
        base = env.unwrapped
        if isinstance(base, DropEnv):
            return self.oracle.drop(base.state, base.goal_position)
        if not isinstance(base, PickEnv):
            raise TypeError(f"imitation clones Pick or Drop skills, not {type(base).__name__}")
        in_view = visible(base.state, base.goal_object)
        self.seen |= in_view
        if (self.look_first and not in_view and self.turns < self.FULL_TURN
                and (self.search_again or not self.seen)):
            self.turns += 1
            return int(Action.TURN_LEFT)
        return self.oracle.pick(base.state, base.goal_object)


def expert_actions(env: DummyVecEnv, experts: list[Expert]) -> np.ndarray:
    """Each expert's next action in its env of ``env`` (N,)."""
    return np.asarray([expert.act(wrapped) for expert, wrapped in zip(experts, env.envs, strict=True)], np.int64)


def discounted_returns(rewards: np.ndarray, dones: np.ndarray, gamma: float) -> np.ndarray:
    """rewards, dones (T, N) -> (T, N): the discounted sum of the rewards from each step to its episode's end (an
    episode still running at step T is cut there)."""
    returns, following = np.zeros_like(rewards, np.float64), np.zeros(rewards.shape[1])
    for t in range(len(rewards) - 1, -1, -1):
        following = rewards[t] + gamma * following * (1.0 - dones[t])
        returns[t] = following
    return returns


def drive(env: DummyVecEnv, experts: list[Expert], policy: MaskableActorCriticPolicy | None, steps: int,
          gamma: float, seed: int, bar: tqdm) -> tuple[Labelled, dict[str, float]]:
    """About ``steps`` steps of ``env`` (whole vector steps) from a fresh reset seeded by ``seed``, driven by the
    experts (``policy`` None) or by ``policy``; every step labelled with the expert's action. Returns the labels and
    the round's figures: episodes ended, their success rate, and the policy's agreement with the expert (its most
    likely action; NaN when the expert drove)."""
    env.seed(seed)
    observation = env.reset()
    for expert in experts:
        expert.reset()
    frames: dict[str, list[np.ndarray]] = {key: [] for key in observation}
    actions, masks, rewards, dones, agreed = [], [], [], [], []
    successes: list[float] = []
    for _ in range(-(-steps // env.num_envs)):
        mask = get_action_masks(env)
        label = expert_actions(env, experts)
        for key, value in observation.items():
            frames[key].append(value)
        if policy is None:
            action = label
        else:
            with torch.no_grad():
                distribution = policy.get_distribution(policy.obs_to_tensor(observation)[0], action_masks=mask)
                action = distribution.sample().numpy()
                agreed.append(distribution.mode().numpy() == label)
        observation, reward, done, infos = env.step(action)
        for index in np.flatnonzero(done):
            experts[index].reset()
            successes.append(float(infos[index]["metrics"]["success"]))
        actions.append(label), masks.append(mask), rewards.append(reward), dones.append(done)
        bar.update(env.num_envs)
    returns = discounted_returns(np.asarray(rewards), np.asarray(dones, np.float64), gamma)
    labelled = Labelled({key: np.concatenate(value) for key, value in frames.items()}, np.concatenate(actions),
                        np.concatenate(masks), returns.reshape(-1).astype(np.float32))
    figures = {"episodes": len(successes), "success": float(np.mean(successes)) if successes else float("nan"),
               "agreement": float(np.mean(agreed)) if agreed else float("nan")}
    return labelled, figures


def critic_parameters(policy: MaskableActorCriticPolicy) -> list[torch.nn.Parameter]:
    """The layers only the value estimate uses: the critic's MLP and value head (and its own encoder if the policy
    does not share one)."""
    own = [] if policy.share_features_extractor else list(policy.vf_features_extractor.parameters())
    return [*own, *policy.mlp_extractor.value_net.parameters(), *policy.value_net.parameters()]


def fit(policy: MaskableActorCriticPolicy, data: Labelled, settings: ImitationParams, generator: torch.Generator,
        critic: bool = False) -> dict[str, float]:
    """``settings.epochs`` passes over ``data`` in minibatches of ``settings.batch_size`` (Adam,
    ``settings.learning_rate``): the actor (every trainable parameter) on the expert action's negative
    log-likelihood (``action_nll``), or with ``critic`` the ``critic_parameters`` on the value's squared error
    against the returns (``value_mse``); only the trained head runs. That loss's mean over the last epoch."""
    trained = critic_parameters(policy) if critic else [p for p in policy.parameters() if p.requires_grad]
    optimizer = torch.optim.Adam(trained, lr=settings.learning_rate)
    policy.set_training_mode(True)
    losses: list[float] = []
    for _ in range(settings.epochs):
        losses = []
        for batch in torch.randperm(len(data), generator=generator).split(settings.batch_size):
            index = batch.numpy()
            observation, _ = policy.obs_to_tensor({key: value[index] for key, value in data.observations.items()})
            if critic:
                loss = torch.nn.functional.mse_loss(policy.predict_values(observation).flatten(),
                                                    torch.as_tensor(data.returns[index]))
            else:
                distribution = policy.get_distribution(observation, action_masks=data.masks[index])
                loss = -distribution.log_prob(torch.as_tensor(data.actions[index])).mean()
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
            losses.append(loss.item())
    policy.set_training_mode(False)
    return {"value_mse" if critic else "action_nll": round(float(np.mean(losses)), 5)}


def clone_oracle(policy: MaskableActorCriticPolicy, env: DummyVecEnv, settings: ImitationParams, gamma: float,
                 seed: int, log_path: Path, progress: bool = True) -> list[dict[str, Any]]:
    """Train ``policy`` to imitate the ``Expert`` on ``env`` (in-process Pick or Drop envs seen as the policy sees
    them): ``settings.rounds`` rounds for the actor, one for the critic (module docstring); the rounds' rows, also
    written to ``log_path``."""
    experts = [Expert(wrapped, settings.look_first, settings.search_again) for wrapped in env.envs]
    generator = torch.Generator().manual_seed(seed)
    round_seeds = np.random.SeedSequence([seed, 7919]).generate_state(settings.rounds + 1)
    buffer = LabelBuffer(settings.rounds * env.num_envs * -(-settings.round_steps // env.num_envs))
    rows: list[dict[str, Any]] = []
    started = time.monotonic()
    with tqdm(total=(settings.rounds + 1) * settings.round_steps, desc="imitation", unit="step",
              disable=not progress, dynamic_ncols=True) as bar:
        for round_index, round_seed in enumerate(round_seeds):
            critic = round_index == settings.rounds
            driver = None if round_index == 0 else policy
            labelled, figures = drive(env, experts, driver, settings.round_steps, gamma, int(round_seed), bar)
            if not critic:
                buffer.add(labelled)
            data = labelled if critic else buffer.labels()
            losses = fit(policy, data, settings, generator, critic)
            rows.append({"round": round_index, "driver": "expert" if driver is None else "policy",
                         "trains": "critic" if critic else "actor", "steps": len(labelled),
                         **{k: round(v, 4) for k, v in figures.items()}, "labels": len(data), **losses,
                         "seconds": round(time.monotonic() - started, 1)})
            bar.set_postfix(success=f"{figures['success']:.2f}", **{k: f"{v:.3f}" for k, v in losses.items()})
            write_log(log_path, rows)
    return rows


def write_log(path: Path, rows: list[dict[str, Any]]) -> None:
    """The rounds' rows (``LOG_FIELDS``) as CSV, through a temporary name."""
    with atomic_output(path) as partial, partial.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=LOG_FIELDS)
        writer.writeheader()
        writer.writerows(rows)
