"""Discrete actions as robot motion: geometry_msgs/Twist segments with durations, and PICK / DROP events.

MOVE drives ``move_distance_m`` at ``linear_speed_mps``; TURN_LEFT / TURN_RIGHT turn ``turn_angle_rad`` at
``angular_speed_radps`` (counter-clockwise positive, as the arena's heading); each ends with a zero Twist held for
``settle_s``. PICK and DROP move nothing: they are events for a gripper or an operator, given ``event_s``. A stop
is a zero Twist alone.
"""

from __future__ import annotations

from dataclasses import dataclass

from mor.data.schema import NO_ACTION
from mor.robot.params import ActuatorParams
from mor.sim.rules import Action


@dataclass(frozen=True)
class Segment:
    """Drive with forward speed ``linear_mps`` (m/s) and turn rate ``angular_radps`` (rad/s) for ``duration_s``."""

    linear_mps: float
    angular_radps: float
    duration_s: float

    @property
    def is_stop(self) -> bool:
        return self.linear_mps == 0.0 and self.angular_radps == 0.0


@dataclass(frozen=True)
class Command:
    """What the robot is told after one frame: ``action`` (-1: none, a stop or a wait), Twist segments in order,
    and an event name (PICK, DROP) or None."""

    action: int
    segments: tuple[Segment, ...]
    event: str | None = None

    @property
    def duration_s(self) -> float:
        return sum(segment.duration_s for segment in self.segments)

    @property
    def name(self) -> str:
        """The action's name, NONE for a stop or a wait (what ``/mor/action`` carries)."""
        return Action(self.action).name if self.action >= 0 else "NONE"


#: The safety stop: a zero Twist, nothing else.
STOP = Command(NO_ACTION, (Segment(0.0, 0.0, 0.0),))
#: A wait: nothing is sent.
WAIT = Command(NO_ACTION, ())


class Actuator:
    """``command(action) -> Command`` from the ``robot.actuator`` parameters."""

    def __init__(self, params: ActuatorParams) -> None:
        self.params = params

    def command(self, action: int) -> Command:
        p, action = self.params, Action(action)
        settle = Segment(0.0, 0.0, p.settle_s)
        if action == Action.MOVE:
            return Command(action, (Segment(p.linear_speed_mps, 0.0, p.move_distance_m / p.linear_speed_mps), settle))
        if action in (Action.TURN_LEFT, Action.TURN_RIGHT):
            rate = p.angular_speed_radps if action == Action.TURN_LEFT else -p.angular_speed_radps
            return Command(action, (Segment(0.0, rate, p.turn_angle_rad / p.angular_speed_radps), settle))
        return Command(action, (Segment(0.0, 0.0, p.event_s),), event=action.name)


__all__ = ["STOP", "WAIT", "Actuator", "Command", "Segment"]
