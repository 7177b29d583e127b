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

from typing import Any

from mor.sim.rules import Action

SCHEMA_VERSION = "1"
#: The LeRobot dataset's layout (``lerobot_features``), hashed into the dataset version: bump it when they change.
#: 2: ``state.object_visible`` added.
DATASET_LAYOUT = "2"
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


def lerobot_features(image_size: int) -> dict[str, dict[str, Any]]:
    """The LeRobot v3.0 features of one frame. Objects are padded to ``MAX_OBJECTS`` slots: an absent slot has
    class -1 and position 0. Positions are flattened (x0, y0, x1, y1, ...). Units: metres and radians, world frame
    (docs/design.md). ``action`` is the action taken after the frame (-1 on an episode's last frame).
    ``state.object_visible``: 1 where the object is in view by ``mor.sim.rules.visible`` (``mor.data.visibility``),
    0 otherwise and in absent slots.
    """
    xy = [f"{axis}{i}" for i in range(MAX_OBJECTS) for axis in ("x", "y")]
    return {
        "observation.image": {"dtype": "image", "shape": (image_size, image_size, 3),
                              "names": ["height", "width", "channels"]},
        "observation.object_classes": {"dtype": "int64", "shape": (MAX_OBJECTS,),
                                       "names": [f"class{i}" for i in range(MAX_OBJECTS)]},
        "observation.held": {"dtype": "int64", "shape": (1,), "names": None},
        "observation.target_positions": {"dtype": "float32", "shape": (2 * MAX_OBJECTS,), "names": xy},
        "state.agent_pose": {"dtype": "float32", "shape": (3,), "names": ["x", "y", "theta"]},
        "state.object_positions": {"dtype": "float32", "shape": (2 * MAX_OBJECTS,), "names": xy},
        "state.object_visible": {"dtype": "int64", "shape": (MAX_OBJECTS,),
                                 "names": [f"visible{i}" for i in range(MAX_OBJECTS)]},
        "action": {"dtype": "int64", "shape": (1,), "names": None},
    }
