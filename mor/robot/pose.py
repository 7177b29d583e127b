"""Pose sources: what the controller knows of the world at a frame, as the policies' ``PoseBelief``.

``aruco``: the top camera's tags (``mor.robot.aruco``): the detected pose with zero covariance, as the ground
truth's variant sees the truth; an object keeps its last detected position while its tag is out of view (objects move only when
held), the held one is at the robot. ``lnet``: the first-person frames through the L-Net's streaming step.
A reading without a belief (``problem`` says why) must not be acted on.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np

from mor.data.real import center_crop_resize
from mor.data.schema import NO_ACTION
from mor.errors import ConfigError
from mor.robot.aruco import ArenaLocalizer, TagDetections, TagDetector
from mor.robot.policy import LNetRunner, LNetTracker, PoseBelief, truth_belief
from mor.sim.arena import Arena
from mor.sim.tags import ArucoTags, TopCamera

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class Frame:
    """One moment the controller sees. time_ns: the clock (ns); held: the held object's index, -1 when none
    (the gripper's or operator's word, or the simulator's); top_down (H, W, 3) and first_person (S, S, 3) uint8
    RGB images, None where that camera gave none; truth: the simulator's agent pose (3,) and object positions
    (n, 2), None on hardware."""

    time_ns: int
    held: int
    top_down: np.ndarray | None = None
    first_person: np.ndarray | None = None
    truth: tuple[np.ndarray, np.ndarray] | None = None


@dataclass(frozen=True)
class RobotTask:
    """What a run must do: object_classes (n,) class ids, target_positions (n, 2) metres, and its seed (the
    skills' draws; in simulation the episode's reset seed)."""

    object_classes: np.ndarray
    target_positions: np.ndarray
    seed: int

    @property
    def n_objects(self) -> int:
        return len(self.object_classes)


@dataclass(frozen=True)
class PoseReading:
    """A pose source's answer at one frame: the belief (N = 1) or None; the agent pose (3,) and object positions
    (n, 2) it holds (the belief's means); why there is no belief; the tags seen (aruco); the seconds it took."""

    belief: PoseBelief | None
    agent_pose: np.ndarray | None = None
    object_positions: np.ndarray | None = None
    problem: str | None = None
    detections: TagDetections | None = None
    seconds: float = 0.0


def _reading(belief: PoseBelief | None, started: float, **fields: object) -> PoseReading:
    if belief is not None:
        fields.update(agent_pose=np.array([*belief.agent_mean[0], belief.heading[0]], np.float64),
                      object_positions=belief.object_mean[0].astype(np.float64))
    return PoseReading(belief, seconds=time.perf_counter() - started, **fields)


class ArucoPoseSource:
    """Poses from the top camera's ArUco tags (``read(frame, previous_action) -> PoseReading``)."""

    camera = "top_down"

    def __init__(self, tags: ArucoTags, camera: TopCamera, refinement: str) -> None:
        self.detector = TagDetector(tags, refinement)
        self.localizer = ArenaLocalizer(tags, camera)
        self._objects = np.zeros((0, 2))
        self._reported: set[int] = set()

    def start(self, task: RobotTask) -> None:
        if task.n_objects > len(self.detector.tags.object_ids):
            raise ConfigError(f"robot.tags.object_ids: {task.n_objects} objects need {task.n_objects} tag ids, got "
                              f"{self.detector.tags.object_ids}; add their ids in params.yaml")
        self._objects = np.full((task.n_objects, 2), np.nan)

    def read(self, frame: Frame, previous_action: int) -> PoseReading:
        started = time.perf_counter()
        if frame.top_down is None:
            return _reading(None, started, problem="no top camera frame")
        detections = self.detector.detect(frame.top_down)
        for tag_id in set(detections.unknown) - self._reported:
            logger.warning("tag %d is no tag of robot.tags: ignored", tag_id)
            self._reported.add(tag_id)
        fix = self.localizer.locate(detections)
        for index, position in fix.objects.items():
            if index < len(self._objects):
                self._objects[index] = position
        if fix.agent_pose is None:
            return _reading(None, started, problem=fix.problem, detections=detections)
        objects = self._objects.copy()
        if frame.held >= 0:
            objects[frame.held] = fix.agent_pose[:2]
        unseen = np.flatnonzero(np.isnan(objects[:, 0]))
        if len(unseen):
            ids = [self.detector.tags.object_ids[i] for i in unseen]
            return _reading(None, started, problem=f"object tag(s) {ids} not seen yet", detections=detections)
        return _reading(truth_belief(fix.agent_pose, objects), started, detections=detections)


class LNetPoseSource:
    """Poses from the first-person frames through the L-Net's streaming step (a real camera's frame is
    centre-cropped and resized to the L-Net's image size)."""

    camera = "first_person"

    def __init__(self, runner: LNetRunner, search_arena: Arena | None = None) -> None:
        self.runner = runner
        self.tracker = LNetTracker(runner, search_arena)
        self._classes = np.zeros(0, np.int64)
        self._starting = True

    def start(self, task: RobotTask) -> None:
        self._classes = np.asarray(task.object_classes, np.int64)
        self._starting = True

    def read(self, frame: Frame, previous_action: int) -> PoseReading:
        started = time.perf_counter()
        if frame.first_person is None:
            return _reading(None, started, problem="no first-person frame")
        image = center_crop_resize(frame.first_person, self.runner.image_size)
        held = frame.held if frame.held >= 0 else len(self._classes)
        belief = self.tracker.observe(image, self._classes, held, NO_ACTION if self._starting else previous_action,
                                      self._starting)
        self._starting = False
        return _reading(belief, started)


PoseSource = ArucoPoseSource | LNetPoseSource

__all__ = ["ArucoPoseSource", "Frame", "LNetPoseSource", "PoseReading", "PoseSource", "RobotTask"]
