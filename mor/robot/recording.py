"""Every controlled run, written twice: as a ROS 2 recording (rosbag2 MCAP, readable by ``mor import-real`` and
Foxglove) and as an episode of our dataset (``mor.data.episode_io``) that ``mor build-dataset`` takes in.

Recording topics (the pose, action, held, cmd_vel and first-person image topics are ``RealTopics``' defaults):

- ``/camera/image_raw/compressed``, the top camera's topic (``robot.top_image_topic``): sensor_msgs/CompressedImage
  PNG, every frame the controller used
- ``/mor/detections``   std_msgs/String, JSON: the tags seen (ids, pixel corners, refused and unknown ids)
- ``/tracker/robot_pose``, ``/tracker/object_{i}/pose``: geometry_msgs/PoseStamped, the estimated poses (frame
  ``map`` = the arena frame); absent on a frame without a pose
- ``/mor/action``       std_msgs/String: the action commanded after the frame (NONE: a wait or a stop)
- ``/mor/skill``        std_msgs/String: the skill that chose it (pick, drop; none without a pose)
- ``/cmd_vel``          geometry_msgs/Twist: each segment at its start
- ``/mor/held``         std_msgs/Int32: the held object (-1: none)
- ``/mor/event``        std_msgs/String: PICK and DROP events and the controller's notes (stops)
- ``/sim/truth/robot_pose``, ``/sim/truth/object_{i}/pose``: the simulator's truth (sim-as-robot only)

and an MCAP metadata record ``mor_robot`` (the run's source, loop, method, seed, objects and targets). The episode
has one frame per controller step with a pose (the first-person image at the dataset's size, the truth in
simulation, the estimate on hardware), and its actions are ``mor.data.real.executed_actions``: the rule of
``mor import-real``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
from mcap_ros2.writer import Writer as Ros2Writer

from mor.data.episode_io import EpisodeHeader, EpisodeWriter, encode_png
from mor.data.real import RealTopics, center_crop_resize, executed_actions
from mor.data.ros2_messages import MSGDEFS, pose_stamped, stamp, twist
from mor.data.schema import NO_ACTION
from mor.robot.controller import Step
from mor.robot.pose import Frame, RobotTask

DETECTIONS_TOPIC = "/mor/detections"
SKILL_TOPIC = "/mor/skill"
EVENT_TOPIC = "/mor/event"
TRUTH_AGENT_TOPIC = "/sim/truth/robot_pose"
TRUTH_OBJECT_TOPIC = "/sim/truth/object_{i}/pose"
METADATA = "mor_robot"
MAP_FRAME = "map"


@dataclass(frozen=True)
class RunInfo:
    """What identifies a run: its episode id, source (sim or real), loop (aruco_topdown, fpv_lnet, replay, live),
    method, task, the dataset's image size and frame rate, the arena's wall textures (sim), its parameters."""

    episode_id: str
    source: str
    loop: str
    method: str
    task: RobotTask
    image_size: int
    fps: float
    wall_textures: tuple[int, ...] = ()
    params: dict[str, Any] = field(default_factory=dict)

    def metadata(self) -> dict[str, str]:
        """The recording's ``mor_robot`` metadata record (strings)."""
        return {"episode_id": self.episode_id, "source": self.source, "loop": self.loop, "method": self.method,
                "seed": str(self.task.seed), "object_classes": json.dumps(self.task.object_classes.tolist()),
                "target_positions": json.dumps(np.asarray(self.task.target_positions).tolist())}


@dataclass
class _EpisodeFrames:
    images: list[bytes] = field(default_factory=list)
    poses: list[np.ndarray] = field(default_factory=list)
    objects: list[np.ndarray] = field(default_factory=list)
    held: list[int] = field(default_factory=list)
    commands: list[int] = field(default_factory=list)


class RunRecorder:
    """``with RunRecorder(bag, episodes_dir, info, top_topic) as recorder: recorder.add(step) ...;
    recorder.add_last(frame)``. Both files are written under temporary names and renamed when whole; the episode
    (``episodes_dir/<episode id>.mcap``, skipped when ``episodes_dir`` is None) only if a frame had a pose."""

    def __init__(self, bag_path: Path, episodes_dir: Path | None, info: RunInfo, top_image_topic: str) -> None:
        self.bag_path, self.info, self.top_topic = Path(bag_path), info, top_image_topic
        self.episode_path = None if episodes_dir is None else Path(episodes_dir) / f"{info.episode_id}.mcap"
        self.topics = RealTopics()
        self._partial = self.bag_path.with_name(self.bag_path.name + ".partial")
        self._frames = _EpisodeFrames()
        self._stream: BinaryIO | None = None
        self._counts: dict[str, int] = {}

    def __enter__(self) -> RunRecorder:
        self.bag_path.parent.mkdir(parents=True, exist_ok=True)
        self._stream = open(self._partial, "wb")  # noqa: SIM115 - closed in __exit__
        self._writer = Ros2Writer(self._stream)
        self._schemas = {name: self._writer.register_msgdef(name, text) for name, text in MSGDEFS.items()}
        return self

    def _write(self, topic: str, kind: str, message: dict, ns: int) -> None:
        sequence = self._counts[topic] = self._counts.get(topic, 0) + 1
        self._writer.write_message(topic, self._schemas[kind], message, log_time=ns, publish_time=ns,
                                   sequence=sequence)

    def _image(self, topic: str, image: np.ndarray, ns: int) -> bytes:
        png = encode_png(image)
        self._write(topic, "sensor_msgs/msg/CompressedImage",
                    {"header": {"stamp": stamp(ns), "frame_id": "camera"}, "format": "png", "data": png}, ns)
        return png

    def _poses(self, agent_topic: str, object_topics: list[str], agent: np.ndarray, objects: np.ndarray,
               ns: int) -> None:
        self._write(agent_topic, "geometry_msgs/msg/PoseStamped", pose_stamped(ns, MAP_FRAME, *agent), ns)
        for topic, (x, y) in zip(object_topics, objects, strict=True):
            self._write(topic, "geometry_msgs/msg/PoseStamped", pose_stamped(ns, MAP_FRAME, x, y), ns)

    def _frame(self, frame: Frame, estimate: tuple[np.ndarray, np.ndarray] | None, command: int) -> None:
        """The frame's images, held, truth and estimated poses (agent (3,), objects (n, 2)); the episode's frame
        when there is a pose (the truth in simulation, else the estimate)."""
        ns, n = frame.time_ns, self.info.task.n_objects
        png = None
        if frame.top_down is not None:
            self._image(self.top_topic, frame.top_down, ns)
        if frame.first_person is not None:
            png = self._image(self.topics.image, center_crop_resize(frame.first_person, self.info.image_size), ns)
        self._write(self.topics.held, "std_msgs/msg/Int32", {"data": int(frame.held)}, ns)
        if frame.truth is not None:
            self._poses(TRUTH_AGENT_TOPIC, [TRUTH_OBJECT_TOPIC.format(i=i) for i in range(n)], *frame.truth, ns)
        if estimate is not None:
            self._poses(self.topics.agent_pose, self.topics.object_topics(n), *estimate, ns)
        pose = frame.truth or estimate
        if pose is not None and png is not None:
            self._frames.images.append(png)
            self._frames.poses.append(np.asarray(pose[0], np.float64))
            self._frames.objects.append(np.asarray(pose[1], np.float64))
            self._frames.held.append(int(frame.held))
            self._frames.commands.append(command)

    def add(self, step: Step) -> None:
        """One controller step: its frame, what the pose source saw, the command and its Twist segments."""
        ns, reading, command = step.frame.time_ns, step.reading, step.command
        if reading.detections is not None:
            self._write(DETECTIONS_TOPIC, "std_msgs/msg/String", {"data": json.dumps(reading.detections.as_json())},
                        ns)
        estimate = None if reading.agent_pose is None else (reading.agent_pose, reading.object_positions)
        self._frame(step.frame, estimate, command.action)
        self._write(self.topics.action, "std_msgs/msg/String", {"data": command.name}, ns)
        self._write(SKILL_TOPIC, "std_msgs/msg/String", {"data": step.skill}, ns)
        for note in (command.event, step.note):
            if note:
                self._write(EVENT_TOPIC, "std_msgs/msg/String", {"data": note}, ns)
        offset = ns
        for segment in command.segments:
            self._write(self.topics.cmd_vel, "geometry_msgs/msg/Twist",
                        twist(segment.linear_mps, segment.angular_radps), offset)
            offset += int(round(segment.duration_s * 1e9))

    def add_last(self, frame: Frame, estimate: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        """The frame after the run's last command (the episode's last frame: no action after it), with the pose
        source's estimate (agent (3,), objects (n, 2)) if it read one."""
        self._frame(frame, estimate, NO_ACTION)

    def __exit__(self, error_type: Any, error: Any, traceback: Any) -> None:
        assert self._stream is not None
        try:
            if error_type is None:
                self._writer.add_metadata(METADATA, self.info.metadata())
                self._writer.finish()
        finally:
            self._stream.close()
        if error_type is not None:
            self._partial.unlink(missing_ok=True)
            return
        self._partial.replace(self.bag_path)
        if self.episode_path is not None and self._frames.images:
            self._write_episode()

    def _write_episode(self) -> None:
        info, frames = self.info, self._frames
        poses = np.stack(frames.poses)
        actions = executed_actions(np.asarray(frames.commands), poses)
        header = EpisodeHeader(
            episode_id=info.episode_id, source=info.source,
            seed=info.task.seed if info.source == "sim" else None, fps=info.fps,
            object_classes=np.asarray(info.task.object_classes, np.int64),
            target_positions=np.asarray(info.task.target_positions, np.float64).reshape(-1, 2),
            wall_textures=info.wall_textures,
            params={"import": {"image_size": info.image_size, "fps": info.fps},
                    "controller": {"loop": info.loop, "method": info.method, "recording": self.bag_path.name,
                                   "robot": info.params}})
        with EpisodeWriter(self.episode_path, header) as writer:
            for k, png in enumerate(frames.images):
                writer.add_frame(png, poses[k], frames.objects[k], frames.held[k], int(actions[k]))


__all__ = ["DETECTIONS_TOPIC", "EVENT_TOPIC", "METADATA", "SKILL_TOPIC", "TRUTH_AGENT_TOPIC", "TRUTH_OBJECT_TOPIC",
           "RunInfo", "RunRecorder"]
