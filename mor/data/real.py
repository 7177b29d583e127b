"""Importing a real TurtleBot run (a ROS 2 rosbag2 MCAP recording) as one episode MCAP.

The real setup (paper Supplementary D): a TurtleBot3 Burger with a first-person camera, and a top-down camera
whose ArUco tracker gives the poses of the robot and of the objects. The recording is read with
``mcap_ros2.decoder.DecoderFactory`` (no ROS install) and written with ``EpisodeWriter``, so a real episode has
the same schema as a simulated one and goes through the same dataset build.

Topics (``RealTopics``; defaults follow TurtleBot3 and common tracker conventions):

- image       ``/camera/image_raw/compressed``  sensor_msgs/msg/CompressedImage (jpeg/png); sensor_msgs/msg/Image
              (rgb8, bgr8, rgba8, bgra8, mono8) is read too
- agent pose  ``/tracker/robot_pose``           geometry_msgs/msg/PoseStamped (also Pose, PoseWithCovarianceStamped,
              nav_msgs/msg/Odometry), metres in the arena frame, yaw from the quaternion
- objects     ``/tracker/object_{i}/pose``      one PoseStamped topic per object, ``i`` = 0 .. n_objects - 1
- action      ``/mor/action``                   std_msgs/msg/String (MOVE, TURN_LEFT, TURN_RIGHT, PICK, DROP; NONE or
              STOP = idle) or an std_msgs integer (the ``Action`` value, -1 = idle)
- cmd_vel     ``/cmd_vel``                      geometry_msgs/msg/Twist (or TwistStamped): used only when the action
              topic is absent; linear.x > threshold -> MOVE, else angular.z > threshold -> TURN_LEFT,
              < -threshold -> TURN_RIGHT, else idle
- held        ``/mor/held``                     std_msgs/msg/Int32, the held object's index, -1 = none (optional)

A topic with no messages counts as absent. Non-finite (NaN) tracker poses, which a tracker may publish while it
has lost a tag, are skipped, so the agent pose is interpolated over the gap.

Resampling onto the dataset's frame rate ``fps``: frame k is at t_k = t_start + k / fps, from t_start = the later
of the first image and the first agent pose to t_end = the earlier of the last image and the last agent pose
(usually the first and last image: the tracker runs all along). Per frame:

- image: the latest image at or before t_k, centre-cropped to a square, resized to ``image_size``, PNG;
- agent pose: linearly interpolated at t_k (yaw on the unwrapped angle), or the latest (``pose_interpolation``);
- object positions: the latest tracker pose at or before t_k (before an object's first pose: its first pose);
  the held object is put at the agent's position, as in simulated episodes;
- held: the latest ``/mor/held`` value at or before t_k (-1 before the first). Without a held topic it is inferred
  from the actions with the simulator's rule (PICK takes ``rules.pick_candidate``, DROP releases);
- action (taken after frame k): the first non-idle action whose time falls in [t_k, t_{k+1}); when there is none,
  -1 (``NO_ACTION``: the robot was idle) if an idle command (a zero Twist, NONE) falls in the window, else, with
  ``action_fill="executing"`` (default), the action still executing at t_k, i.e. the latest action before t_k if
  it is not idle and at most ``action_hold_s`` old. Then what the robot did (``executed_actions``, the rule the
  robot controller's own episodes use too): a MOVE or a turn that the tracked pose does not show is -1.
  The last frame's action is -1, as in simulated episodes. With cmd_vel only, changes of the held topic add
  PICK (-1 -> i) and DROP (i -> -1) actions at the time of the change.

Message times are the recorder's receive times (``timestamps="log"``: one clock for every topic), or the
messages' header stamps where they have one (``timestamps="header"``).
"""

from __future__ import annotations

import io
import logging
import string
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
from mcap.reader import McapReader, make_reader
from mcap_ros2.decoder import DecoderFactory as Ros2DecoderFactory
from PIL import Image, UnidentifiedImageError
from pydantic import Field, ValidationError, ValidationInfo, field_validator

from mor.data.episode_io import EpisodeHeader, EpisodeWriter, encode_png
from mor.data.manifest import file_sha256
from mor.data.schema import MAX_OBJECTS, NO_ACTION
from mor.errors import ConfigError, MorError
from mor.params_model import ParamsModel
from mor.sim.catalog import N_CLASSES
from mor.sim.config import format_validation_error
from mor.sim.rules import Action, WorldState, pick_candidate

logger = logging.getLogger(__name__)

EPISODE_SUFFIX = ".mcap"
SOURCE = "real"

#: The command-line flag that sets each ``RealTopics`` field (named in error messages).
TOPIC_FLAGS: dict[str, str] = {
    "image": "--image-topic", "agent_pose": "--agent-pose-topic", "object_pose": "--object-pose-topic",
    "action": "--action-topic", "cmd_vel": "--cmd-vel-topic", "held": "--held-topic",
}

# Message types, without the "/msg/" part (rosbag2 writes "pkg/msg/Name"; older tools "pkg/Name").
IMAGE_TYPES = ("sensor_msgs/CompressedImage", "sensor_msgs/Image")
_POSE_TYPES = ("geometry_msgs/PoseStamped", "geometry_msgs/Pose", "geometry_msgs/PoseWithCovarianceStamped",
               "nav_msgs/Odometry")
INT_TYPES = tuple(f"std_msgs/{kind}{bits}" for kind in ("Int", "UInt") for bits in (8, 16, 32, 64))
_ACTION_TYPES = ("std_msgs/String", *INT_TYPES)
_TWIST_TYPES = ("geometry_msgs/Twist", "geometry_msgs/TwistStamped")
_RAW_ENCODINGS = {"rgb8": 3, "bgr8": 3, "rgba8": 4, "bgra8": 4, "mono8": 1}

_ACTION_NAMES: dict[str, int] = {
    **{action.name: int(action) for action in Action},
    "FORWARD": int(Action.MOVE), "LEFT": int(Action.TURN_LEFT), "RIGHT": int(Action.TURN_RIGHT),
    "PLACE": int(Action.DROP),
    **{idle: NO_ACTION for idle in ("", "NONE", "STOP", "IDLE", "NOOP")},
}


class RealBagError(MorError, ValueError):
    """A recording that cannot be imported; the message names the bag, the topic and what to do."""


class RealTopics(ParamsModel):
    """Which topics of the recording hold what (message types in the module docstring)."""

    image: str = Field("/camera/image_raw/compressed", min_length=1, description="first-person camera")
    agent_pose: str = Field("/tracker/robot_pose", min_length=1, description="robot pose from the top-down tracker")
    object_pose: str = Field("/tracker/object_{i}/pose", min_length=1,
                             description="object i's pose from the top-down tracker; must contain {i}")
    action: str | None = Field("/mor/action", description="executed discrete action; None: use cmd_vel")
    cmd_vel: str | None = Field("/cmd_vel", description="velocity commands, used when the action topic is absent")
    held: str | None = Field("/mor/held", description="held object index (-1: none); None: infer from actions")

    @field_validator("object_pose")
    @classmethod
    def _one_index_field(cls, value: str) -> str:
        try:
            names = [name for _, name, _, _ in string.Formatter().parse(value) if name is not None]
        except ValueError as error:
            raise ValueError(f"not a format string ({error})") from None
        if names != ["i"]:
            raise ValueError("must contain '{i}' exactly once (the object index) and no other {field}")
        return value

    def object_topics(self, n_objects: int) -> list[str]:
        return [self.object_pose.format(i=i) for i in range(n_objects)]


class ImportParams(ParamsModel):
    """What the recording does not say: the objects, their targets, and how to resample. Metres, seconds."""

    n_objects: int = Field(3, ge=1, le=MAX_OBJECTS, description="objects in the run (paper: 3)")
    object_classes: list[int] = Field(description="class id of each object, in object order")
    target_positions: list[tuple[float, float]] = Field(description="(x, y) target of each object, arena frame")
    episode_id: str | None = Field(None, pattern=r"^[A-Za-z0-9][A-Za-z0-9._-]*$",
                                   description="episode id and file stem; None: real-<bag stem>")
    fps: float = Field(10.0, gt=0.0, le=120.0, description="the dataset's frame rate")
    image_size: int = Field(64, ge=16, le=512, description="square image side, pixels")
    timestamps: Literal["log", "header"] = Field(
        "log", description="log: the recorder's receive time; header: header.stamp where a message has one")
    pose_interpolation: Literal["linear", "latest"] = "linear"
    action_fill: Literal["executing", "none"] = Field(
        "executing", description="a frame with no new action gets the one still executing, or -1 (none)")
    action_hold_s: float = Field(1.0, gt=0.0, description="an action counts as executing this long at most")
    cmd_vel_linear_threshold: float = Field(0.01, ge=0.0, description="m/s above which cmd_vel is a MOVE")
    cmd_vel_angular_threshold: float = Field(0.05, ge=0.0, description="rad/s beyond which cmd_vel is a turn")

    @field_validator("object_classes")
    @classmethod
    def _classes(cls, value: list[int], info: ValidationInfo) -> list[int]:
        n = info.data.get("n_objects")
        if n is not None and len(value) != n:
            raise ValueError(f"needs one class per object: {n} values, got {len(value)}")
        bad = [c for c in value if not 0 <= c < N_CLASSES]
        if bad:
            raise ValueError(f"class ids lie in [0, {N_CLASSES}), got {bad[0]}")
        return value

    @field_validator("target_positions")
    @classmethod
    def _targets(cls, value: list[tuple[float, float]], info: ValidationInfo) -> list[tuple[float, float]]:
        n = info.data.get("n_objects")
        if n is not None and len(value) != n:
            raise ValueError(f"needs one (x, y) target per object: {n} pairs, got {len(value)}")
        if not np.all(np.isfinite(np.asarray(value, float))):
            raise ValueError("targets must be finite")
        return value


def make_real_topics(where: str = "", **values: object) -> RealTopics:
    """A validated ``RealTopics``; raises ``ConfigError`` with one line naming the bad field."""
    try:
        return RealTopics(**values)
    except ValidationError as error:
        raise ConfigError(format_validation_error(error, where)) from None


def make_import_params(where: str = "", **values: object) -> ImportParams:
    """A validated ``ImportParams``; raises ``ConfigError`` with one line naming the bad field."""
    try:
        return ImportParams(**values)
    except ValidationError as error:
        raise ConfigError(format_validation_error(error, where)) from None


def center_crop_resize(image: np.ndarray, size: int) -> np.ndarray:
    """(size, size, 3) uint8: the centred square of ``image`` (H, W, 3), resized (Lanczos)."""
    height, width = image.shape[:2]
    side = min(height, width)
    top, left = (height - side) // 2, (width - side) // 2
    square = np.ascontiguousarray(image[top:top + side, left:left + side])
    if side == size:
        return square
    return np.asarray(Image.fromarray(square).resize((size, size), Image.Resampling.LANCZOS))


def quaternion_yaw(x: float, y: float, z: float, w: float) -> float:
    """Rotation about +z (radians, (-pi, pi]) of a quaternion."""
    return float(np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z)))


def _one_line(text: object) -> str:
    return " ".join(str(text).split())


def _base_type(name: str) -> str:
    return name.replace("/msg/", "/")


def _type_names(kinds: tuple[str, ...]) -> str:
    """The types as rosbag2 names them ("pkg/msg/Name"), joined with "or"."""
    return " or ".join(kind.replace("/", "/msg/", 1) for kind in kinds)


@dataclass
class _Series:
    """Samples of one topic, sorted by time (int ns)."""

    times: list[int] = field(default_factory=list)
    values: list[Any] = field(default_factory=list)

    def sorted(self) -> tuple[np.ndarray, list[Any]]:
        times = np.asarray(self.times, np.int64)
        order = np.argsort(times, kind="stable")
        return times[order], [self.values[i] for i in order]


class RosBag:
    """One opened rosbag2 MCAP recording: the file, its topics (type, message count), its decoded messages, and the
    one-line errors it raises (``RealBagError``). Close it (or use it as a context manager)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        try:
            self._stream = open(path, "rb")  # noqa: SIM115 - closed in close()
        except OSError as error:
            raise self.error(f"cannot open it ({_one_line(error.strerror or error)}); check the path") from None
        self.topics: dict[str, tuple[str, int]] = {}
        try:
            self.reader: McapReader = make_reader(self._stream, decoder_factories=[Ros2DecoderFactory()])
            self._inventory()
        except RealBagError:
            self.close()
            raise
        except Exception as error:  # noqa: BLE001 - any failure to parse the file is a corrupt-bag error
            self.close()
            raise self.corrupt(error) from None

    def close(self) -> None:
        self._stream.close()

    def __enter__(self) -> RosBag:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def error(self, text: str) -> RealBagError:
        return RealBagError(_one_line(f"{self.path}: {text}"))

    def corrupt(self, error: BaseException) -> RealBagError:
        return self.error(
            f"not a readable MCAP rosbag2 recording ({type(error).__name__}: {error}); if the recording was cut "
            f"off, repair it with `mcap recover {self.path.name} -o fixed.mcap`, otherwise re-record it")

    def _inventory(self) -> None:
        summary = self.reader.get_summary()
        counts: dict[str, int] = {}
        types: dict[str, str] = {}
        if summary is not None and summary.statistics is not None:
            for channel in summary.channels.values():
                schema = summary.schemas.get(channel.schema_id)
                types.setdefault(channel.topic, schema.name if schema else "")
                counts.setdefault(channel.topic, 0)
            for channel_id, count in summary.statistics.channel_message_counts.items():
                counts[summary.channels[channel_id].topic] += count
        else:  # no statistics (an unfinished or minimal writer): count by reading the file once
            for schema, channel, _ in self.reader.iter_messages(log_time_order=False):
                types.setdefault(channel.topic, schema.name if schema else "")
                counts[channel.topic] = counts.get(channel.topic, 0) + 1
        self.topics = {topic: (types[topic], counts.get(topic, 0)) for topic in types}

    def has(self, topic: str | None) -> bool:
        return topic is not None and self.topics.get(topic, ("", 0))[1] > 0

    def candidates(self, kinds: tuple[str, ...]) -> str:
        names = sorted(t for t, (kind, n) in self.topics.items() if n > 0 and _base_type(kind) in kinds)
        return ", ".join(names[:8]) + (f" (+{len(names) - 8} more)" if len(names) > 8 else "")

    def require(self, topic: str, what: str, flag: str, kinds: tuple[str, ...]) -> str:
        """The base type of ``topic``; raises a one-line error when it is absent, empty or of another type (naming
        ``flag``, the option or parameter that sets the topic)."""
        found = self.candidates(kinds)
        hint = (f"pass {flag} with one of: {found}" if found else
                f"the bag has no {what} topic with messages of type {_type_names(kinds)}; record one or pass {flag}")
        if topic not in self.topics:
            raise self.error(f"no {what} topic '{topic}' in the recording; {hint}")
        kind, count = self.topics[topic]
        if count == 0:
            raise self.error(f"{what} topic '{topic}' has no messages; {hint}")
        if _base_type(kind) not in kinds:
            raise self.error(f"{what} topic '{topic}' is {kind or 'schemaless'}, not {_type_names(kinds)}; {hint}")
        return _base_type(kind)

    def messages(self, topics: list[str]) -> Iterator[tuple[str, int, Any]]:
        """(topic, log time ns, decoded message) in log-time order; decoding errors become RealBagError."""
        try:
            for _, channel, message, decoded in self.reader.iter_decoded_messages(topics=topics):
                yield channel.topic, message.log_time, decoded
        except RealBagError:
            raise
        except Exception as error:  # noqa: BLE001 - a message that cannot be read is a corrupt-bag error
            raise self.corrupt(error) from None


def resolve_bag(bag: Path) -> Path:
    """The MCAP file of ``bag``: the file itself, or the single ``*.mcap`` in a rosbag2 directory."""
    bag = Path(bag)
    if bag.is_dir():
        files = sorted(bag.glob("*.mcap"))
        if len(files) == 1:
            return files[0]
        if not files and any(bag.glob("*.db3")):
            raise RealBagError(f"{bag}: a sqlite3 (.db3) rosbag2, not MCAP; convert it with `ros2 bag convert` "
                               "to storage_id mcap, then import the .mcap")
        what = "no .mcap file" if not files else f"{len(files)} .mcap files (a split recording)"
        raise RealBagError(f"{bag}: the directory holds {what}; pass the path of one .mcap file")
    if not bag.exists():
        raise RealBagError(f"{bag}: no such file; check the path of the recording")
    return bag


def _stamp(message: Any, log_time: int, timestamps: str) -> int:
    if timestamps == "header":
        header = getattr(message, "header", None)
        stamp = getattr(header, "stamp", None)
        if stamp is not None and (stamp.sec or stamp.nanosec):
            return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
    return log_time


def _pose_of(message: Any, kind: str) -> Any:
    if kind == "geometry_msgs/PoseStamped":
        return message.pose
    if kind == "geometry_msgs/Pose":
        return message
    return message.pose.pose  # PoseWithCovarianceStamped, Odometry


def decode_image(message: Any, kind: str) -> np.ndarray:
    """(H, W, 3) uint8 RGB; raises ValueError when the image cannot be decoded."""
    if kind == "sensor_msgs/CompressedImage":
        if "compresseddepth" in str(message.format).lower():
            raise ValueError(f"format {message.format!r} is a depth image")
        try:
            return np.asarray(Image.open(io.BytesIO(bytes(message.data))).convert("RGB"))
        except (UnidentifiedImageError, OSError) as error:
            raise ValueError(f"format {message.format!r}: {error}") from None
    channels = _RAW_ENCODINGS.get(str(message.encoding).lower())
    if channels is None:
        raise ValueError(f"raw encoding {message.encoding!r} is not one of {', '.join(_RAW_ENCODINGS)}")
    height, width, step = int(message.height), int(message.width), int(message.step)
    data = np.frombuffer(bytes(message.data), np.uint8)
    if height * width == 0 or step < width * channels or data.size < height * step:
        raise ValueError(f"{width}x{height} {message.encoding} with step {step} does not fit {data.size} bytes")
    pixels = data[:height * step].reshape(height, step)[:, :width * channels].reshape(height, width, channels)
    if channels == 1:
        return np.repeat(pixels, 3, axis=2)
    if str(message.encoding).lower().startswith("bgr"):
        pixels = pixels[:, :, 2::-1]
    return np.ascontiguousarray(pixels[:, :, :3])


@dataclass
class _Recording:
    """What the import reads from the bag, before resampling (times in ns, sorted)."""

    image_times: np.ndarray
    image_ordinals: np.ndarray
    pose_times: np.ndarray
    poses: np.ndarray
    object_times: list[np.ndarray]
    object_xy: list[np.ndarray]
    action_times: np.ndarray
    actions: np.ndarray
    held_times: np.ndarray | None
    held: np.ndarray | None
    sources: dict[str, Any]


def _action_value(bag: RosBag, topic: str, kind: str, message: Any, number: int) -> int:
    data = message.data
    if kind == "std_msgs/String":
        value = _ACTION_NAMES.get(str(data).strip().upper().replace(" ", "_").replace("-", "_"))
        if value is None:
            raise bag.error(f"action topic '{topic}' message {number} is {str(data)!r}, not an action name; "
                            f"publish one of {', '.join(a.name for a in Action)} (or NONE)")
        return value
    if not NO_ACTION <= int(data) < len(Action):
        raise bag.error(f"action topic '{topic}' message {number} is {int(data)}, not an action; publish "
                        f"0..{len(Action) - 1} ({', '.join(a.name for a in Action)}) or -1 (none)")
    return int(data)


def _twist_value(message: Any, kind: str, params: ImportParams) -> int:
    twist = message.twist if kind == "geometry_msgs/TwistStamped" else message
    if twist.linear.x > params.cmd_vel_linear_threshold:
        return int(Action.MOVE)
    if twist.angular.z > params.cmd_vel_angular_threshold:
        return int(Action.TURN_LEFT)
    if twist.angular.z < -params.cmd_vel_angular_threshold:
        return int(Action.TURN_RIGHT)
    return NO_ACTION


def _read(bag: RosBag, topics: RealTopics, params: ImportParams) -> _Recording:
    """Check the topics and read every non-image message (and the image times)."""
    image_kind = bag.require(topics.image, "image", TOPIC_FLAGS["image"], IMAGE_TYPES)
    pose_kind = bag.require(topics.agent_pose, "agent pose", TOPIC_FLAGS["agent_pose"], _POSE_TYPES)
    object_topics = topics.object_topics(params.n_objects)
    object_kinds = [bag.require(t, f"object {i} pose", TOPIC_FLAGS["object_pose"], _POSE_TYPES)
                    for i, t in enumerate(object_topics)]
    if bag.has(topics.action):
        assert topics.action is not None
        action_source, action_topic = "action", topics.action
        action_kind = bag.require(action_topic, "action", TOPIC_FLAGS["action"], _ACTION_TYPES)
    elif bag.has(topics.cmd_vel):
        assert topics.cmd_vel is not None
        action_source, action_topic = "cmd_vel", topics.cmd_vel
        action_kind = bag.require(action_topic, "velocity command", TOPIC_FLAGS["cmd_vel"], _TWIST_TYPES)
    else:
        offers = [(TOPIC_FLAGS["action"], bag.candidates(_ACTION_TYPES)),
                  (TOPIC_FLAGS["cmd_vel"], bag.candidates(_TWIST_TYPES))]
        found = " or ".join(f"{flag} with one of: {names}" for flag, names in offers if names)
        record = (f"record the executed actions ({_type_names(('std_msgs/String', 'std_msgs/Int32'))}) or the "
                  f"velocity commands ({_type_names(_TWIST_TYPES[:1])}), or pass --action-topic or --cmd-vel-topic")
        raise bag.error(f"neither the action topic '{topics.action}' nor the velocity topic '{topics.cmd_vel}' has "
                        f"messages; {'pass ' + found if found else record}")
    held_topic = topics.held if bag.has(topics.held) else None
    if held_topic:
        bag.require(held_topic, "held object", TOPIC_FLAGS["held"], INT_TYPES)

    images, poses, actions, held = _Series(), _Series(), _Series(), _Series()
    objects = [_Series() for _ in object_topics]
    object_index = {t: i for i, t in enumerate(object_topics)}
    counts: dict[str, int] = {}
    wanted = [topics.image, topics.agent_pose, *object_topics, action_topic, *([held_topic] if held_topic else [])]
    for topic, log_time, message in bag.messages(list(dict.fromkeys(wanted))):
        number = counts[topic] = counts.get(topic, 0) + 1
        time = _stamp(message, log_time, params.timestamps)
        if topic == topics.image:
            images.times.append(time)
            images.values.append(number - 1)  # the image's ordinal: decoded later, only if a frame uses it
        if topic == topics.agent_pose:
            pose = _pose_of(message, pose_kind)
            q = pose.orientation
            value = (pose.position.x, pose.position.y, quaternion_yaw(q.x, q.y, q.z, q.w))
            if np.all(np.isfinite(value)):  # a tracker may publish NaN while it has lost the tag: skip those
                poses.times.append(time)
                poses.values.append(value)
        if topic in object_index:
            i = object_index[topic]
            pose = _pose_of(message, object_kinds[i])
            if np.isfinite(pose.position.x) and np.isfinite(pose.position.y):
                objects[i].times.append(time)
                objects[i].values.append((pose.position.x, pose.position.y))
        if topic == action_topic:
            actions.times.append(time)
            actions.values.append(_action_value(bag, topic, action_kind, message, number) if action_source == "action"
                                  else _twist_value(message, action_kind, params))
        if topic == held_topic:
            value = int(message.data)
            if not -1 <= value < params.n_objects:
                raise bag.error(f"held topic '{topic}' message {number} is {value}, not an object index; publish "
                                f"-1 (none) or 0..{params.n_objects - 1}, or pass --held-topic '' to infer it")
            held.times.append(time)
            held.values.append(value)

    for what, series, topic, name in (("agent pose", poses, topics.agent_pose, "agent_pose"),
                                      *((f"object {i} pose", s, t, "object_pose")
                                        for i, (s, t) in enumerate(zip(objects, object_topics, strict=True)))):
        if not series.times:
            raise bag.error(f"{what} topic '{topic}' has only non-finite (NaN) poses: the tracker never saw the "
                            f"tag; re-record with the tag in view or pass {TOPIC_FLAGS[name]}")
    image_times, image_ordinals = images.sorted()
    pose_times, pose_values = poses.sorted()
    object_sorted = [series.sorted() for series in objects]
    action_times, action_values = actions.sorted()
    held_times, held_values = held.sorted() if held_topic else (None, None)
    sources = {"image_type": image_kind, "agent_pose_type": pose_kind, "actions": action_source,
               "action_topic": action_topic, "action_type": action_kind,
               "held": "topic" if held_topic else ("actions" if action_source == "action" else "none")}
    if action_source == "cmd_vel" and held_topic:  # PICK and DROP from the held topic's changes
        assert held_times is not None and held_values is not None
        extra = [(t, int(Action.PICK) if now >= 0 else int(Action.DROP))
                 for t, before, now in zip(held_times[1:], held_values[:-1], held_values[1:], strict=True)
                 if (before < 0) != (now < 0)]
        if extra:
            merged = sorted([*zip(action_times.tolist(), action_values, strict=True), *extra], key=lambda e: e[0])
            action_times = np.asarray([t for t, _ in merged], np.int64)
            action_values = [v for _, v in merged]
    return _Recording(
        image_times=image_times, image_ordinals=np.asarray(image_ordinals, np.int64),
        pose_times=pose_times, poses=np.asarray(pose_values, np.float64).reshape(-1, 3),
        object_times=[t for t, _ in object_sorted],
        object_xy=[np.asarray(v, np.float64).reshape(-1, 2) for _, v in object_sorted],
        action_times=action_times, actions=np.asarray(action_values, np.int64),
        held_times=held_times, held=None if held_values is None else np.asarray(held_values, np.int64),
        sources=sources,
    )


def _latest(times: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Index of the latest sample at or before each of ``at`` (-1 where there is none)."""
    return np.searchsorted(times, at, side="right") - 1


def _frame_actions(recording: _Recording, frame_times: np.ndarray, params: ImportParams) -> np.ndarray:
    """The command in force over each frame's window [t_k, t_k+1): the first non-idle one that starts in it; else
    idle when a stop (a zero Twist, NONE) comes in it; else (``action_fill="executing"``) the one still executing."""
    times, values = recording.action_times, recording.actions
    hold_ns = int(round(params.action_hold_s * 1e9))
    actions = np.full(len(frame_times), NO_ACTION, np.int64)
    for k in range(len(frame_times) - 1):
        lo, hi = np.searchsorted(times, frame_times[k:k + 2], side="left")
        window = values[lo:hi]
        started = window[window >= 0]
        if len(started):
            actions[k] = started[0]
        elif (len(window) == 0 and params.action_fill == "executing" and lo > 0 and values[lo - 1] >= 0
              and frame_times[k] - times[lo - 1] <= hold_ns):
            actions[k] = values[lo - 1]
    return actions


#: What counts as motion of the tracked pose between two frames (``executed_actions``): metres, radians.
MOTION_MIN_M: float = 0.005
MOTION_MIN_RAD: float = float(np.deg2rad(0.5))


def executed_actions(commands: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """What the robot did after each frame: the one rule of ``import_rosbag`` and of the robot controller's own
    episodes (``mor.robot.recording``).

    commands (T,): the action in force from frame t to frame t + 1 (-1 NO_ACTION: none, or a stop); poses (T, 3)
    the tracked [x m, y m, theta rad] of each frame. A MOVE whose position moved less than ``MOTION_MIN_M``, or a
    turn whose heading changed less than ``MOTION_MIN_RAD``, is no action (-1): the robot did not do it. PICK and
    DROP are kept (they move nothing). The last frame's action is -1. Returns (T,) int64.
    """
    commands = np.asarray(commands, np.int64)
    poses = np.asarray(poses, np.float64).reshape(-1, 3)
    executed = np.full(len(commands), NO_ACTION, np.int64)
    if len(commands) < 2:
        return executed
    moved = np.linalg.norm(np.diff(poses[:, :2], axis=0), axis=1)
    turned = np.abs(np.angle(np.exp(1j * np.diff(poses[:, 2]))))
    now = commands[:-1]
    did = np.where(now == Action.MOVE, moved >= MOTION_MIN_M,
                   np.where(np.isin(now, (Action.TURN_LEFT, Action.TURN_RIGHT)), turned >= MOTION_MIN_RAD, now >= 0))
    executed[:-1] = np.where(did, now, NO_ACTION)
    return executed


def _max_gap_s(times: np.ndarray, start: int, end: int) -> float:
    inside = times[(times >= start) & (times <= end)]
    edges = np.concatenate([[start], inside, [end]])
    return round(float(np.max(np.diff(edges))) / 1e9, 6)


def _resample(bag: RosBag, recording: _Recording, topics: RealTopics, params: ImportParams) -> dict[str, Any]:
    r = recording
    start = int(max(r.image_times[0], r.pose_times[0]))
    end = int(min(r.image_times[-1], r.pose_times[-1]))
    if end < start:
        raise bag.error(f"the images ('{topics.image}') and the agent poses ('{topics.agent_pose}') do not overlap "
                        "in time; record the tracker while the camera runs, or check --timestamps")
    n_frames = int(np.floor((end - start) * params.fps / 1e9 + 1e-9)) + 1
    frame_times = start + np.round(np.arange(n_frames) * (1e9 / params.fps)).astype(np.int64)
    frame_times = frame_times[frame_times <= end]

    seconds = (frame_times - start) / 1e9
    pose_seconds = (r.pose_times - start) / 1e9
    if params.pose_interpolation == "linear" and len(r.pose_times) > 1:
        yaw = np.unwrap(r.poses[:, 2])
        poses = np.stack([np.interp(seconds, pose_seconds, r.poses[:, 0]),
                          np.interp(seconds, pose_seconds, r.poses[:, 1]),
                          np.interp(seconds, pose_seconds, yaw)], axis=1)
    else:
        poses = r.poses[np.maximum(_latest(r.pose_times, frame_times), 0)].copy()
    poses[:, 2] = np.arctan2(np.sin(poses[:, 2]), np.cos(poses[:, 2]))

    objects = np.stack([xy[np.maximum(_latest(t, frame_times), 0)] for t, xy in zip(r.object_times, r.object_xy,
                                                                                        strict=True)], axis=1)
    actions = executed_actions(_frame_actions(r, frame_times, params), poses)
    if r.held_times is not None and r.held is not None:
        index = _latest(r.held_times, frame_times)
        held = np.where(index >= 0, r.held[np.maximum(index, 0)], -1).astype(np.int64)
    else:
        held = np.full(len(frame_times), -1, np.int64)
        if r.sources["held"] == "actions":  # infer with the simulator's PICK / DROP rules
            for k in range(len(frame_times) - 1):
                now = int(held[k])
                if actions[k] == Action.PICK and now < 0:
                    now = pick_candidate(WorldState(poses[k].copy(), objects[k].copy(), -1))
                elif actions[k] == Action.DROP:
                    now = -1
                held[k + 1] = now
    carried = held >= 0
    objects[carried, held[carried]] = poses[carried, :2]

    image_index = _latest(r.image_times, frame_times)
    return {
        "times": frame_times, "poses": poses, "objects": objects, "held": held, "actions": actions,
        "image_ordinals": r.image_ordinals[image_index],
        "quality": {"image_max_gap_s": _max_gap_s(r.image_times, start, end),
                    "agent_pose_max_gap_s": _max_gap_s(r.pose_times, start, end),
                    "frames_without_action": int(np.sum(actions[:-1] < 0)),
                    "start_ns": start, "end_ns": end},
    }


def _images(bag: RosBag, topic: str, kind: str, ordinals: set[int], size: int) -> dict[int, bytes]:
    """PNG bytes of the images with the given ordinals (their order on ``topic``), cropped and resized."""
    pngs: dict[int, bytes] = {}
    last = max(ordinals)
    for ordinal, (_, _, message) in enumerate(bag.messages([topic])):
        if ordinal in ordinals:
            try:
                image = decode_image(message, kind)
            except ValueError as error:
                raise bag.error(f"image {ordinal + 1} on '{topic}' cannot be decoded ({error}); re-record the "
                                "camera as jpeg or png CompressedImage, or pass --image-topic") from None
            pngs[ordinal] = encode_png(center_crop_resize(image, size))
        if ordinal >= last:
            break
    return pngs


def episode_path(out_dir: Path, bag: Path, params: ImportParams) -> Path:
    """Where ``import_rosbag`` writes the episode of ``bag``: ``<out_dir>/<episode id>.mcap``."""
    return Path(out_dir) / f"{params.episode_id or 'real-' + Path(bag).stem}{EPISODE_SUFFIX}"


def import_rosbag(bag: Path, out_dir: Path, topics: RealTopics, params: ImportParams) -> Path:
    """Convert one rosbag2 MCAP recording (a file, or a rosbag2 directory holding one) into one episode MCAP in
    ``out_dir``; returns its path. Raises ``RealBagError`` (one line naming the bag and the topic) on bad input."""
    source = resolve_bag(Path(bag))
    opened = RosBag(source)
    try:
        recording = _read(opened, topics, params)
        frames = _resample(opened, recording, topics, params)
        image_kind = recording.sources["image_type"]
        pngs = _images(opened, topics.image, image_kind, set(frames["image_ordinals"].tolist()), params.image_size)
    finally:
        opened.close()
    path = episode_path(out_dir, source, params)
    header = EpisodeHeader(
        episode_id=path.name.removesuffix(EPISODE_SUFFIX), source=SOURCE, seed=None, fps=params.fps,
        object_classes=np.asarray(params.object_classes, np.int64),
        target_positions=np.asarray(params.target_positions, np.float64).reshape(-1, 2),
        wall_textures=(),
        params={"topics": topics.model_dump(mode="json"), "import": params.model_dump(mode="json"),
                "bag": {"file": source.name, "sha256": file_sha256(source)},
                "sources": recording.sources, "quality": frames["quality"]},
    )
    actions = frames["actions"]
    if path.exists():
        logger.warning("%s: replacing the existing episode %s", source, path)
    with EpisodeWriter(path, header) as writer:
        for k, ordinal in enumerate(frames["image_ordinals"].tolist()):
            writer.add_frame(pngs[ordinal], frames["poses"][k], frames["objects"][k], int(frames["held"][k]),
                             int(actions[k]))
    logger.info("%s: %d frames at %g fps (actions from %s, held from %s) -> %s", source, len(actions), params.fps,
                recording.sources["actions"], recording.sources["held"], path)
    return path


__all__ = ["IMAGE_TYPES", "INT_TYPES", "MOTION_MIN_M", "MOTION_MIN_RAD", "TOPIC_FLAGS", "ImportParams", "RealBagError",
           "RealTopics", "RosBag", "center_crop_resize", "decode_image", "episode_path", "executed_actions",
           "import_rosbag", "make_import_params", "make_real_topics", "quaternion_yaw", "resolve_bag"]
