"""The episode record's schema, declared once: MCAP topics and the LeRobot features built from the same fields.

One MCAP file per episode (the source of truth). Frame i is logged at ``BASE_TIME_NS + i / fps`` on:

- ``/camera/image``   foxglove.CompressedImage (PNG), frame_id ``camera``
- ``/agent/pose``     foxglove.PoseInFrame, frame_id ``world``: x, y (metres), yaw theta as a quaternion
- ``/objects/poses``  foxglove.PosesInFrame, frame_id ``world``: one pose per object, in object order
                      (the held object at the agent's position)
- ``/tf``             foxglove.FrameTransforms: world -> base_link, base_link -> camera, world -> object_<i>
- ``/state``          JSON: step, action (taken after this frame; -1 on the last frame), action name, held (-1: none)

and once, at the first frame's time, ``/episode`` (JSON: object classes, target positions, wall textures) plus
the MCAP metadata record ``episode`` (id, source, seed, fps, frame count, params, simulator version).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from mor.sim.rules import Action

SCHEMA_VERSION = "1"
#: The LeRobot dataset's layout (``lerobot_features``), hashed into the dataset version: bump it when they change.
#: 2: ``state.object_visible`` added. 3: LeRobot's names (``observation.images.front``, ``observation.state``,
#: ``action``) and the ground truth under ``ground_truth.*`` (was ``observation.image``, ``observation.held``,
#: ``state.*``).
DATASET_LAYOUT = "3"
BASE_TIME_NS = 1_700_000_000_000_000_000  # a fixed epoch: the same episode gives the same bytes
WORLD_FRAME, AGENT_FRAME, CAMERA_FRAME = "world", "base_link", "camera"
NO_ACTION = -1
MAX_OBJECTS = 5

TOPIC_IMAGE = "/camera/image"
TOPIC_AGENT_POSE = "/agent/pose"
TOPIC_OBJECT_POSES = "/objects/poses"
TOPIC_TF = "/tf"
TOPIC_STATE = "/state"
TOPIC_EPISODE = "/episode"
PER_FRAME_TOPICS = (TOPIC_IMAGE, TOPIC_AGENT_POSE, TOPIC_OBJECT_POSES, TOPIC_TF, TOPIC_STATE)
ALL_TOPICS = (*PER_FRAME_TOPICS, TOPIC_EPISODE)

STATE_JSON_SCHEMA: dict[str, Any] = {
    "title": "mor.State",
    "type": "object",
    "properties": {
        "step": {"type": "integer"},
        "action": {"type": "integer", "description": "taken after this frame; -1 on the last frame"},
        "action_name": {"type": "string", "enum": [a.name for a in Action] + ["NONE"]},
        "held": {"type": "integer", "description": "index of the held object, -1 when none"},
    },
}
EPISODE_JSON_SCHEMA: dict[str, Any] = {
    "title": "mor.Episode",
    "type": "object",
    "properties": {
        "object_classes": {"type": "array", "items": {"type": "integer"}},
        "target_positions": {"type": "array", "items": {"type": "array", "items": {"type": "number"}}},
        "wall_textures": {"type": "array", "items": {"type": "integer"}},
    },
}


# ---- the LeRobot features of one frame -----------------------------------------------------------------------
# LeRobot's conventions: cameras under ``observation.images.<camera>``, the robot's own state as one float vector
# ``observation.state``, the command as the vector ``action``; a stock policy reads exactly these (lerobot's
# ``dataset_to_policy_features`` types every other ``observation.*`` key as extra state, which its policies ignore).
# Everything under ``observation.`` is what an RGB-only agent is given (the camera, its own state, the task: which
# objects, where they go); what it is not given (the simulator's truth, the L-Net's training labels) is under
# ``ground_truth.``.
OBSERVATION, GROUND_TRUTH = "observation", "ground_truth"
IMAGE = f"{OBSERVATION}.images.front"
STATE = f"{OBSERVATION}.state"
OBJECT_CLASSES = f"{OBSERVATION}.object_classes"
TARGET_POSITIONS = f"{OBSERVATION}.target_positions"
AGENT_POSE = f"{GROUND_TRUTH}.agent_pose"
OBJECT_POSITIONS = f"{GROUND_TRUTH}.object_positions"
OBJECT_VISIBLE = f"{GROUND_TRUTH}.object_visible"
ACTION = "action"

#: ``observation.state``: which object slot the robot holds (one-hot, all 0 when none), then the action it took
#: before this frame (one-hot, all 0 on an episode's first frame and after an idle frame).
STATE_NAMES: tuple[str, ...] = (*(f"held{i}" for i in range(MAX_OBJECTS)),
                                *(f"previous_{a.name.lower()}" for a in Action))


@dataclass(frozen=True)
class Feature:
    """One LeRobot feature: its dtype, shape and element names (what lerobot stores), and for the dataset card its
    units and meaning."""

    dtype: str
    shape: tuple[int, ...]
    names: list[str]
    units: str
    meaning: str


def features(image_size: int) -> dict[str, Feature]:
    """The features of one frame, declared once. Objects are padded to ``MAX_OBJECTS`` slots: an absent slot has
    class -1 and position 0. Positions are flattened (x0, y0, x1, y1, ...). Units: metres and radians, world frame
    (docs/design.md). ``action`` is the action taken after the frame (-1 on an episode's last frame).
    ``ground_truth.object_visible``: 1 where the object is in view by ``mor.sim.rules.visible``
    (``mor.data.visibility``), 0 otherwise and in absent slots.
    """
    xy = [f"{axis}{i}" for i in range(MAX_OBJECTS) for axis in ("x", "y")]
    actions = ", ".join(f"{a.value} {a.name}" for a in Action)
    return {
        IMAGE: Feature("image", (image_size, image_size, 3), ["height", "width", "channels"], "uint8 RGB",
                       "first-person camera image (lerobot returns it as (3, H, W) float32 in [0, 1])"),
        STATE: Feature("float32", (len(STATE_NAMES),), list(STATE_NAMES), "0 / 1",
                       "what the robot knows of itself: the held object slot (one-hot, all 0 when none), then the "
                       "previous action (one-hot, all 0 on an episode's first frame)"),
        OBJECT_CLASSES: Feature("int64", (MAX_OBJECTS,), [f"class{i}" for i in range(MAX_OBJECTS)], "class id",
                                "class of each object slot, -1 for an empty slot"),
        TARGET_POSITIONS: Feature("float32", (2 * MAX_OBJECTS,), xy, "m, world frame",
                                  "target (x, y) of each object slot, 0 for an empty slot"),
        AGENT_POSE: Feature("float32", (3,), ["x", "y", "theta"], "m, m, rad; world frame",
                            "ground-truth agent pose (x, y, heading); not observed by the agent"),
        OBJECT_POSITIONS: Feature("float32", (2 * MAX_OBJECTS,), xy, "m, world frame",
                                  "ground-truth (x, y) of each object slot (held: the agent's); not observed"),
        OBJECT_VISIBLE: Feature("int64", (MAX_OBJECTS,), [f"visible{i}" for i in range(MAX_OBJECTS)], "0 / 1",
                                "object slot in view by `mor.sim.rules.visible` (0 when held or empty)"),
        ACTION: Feature("int64", (1,), ["action_id"], "action id",
                        f"the discrete action taken after this frame: {actions}; -1 on an episode's last frame "
                        "(lerobot returns a (1,) feature as one value per frame)"),
    }


def lerobot_features(image_size: int) -> dict[str, dict[str, Any]]:
    """``features`` as ``LeRobotDataset.create`` takes them (LeRobot v3.0: dtype, shape, names)."""
    return {name: {"dtype": f.dtype, "shape": f.shape, "names": f.names} for name, f in features(image_size).items()}
