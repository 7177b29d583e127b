"""The Gymnasium environment shared by the three MOR tasks.

Contract (every task):
- ``action_space``: Discrete(5), see ``mor.sim.rules.Action``. The action a subtask removes is masked:
  ``action_masks()`` (what sb3-contrib's MaskablePPO reads) marks it False, and taking it anyway is a no-op
  step with ``info["masked_action"] = True``.
- ``observation_space``: a Dict with ``image`` (H, W, 3) uint8, ``object_classes`` (n,) class ids,
  ``held`` (index of the held object, n when none) and the task's own goal keys. Never a ground-truth pose.
  With ``render_frames=False`` there is no ``image`` key and nothing is rendered (no MuJoCo scene is built):
  the fast path for policies that read poses, not pixels.
- ``info`` (what the agent must not see): ``agent_pose`` (3,) [x m, y m, theta rad], ``object_positions`` (n, 2) m
  (the held object at the agent), ``held`` (-1 when none), ``target_positions`` (n, 2) m, ``object_classes`` (n,),
  the step's events (``obstructed``, ``picked``, ``dropped``, ``drop_blocked``, ``masked_action``), and on the
  last step ``metrics``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.error import ResetNeeded

from mor.errors import ConfigError
from mor.sim.arena import Arena
from mor.sim.catalog import N_CLASSES
from mor.sim.config import SimConfig, make_sim_config
from mor.sim.episode import EpisodeLayout, sample_layout
from mor.sim.rules import N_ACTIONS, Action, Events, MotionNoise, WorldState, apply_action
from mor.sim.scene import Scene

Observation = dict[str, np.ndarray | int]
#: The keys ``reset(options=...)`` accepts (none yet: the layout comes from the seed and the env's parameters).
RESET_OPTIONS: frozenset[str] = frozenset()


def _check_reset_options(options: Any) -> None:
    """Raise ConfigError unless ``options`` is None or a dict of keys in ``RESET_OPTIONS``."""
    if options is None:
        return
    if not isinstance(options, dict):
        raise ConfigError(f"reset(options=...): expected a dict or None, got {type(options).__name__}")
    unknown = sorted(map(str, set(options) - RESET_OPTIONS))
    if unknown:
        accepted = ", ".join(sorted(RESET_OPTIONS)) or "none"
        raise ConfigError(f"reset(options=...): unknown option(s) {', '.join(unknown)}; accepted: {accepted} "
                          "(scene parameters such as n_objects are set when the env is made)")


@dataclass(frozen=True)
class StepOutcome:
    """A task's verdict on one step."""

    reward: float
    terminated: bool
    success: bool


class MOREnv(gym.Env[Observation, int]):
    """Base class of ``MOR/Pick-v0``, ``MOR/Drop-v0`` and ``MOR/Rearrange-v0``; see the module docstring."""

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": 8}
    default_horizon: ClassVar[int]
    removed_action: ClassVar[Action | None] = None

    def __init__(
        self, render_mode: str | None = None, horizon: int | None = None, render_frames: bool = True, **sim_params: Any
    ) -> None:
        """sim_params: the fields of ``SimConfig`` (n_objects, image_size, arena, arena_size, texture_pool, landmark,
        rewards: a ``RewardParams`` or a dict of its fields, e.g. ``rewards={"success": 5.0}``).
        render_frames: False leaves ``image`` out of the observation and never builds the MuJoCo scene."""
        self.config: SimConfig = make_sim_config(where=type(self).__name__, **sim_params)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode: {render_mode!r} is not supported; use 'rgb_array' or None")
        self.render_mode = render_mode
        self.render_frames = bool(render_frames)
        if horizon is not None and int(horizon) < 1:
            raise ConfigError(f"horizon: must be at least 1 step (got {horizon!r})")
        self.horizon = int(horizon) if horizon is not None else self.default_horizon
        self.arena = Arena.build(self.config.arena, self.config.arena_size)
        self.noise = MotionNoise()
        # Fail at construction, not at the first reset, when the objects cannot fit.
        sample_layout(np.random.default_rng(0), self.arena, self.config.n_objects, self.config.texture_pool)
        n, size, half = self.config.n_objects, self.config.image_size, self.arena.half_extent
        self.action_space = spaces.Discrete(N_ACTIONS)
        self.observation_space = spaces.Dict(
            {
                **({"image": spaces.Box(0, 255, (size, size, 3), np.uint8)} if self.render_frames else {}),
                "object_classes": spaces.MultiDiscrete(np.full(n, N_CLASSES)),
                "held": spaces.Discrete(n + 1),
                **self._goal_spaces(n, half),
            }
        )
        self._scene: Scene | None = None
        self.layout: EpisodeLayout | None = None
        self.state: WorldState | None = None
        self.steps = 0
        self._ended = False

    # ---- what each task defines ------------------------------------------------------------------------------
    def _goal_spaces(self, n: int, half_extent: float) -> dict[str, spaces.Space]:
        raise NotImplementedError

    def _goal_observation(self) -> dict[str, np.ndarray | int]:
        raise NotImplementedError

    def _begin_task(self) -> None:
        """Adjust ``self.state`` and choose the goal after the layout is drawn (uses ``self.np_random``)."""

    def _landmarks(self) -> list[tuple[np.ndarray, int]]:
        """(target position, class id) of each landmark to show when ``landmark=True``."""
        return []

    def _outcome(self, before: WorldState, events: Events) -> StepOutcome:
        raise NotImplementedError

    def _metrics(self, outcome: StepOutcome) -> dict[str, float]:
        return {"success": float(outcome.success)}

    # ---- the Gymnasium API -----------------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Observation, dict]:
        """options: None or a dict whose keys are in ``RESET_OPTIONS`` (there are none yet); anything else raises
        ConfigError, so that an option meant for another env is never silently ignored."""
        _check_reset_options(options)
        super().reset(seed=seed)
        self._ended = False
        self.layout = sample_layout(self.np_random, self.arena, self.config.n_objects, self.config.texture_pool)
        self.state = WorldState(self.layout.agent_pose.copy(), self.layout.initial_positions.copy())
        self.steps = 0
        self._begin_task()
        if self.render_frames or self.render_mode is not None:
            scene = self._ensure_scene()
            scene.set_episode(
                self.layout.wall_textures, self.layout.object_classes, self._landmarks() if self.config.landmark else ()
            )
            scene.set_state(self.state)
        return self._observation(), self._info(Events(action=Action.MOVE))

    def step(self, action: int) -> tuple[Observation, float, bool, bool, dict]:
        if self.state is None:
            raise ResetNeeded("call reset() before step()")
        if self._ended:
            raise ResetNeeded("the episode has ended (terminated or truncated); call reset() before step()")
        if np.asarray(action).dtype == np.bool_ or not self.action_space.contains(action):
            names = ", ".join(f"{a.value}={a.name}" for a in Action)
            raise ValueError(
                f"action {action!r} is outside the action space Discrete({N_ACTIONS}), an int (not a bool): {names}"
            )
        chosen = Action(int(action))
        before = self.state.copy()
        self.steps += 1
        masked = chosen == self.removed_action
        events = Events(action=chosen) if masked else apply_action(self.state, chosen, self.arena, self.noise, self.np_random)
        outcome = self._outcome(before, events)
        truncated = not outcome.terminated and self.steps >= self.horizon
        if self._scene is not None:
            self._scene.set_state(self.state)
        info = self._info(events)
        info["masked_action"] = masked
        if outcome.terminated or truncated:
            info["metrics"] = self._metrics(outcome)
            self._ended = True
        return self._observation(), outcome.reward, outcome.terminated, truncated, info

    def action_masks(self) -> np.ndarray:
        """(5,) bool: False for the action this task removes (sb3-contrib MaskablePPO reads this)."""
        mask = np.ones(N_ACTIONS, dtype=bool)
        if self.removed_action is not None:
            mask[self.removed_action] = False
        return mask

    def render(self) -> np.ndarray | None:
        """With ``render_mode="rgb_array"``: the first-person view beside the top-down view, (H, W, 3) uint8."""
        if self.render_mode is None:
            gym.logger.warn("render() called without render_mode; make the env with render_mode='rgb_array'")
            return None
        from mor.sim.views import side_by_side

        return side_by_side(self._ensure_scene().render_first_person(), self.top_down())

    def top_down(self) -> np.ndarray:
        """The schematic top-down view of the current state, (S, S, 3) uint8."""
        from mor.sim.views import draw_top_down

        assert self.layout is not None and self.state is not None
        return draw_top_down(self.arena, self.layout, self.state)

    def close(self) -> None:
        if self._scene is not None:
            self._scene.close()
            self._scene = None

    # ---- helpers ---------------------------------------------------------------------------------------------
    def _ensure_scene(self) -> Scene:
        if self._scene is None:
            self._scene = Scene(self.arena, self.config.image_size, n_landmarks=self.config.n_objects)
        return self._scene

    def _observation(self) -> Observation:
        assert self.layout is not None and self.state is not None
        held = self.state.held if self.state.held >= 0 else self.config.n_objects
        return {
            **({"image": self._ensure_scene().render_first_person()} if self.render_frames else {}),
            "object_classes": self.layout.object_classes.copy(),
            "held": held,
            **self._goal_observation(),
        }

    def _info(self, events: Events) -> dict[str, Any]:
        assert self.layout is not None and self.state is not None
        return {
            "agent_pose": self.state.agent_pose.copy(),
            "object_positions": self.state.object_positions(),
            "held": self.state.held,
            "target_positions": self.layout.target_positions.copy(),
            "object_classes": self.layout.object_classes.copy(),
            "obstructed": events.obstructed,
            "picked": events.picked,
            "dropped": events.dropped,
            "drop_blocked": events.drop_blocked,
            "masked_action": False,
        }
