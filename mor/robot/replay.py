"""Replaying a recorded run through the controller, without ROS: ``mor robot replay run.mcap``.

The bag is read with ``mor.data.real.RosBag``. Each message on the pose source's camera topic (the top camera for
``aruco``, the first-person camera for ``lnet``) is one controller step, given the latest first-person image and
held object (``/mor/held``, -1 when the bag has none) at or before it. The commands go nowhere (the recorded world
already happened): they are recorded (``mor.robot.recording``) and compared with the bag's own ``/mor/action``
where it has one, so that replaying the controller's own recording checks that it decides the same again.

The task (objects and targets) comes from the recording's ``mor_robot`` metadata, or from the caller. Bad input is
one line naming the bag: a missing camera topic, a tag id of no tag of ``robot.tags``, or a layout whose corner or
robot tags the bag never shows.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mor.data.real import IMAGE_TYPES, INT_TYPES, RealTopics, RosBag, decode_image, resolve_bag
from mor.data.schema import NO_ACTION
from mor.robot.controller import Controller
from mor.robot.params import RobotParams
from mor.robot.pose import Frame, RobotTask
from mor.robot.recording import METADATA, RunInfo, RunRecorder
from mor.sim.rules import Action


@dataclass(frozen=True)
class ReplaySummary:
    """What a replay did: steps, the actions it decided (-1: none), how many of the frames with a recorded action
    (``compared``; 0 when the bag has no action topic) it matched, its notes (stops), and the files written."""

    steps: int
    actions: list[int]
    compared: int
    agreeing: int
    notes: list[str]
    recording: Path
    episode: Path | None


def bag_task(bag: RosBag) -> tuple[RobotTask | None, dict[str, str]]:
    """The task in the recording's ``mor_robot`` metadata (None without one) and that metadata."""
    for record in bag.reader.iter_metadata():
        if record.name == METADATA:
            meta = dict(record.metadata)
            return RobotTask(np.asarray(json.loads(meta["object_classes"]), np.int64),
                             np.asarray(json.loads(meta["target_positions"]), np.float64), int(meta["seed"])), meta
    return None, {}


def message_groups(bag: RosBag, topics: list[str]) -> Iterator[tuple[int, dict[str, Any]]]:
    """The bag's messages on ``topics``, grouped by log time: (time ns, {topic: decoded message})."""
    time, group = None, {}
    for topic, ns, message in bag.messages(topics):
        if time is not None and ns != time:
            yield time, group
            group = {}
        time, group[topic] = ns, message
    if time is not None:
        yield time, group


def replay_bag(bag_path: Path, controller: Controller, params: RobotParams, task: RobotTask | None,
               recording: Path, episodes_dir: Path | None, image_size: int, fps: float) -> ReplaySummary:
    """Replay ``bag_path`` through ``controller`` (see the module); ``task``: the objects and targets when the
    bag's metadata has none. Writes ``recording`` and (into ``episodes_dir``) the replay's episode."""
    source = resolve_bag(Path(bag_path))
    topics = RealTopics()
    with RosBag(source) as bag:
        saved, meta = bag_task(bag)
        task = task or saved
        if task is None:
            raise bag.error("has no mor_robot metadata (not a controller's recording): pass --object-classes and "
                            "--targets")
        top = controller.source.camera == "top_down"
        camera = params.top_image_topic if top else topics.image
        kinds = {camera: bag.require(camera, "top camera" if top else "first-person camera",
                                     "robot.top_image_topic" if top else "--fpv-topic (RealTopics.image)",
                                     IMAGE_TYPES)}
        for topic in (topics.image, topics.held, topics.action):
            if bag.has(topic) and topic not in kinds:
                kinds[topic] = bag.topics[topic][0].replace("/msg/", "/")
        if topics.held in kinds:
            bag.require(topics.held, "held object", "--held-topic", INT_TYPES)
        info = RunInfo(f"replay-{source.stem}", meta.get("source", "real"), "replay", controller.policy.method,
                       task, image_size, fps, params=params.model_dump(mode="json"))
        controller.start(task)
        seen: set[int] = set()
        actions, compared, agreeing, notes = [], 0, 0, []
        held, first_person, recorded = -1, None, None
        with RunRecorder(recording, episodes_dir, info, params.top_image_topic) as recorder:
            for ns, group in message_groups(bag, list(kinds)):
                if topics.held in group:
                    held = int(group[topics.held].data)
                if topics.image in group:
                    first_person = decode_image(group[topics.image], kinds[topics.image])
                recorded = _action(group[topics.action].data) if topics.action in group else None
                if camera not in group:
                    continue
                image = decode_image(group[camera], kinds[camera])
                step = controller.step(Frame(ns, held, image if top else None, first_person))
                detections = step.reading.detections
                if detections is not None:
                    if detections.unknown:
                        raise bag.error(f"frame {step.index} shows tag id(s) {list(detections.unknown)}, no tag of "
                                        "robot.tags; add them to robot.tags (object_ids, corner_ids) in params.yaml "
                                        "or record without them in view")
                    seen.update(detections.ids.tolist())
                recorder.add(step)
                actions.append(step.command.action)
                compared += recorded is not None
                agreeing += recorded is not None and recorded == step.command.action
                notes += [step.note] if step.note else []
            if top:
                _check_layout(bag, params, seen)
    episode = recorder.episode_path
    return ReplaySummary(len(actions), actions, compared, agreeing, notes, recording,
                         episode if episode is not None and episode.exists() else None)


def _action(value: str | int) -> int:
    """A recorded /mor/action (a name, NONE, or an integer) as an action, -1 for none."""
    if isinstance(value, str):
        return int(Action[value]) if value in Action.__members__ else NO_ACTION
    return int(value)


def _check_layout(bag: RosBag, params: RobotParams, seen: set[int]) -> None:
    """A one-line error when the bag never shows a corner tag or the robot's tag of ``params.tags``."""
    tags = params.tags
    missing = [(f"robot.tags.corner_ids {tag_id}") for tag_id in tags.corner_ids if tag_id not in seen]
    missing += [f"robot.tags.agent_id {tags.agent_id}"] if tags.agent_id not in seen else []
    if missing:
        raise bag.error(f"never shows the tag(s) {', '.join(missing)}; set robot.tags in params.yaml to the ids of "
                        "the arena's tags (seen: " + (", ".join(map(str, sorted(seen))) or "none") + ")")


__all__ = ["ReplaySummary", "bag_task", "message_groups", "replay_bag"]
