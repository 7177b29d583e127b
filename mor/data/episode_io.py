"""Writing and reading one episode's MCAP file (layout in ``mor.data.schema``).

Writes go to ``<name>.partial`` and are renamed when the file is complete, so a file with the final name is
always a whole episode.
"""

from __future__ import annotations

import io
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.Pose_pb2 import Pose
from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame
from foxglove_schemas_protobuf.PosesInFrame_pb2 import PosesInFrame
from foxglove_schemas_protobuf.Quaternion_pb2 import Quaternion
from foxglove_schemas_protobuf.Vector3_pb2 import Vector3
from google.protobuf.timestamp_pb2 import Timestamp
from mcap.decoder import DecoderFactory
from mcap.reader import make_reader
from mcap.well_known import MessageEncoding, SchemaEncoding
from mcap.writer import CompressionType, IndexType, Writer
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoderFactory
from mcap_protobuf.schema import register_schema
from PIL import Image

from mor.data import schema
from mor.errors import MorError
from mor.sim.rules import Action
from mor.sim.scene import CAMERA_HEIGHT

SIMULATOR_VERSION = "mor-sim-1"


class EpisodeFileError(MorError):
    """An episode file that cannot be read as an episode."""


@dataclass
class EpisodeHeader:
    """What is fixed for a whole episode.

    object_classes: (n,) class ids; target_positions: (n, 2) metres; wall_textures: texture index per wall
    (empty for real runs); params: the parameters that produced it (JSON-able).
    """

    episode_id: str
    source: str
    seed: int | None
    fps: float
    object_classes: np.ndarray
    target_positions: np.ndarray
    wall_textures: tuple[int, ...] = ()
    params: dict[str, Any] = field(default_factory=dict)
    simulator_version: str = SIMULATOR_VERSION


@dataclass
class EpisodeData:
    """A whole episode in memory. T frames, n objects.

    images (T, H, W, 3) uint8; agent_poses (T, 3) [x m, y m, theta rad]; object_positions (T, n, 2) m;
    held (T,) index or -1; actions (T,) the action taken after each frame, -1 on the last.
    """

    header: EpisodeHeader
    images: np.ndarray
    agent_poses: np.ndarray
    object_positions: np.ndarray
    held: np.ndarray
    actions: np.ndarray

    @property
    def n_frames(self) -> int:
        return len(self.agent_poses)


def encode_png(image: np.ndarray) -> bytes:
    """PNG bytes of an (H, W, 3) uint8 image (fast compression: frames are small)."""
    buffer = io.BytesIO()
    Image.fromarray(image).save(buffer, format="PNG", compress_level=1)
    return buffer.getvalue()


def decode_png(data: bytes) -> np.ndarray:
    """(H, W, 3) uint8 from PNG or JPEG bytes."""
    return np.asarray(Image.open(io.BytesIO(data)).convert("RGB"))


def _timestamp(ns: int) -> Timestamp:
    stamp = Timestamp()
    stamp.FromNanoseconds(ns)
    return stamp


def _pose(x: float, y: float, z: float = 0.0, yaw: float = 0.0) -> Pose:
    return Pose(position=Vector3(x=x, y=y, z=z),
                orientation=Quaternion(x=0.0, y=0.0, z=float(np.sin(yaw / 2)), w=float(np.cos(yaw / 2))))


def _transform(ns: int, parent: str, child: str, pose: Pose) -> FrameTransform:
    return FrameTransform(timestamp=_timestamp(ns), parent_frame_id=parent, child_frame_id=child,
                          translation=pose.position, rotation=pose.orientation)


# The camera looks along the robot's +x; foxglove's camera convention is z forward, x right, y down.
_CAMERA_ROTATION = Quaternion(x=-0.5, y=0.5, z=-0.5, w=0.5)


class EpisodeWriter:
    """Stream one episode into ``path`` (through ``path.partial``); use as a context manager.

    On leaving the ``with`` block without error the file is finished and renamed; on error it is deleted.
    """

    def __init__(self, path: Path, header: EpisodeHeader) -> None:
        self.path = Path(path)
        self.header = header
        self.partial = self.path.with_name(self.path.name + ".partial")
        self._frames = 0
        self._file: BinaryIO | None = None

    def __enter__(self) -> EpisodeWriter:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = open(self.partial, "wb")  # noqa: SIM115 - closed in __exit__
        self._writer = Writer(self._file, compression=CompressionType.ZSTD, index_types=IndexType.ALL)
        self._writer.start(profile="", library=f"mor {SIMULATOR_VERSION}")
        self._channels = {
            topic: self._writer.register_channel(topic, MessageEncoding.Protobuf, register_schema(self._writer, cls))
            for topic, cls in (
                (schema.TOPIC_IMAGE, CompressedImage),
                (schema.TOPIC_AGENT_POSE, PoseInFrame),
                (schema.TOPIC_OBJECT_POSES, PosesInFrame),
                (schema.TOPIC_TF, FrameTransforms),
            )
        }
        for topic, json_schema in ((schema.TOPIC_STATE, schema.STATE_JSON_SCHEMA),
                                   (schema.TOPIC_EPISODE, schema.EPISODE_JSON_SCHEMA)):
            schema_id = self._writer.register_schema(json_schema["title"], SchemaEncoding.JSONSchema,
                                                     json.dumps(json_schema).encode())
            self._channels[topic] = self._writer.register_channel(topic, MessageEncoding.JSON, schema_id)
        header = self.header
        self._log(schema.TOPIC_EPISODE, 0, json.dumps({
            "object_classes": [int(c) for c in header.object_classes],
            "target_positions": np.asarray(header.target_positions, float).round(6).tolist(),
            "wall_textures": [int(t) for t in header.wall_textures],
        }).encode())
        return self

    def _time(self, frame: int) -> int:
        return schema.BASE_TIME_NS + int(round(frame * 1e9 / self.header.fps))

    def _log(self, topic: str, frame: int, data: bytes) -> None:
        ns = self._time(frame)
        self._writer.add_message(self._channels[topic], log_time=ns, data=data, publish_time=ns, sequence=frame)

    def add_frame(self, image_png: bytes, agent_pose: np.ndarray, object_positions: np.ndarray, held: int,
                  action: int) -> None:
        """Append frame ``self.n_frames``: PNG bytes, pose (3,), object positions (n, 2), held index, action."""
        frame, ns = self._frames, self._time(self._frames)
        x, y, theta = (float(v) for v in agent_pose)
        agent = _pose(x, y, 0.0, theta)
        objects = [_pose(float(px), float(py)) for px, py in object_positions]
        self._log(schema.TOPIC_IMAGE, frame, CompressedImage(
            timestamp=_timestamp(ns), frame_id=schema.CAMERA_FRAME, data=image_png, format="png").SerializeToString())
        self._log(schema.TOPIC_AGENT_POSE, frame, PoseInFrame(
            timestamp=_timestamp(ns), frame_id=schema.WORLD_FRAME, pose=agent).SerializeToString())
        self._log(schema.TOPIC_OBJECT_POSES, frame, PosesInFrame(
            timestamp=_timestamp(ns), frame_id=schema.WORLD_FRAME, poses=objects).SerializeToString())
        camera = Pose(position=Vector3(x=0.0, y=0.0, z=CAMERA_HEIGHT), orientation=_CAMERA_ROTATION)
        transforms = [_transform(ns, schema.WORLD_FRAME, schema.AGENT_FRAME, agent),
                      _transform(ns, schema.AGENT_FRAME, schema.CAMERA_FRAME, camera)]
        transforms += [_transform(ns, schema.WORLD_FRAME, f"object_{i}", pose) for i, pose in enumerate(objects)]
        self._log(schema.TOPIC_TF, frame, FrameTransforms(transforms=transforms).SerializeToString())
        name = Action(action).name if action >= 0 else "NONE"
        self._log(schema.TOPIC_STATE, frame, json.dumps(
            {"step": frame, "action": int(action), "action_name": name, "held": int(held)}).encode())
        self._frames += 1

    @property
    def n_frames(self) -> int:
        return self._frames

    def __exit__(self, error_type: Any, error: Any, traceback: Any) -> None:
        assert self._file is not None
        try:
            if error_type is None:
                header = self.header
                self._writer.add_metadata("episode", {
                    "episode_id": header.episode_id, "source": header.source,
                    "seed": "" if header.seed is None else str(header.seed), "fps": repr(float(header.fps)),
                    "n_frames": str(self._frames), "n_objects": str(len(header.object_classes)),
                    "params": json.dumps(header.params, sort_keys=True), "simulator_version": header.simulator_version,
                    "schema_version": schema.SCHEMA_VERSION,
                })
                self._writer.finish()
        finally:
            self._file.close()
        if error_type is None:
            self.partial.replace(self.path)
        else:
            self.partial.unlink(missing_ok=True)


class _JsonDecoderFactory(DecoderFactory):
    def decoder_for(self, message_encoding: str, schema_record: Any) -> Any:
        return json.loads if message_encoding == MessageEncoding.JSON else None


REDO = "delete it and re-collect (sim) or re-import (real) it"


def _unreadable(path: Path, what: str, error: BaseException) -> EpisodeFileError:
    """One line naming ``path``, what could not be read and the error (whatever its type), and what to do."""
    detail = " ".join(f"{type(error).__name__}: {error}".split())
    return EpisodeFileError(f"{path}: {what} ({detail}); {REDO}")


def read_metadata(path: Path) -> dict[str, str]:
    """The ``episode`` metadata record of ``path`` (raises EpisodeFileError when unreadable)."""
    try:
        with open(path, "rb") as stream:
            for record in make_reader(stream).iter_metadata():
                if record.name == "episode":
                    return dict(record.metadata)
    except Exception as error:  # any failure to parse the file's bytes means a bad file
        raise _unreadable(path, "not a readable episode MCAP", error) from None
    raise EpisodeFileError(f"{path}: no 'episode' metadata record; {REDO}")


def check_summary(path: Path) -> dict[str, str]:
    """The metadata of ``path`` after checking its summary: indexed, every channel, ``n_frames`` messages on each
    per-frame channel. Raises EpisodeFileError (one line); reads no message."""
    metadata = read_metadata(path)
    try:
        with open(path, "rb") as stream:
            summary = make_reader(stream).get_summary()
        if summary is None or summary.statistics is None or not summary.chunk_indexes:
            raise EpisodeFileError(f"{path}: no summary or chunk index (truncated?); {REDO}")
        counts = {summary.channels[cid].topic: n for cid, n in summary.statistics.channel_message_counts.items()}
        frames = int(metadata["n_frames"])
    except EpisodeFileError:
        raise
    except Exception as error:  # any failure to parse the file's bytes means a bad file
        raise _unreadable(path, "unreadable summary", error) from None
    missing = [topic for topic in schema.ALL_TOPICS if topic not in counts]
    if missing:
        raise EpisodeFileError(f"{path}: missing channels {', '.join(missing)}; {REDO}")
    uneven = {t: counts[t] for t in schema.PER_FRAME_TOPICS if counts[t] != frames}
    if uneven:
        raise EpisodeFileError(f"{path}: frame counts disagree (metadata {frames}, channels {uneven}); {REDO}")
    return metadata


def verify_episode(path: Path) -> dict[str, str]:
    """Check that ``path`` is a whole episode: its summary (``check_summary``), every chunk's CRC, and every
    message decoded (images included). Returns its metadata; raises EpisodeFileError (one line naming the file)."""
    metadata = check_summary(path)
    read_episode(path)
    return metadata


def read_episode(path: Path, with_images: bool = True) -> EpisodeData:
    """Read a whole episode, checking chunk CRCs; ``with_images=False`` skips decoding the PNGs (images is then
    empty). Any failure to decode a message (whatever the exception) is an EpisodeFileError naming the file."""
    path = Path(path)
    metadata = read_metadata(path)
    try:
        return _decode_episode(path, metadata, with_images)
    except EpisodeFileError:
        raise
    except Exception as error:  # protobuf, zstd, PNG, JSON, shapes: any failure to decode means a bad file
        raise _unreadable(path, "unreadable messages", error) from None


def _decode_episode(path: Path, metadata: dict[str, str], with_images: bool) -> EpisodeData:
    topics = [t for t in schema.ALL_TOPICS if with_images or t != schema.TOPIC_IMAGE]
    images, poses, objects, held, actions = [], [], [], [], []
    episode: dict[str, Any] = {}
    with open(path, "rb") as stream:
        reader = make_reader(stream, validate_crcs=True,
                             decoder_factories=[ProtobufDecoderFactory(), _JsonDecoderFactory()])
        for _, channel, _, message in reader.iter_decoded_messages(topics=topics, log_time_order=False):
            topic = channel.topic
            if topic == schema.TOPIC_IMAGE:
                images.append(decode_png(message.data))
            elif topic == schema.TOPIC_AGENT_POSE:
                q = message.pose.orientation
                poses.append((message.pose.position.x, message.pose.position.y,
                              2.0 * np.arctan2(q.z, q.w)))
            elif topic == schema.TOPIC_OBJECT_POSES:
                objects.append([(p.position.x, p.position.y) for p in message.poses])
            elif topic == schema.TOPIC_STATE:
                held.append(message["held"])
                actions.append(message["action"])
            elif topic == schema.TOPIC_EPISODE:
                episode = message
    n, frames = int(metadata["n_objects"]), int(metadata["n_frames"])
    counts = {"poses": len(poses), "object poses": len(objects), "states": len(held)}
    if with_images:
        counts["images"] = len(images)
    if any(count != frames for count in counts.values()):
        raise EpisodeFileError(f"{path}: {frames} frames in the metadata but {counts} messages; {REDO}")
    header = EpisodeHeader(
        episode_id=metadata["episode_id"], source=metadata["source"],
        seed=int(metadata["seed"]) if metadata["seed"] else None, fps=float(metadata["fps"]),
        object_classes=np.asarray(episode.get("object_classes", []), np.int64),
        target_positions=np.asarray(episode.get("target_positions", []), np.float64).reshape(n, 2),
        wall_textures=tuple(episode.get("wall_textures", [])), params=json.loads(metadata["params"]),
        simulator_version=metadata["simulator_version"],
    )
    theta = np.asarray(poses, np.float64).reshape(-1, 3)
    theta[:, 2] = (theta[:, 2] + np.pi) % (2 * np.pi) - np.pi
    return EpisodeData(
        header=header,
        images=np.asarray(images, np.uint8) if with_images else np.zeros((0, 0, 0, 3), np.uint8),
        agent_poses=theta,
        object_positions=np.asarray(objects, np.float64).reshape(-1, n, 2),
        held=np.asarray(held, np.int64),
        actions=np.asarray(actions, np.int64),
    )
