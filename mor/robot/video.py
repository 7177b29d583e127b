"""A controlled run's video from its recording: the top camera with the detected tags drawn (the robot's in green
with its heading, the objects' in blue with their index, the corners' in red) and the targets' success circles
(grey, t<index>), beside the first-person view, the commanded action and the skill that chose it underneath.
Any recording of ``mor.robot.recording`` (sim-as-robot or hardware) will do.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

from mor.data.real import IMAGE_TYPES, RealTopics, RosBag, decode_image, resolve_bag
from mor.robot.params import RobotParams
from mor.robot.recording import DETECTIONS_TOPIC, SKILL_TOPIC
from mor.robot.aruco import ArenaLocalizer, TagDetections
from mor.robot.replay import bag_task, message_groups
from mor.sim.metrics import SUCCESS_RADIUS
from mor.sim.views import write_video

_GREEN, _BLUE, _RED, _GREY = (40, 200, 60), (40, 90, 230), (220, 40, 40), (90, 90, 90)


def draw_targets(image: np.ndarray, detections: TagDetections, targets: np.ndarray, params: RobotParams) -> None:
    """Each target (n, 2) metres as its success circle (``SUCCESS_RADIUS``) and index, in place, through the corner
    tags' homography (nothing when a corner tag is missing)."""
    matrix, _ = ArenaLocalizer(params.tags, params.top_camera).homography(detections)
    if matrix is None:
        return
    inverse = np.linalg.inv(matrix)
    for index, target in enumerate(np.asarray(targets, np.float64)):
        ends = np.array([target, target + (SUCCESS_RADIUS, 0.0)])
        centre, edge = cv2.perspectiveTransform(ends[None], inverse)[0]
        cv2.circle(image, tuple(np.round(centre).astype(int)), int(round(np.linalg.norm(edge - centre))), _GREY,
                   max(1, image.shape[1] // 600))
        cv2.putText(image, f"t{index}", tuple(np.round(centre).astype(int)), cv2.FONT_HERSHEY_SIMPLEX,
                    image.shape[1] / 800, _GREY, max(1, image.shape[1] // 400))


def draw_detections(image: np.ndarray, detections: dict, params: RobotParams,
                    targets: np.ndarray | None = None) -> np.ndarray:
    """``image`` (H, W, 3) RGB with the outlines of ``detections`` (``TagDetections.as_json``) and the task's
    ``targets`` (n, 2) drawn on a copy."""
    tags, out = params.tags, image.copy()
    width = max(1, image.shape[1] // 400)
    if targets is not None:
        found = TagDetections(np.asarray(detections["ids"], np.int64),
                              np.asarray(detections["corners"], np.float64).reshape(-1, 4, 2))
        draw_targets(out, found, targets, params)
    for tag_id, corners in zip(detections["ids"], detections["corners"], strict=True):
        points = np.asarray(corners, np.float64)
        role = tags.role(tag_id)
        colour = {"agent": _GREEN, "object": _BLUE}.get(role, _RED)
        cv2.polylines(out, [np.round(points).astype(np.int32)], True, colour, width + 1)
        centre = points.mean(axis=0)
        if role == "agent":
            heading = (points[1] - points[0]) + (points[2] - points[3])
            tip = centre + 1.5 * heading
            cv2.arrowedLine(out, tuple(np.round(centre).astype(int)), tuple(np.round(tip).astype(int)), _GREEN,
                            width + 1, tipLength=0.3)
        elif role == "object":
            cv2.putText(out, str(tags.object_ids.index(tag_id)), tuple(np.round(centre + (12, -12)).astype(int)),
                        cv2.FONT_HERSHEY_SIMPLEX, image.shape[1] / 800, colour, width)
    return out


def _side_by_side(top: np.ndarray, first_person: np.ndarray | None, height: int, caption: str) -> np.ndarray:
    """The top camera scaled to ``height`` rows, the first-person image (nearest) to its right, a caption below."""
    scaled = cv2.resize(top, (round(top.shape[1] * height / top.shape[0]), height), interpolation=cv2.INTER_AREA)
    parts = [scaled]
    if first_person is not None:
        parts += [np.full((height, 4, 3), 255, np.uint8),
                  cv2.resize(first_person, (height, height), interpolation=cv2.INTER_NEAREST)]
    row = np.concatenate(parts, axis=1)
    band = np.full((22, row.shape[1], 3), 255, np.uint8)
    cv2.putText(band, caption, (6, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1)
    return np.concatenate([row, band], axis=0)


def write_run_video(recording: Path, out: Path, params: RobotParams, height: int = 300, every: int = 1,
                    fps: int = 8) -> Path:
    """The video of ``recording`` (every ``every``-th top camera frame, ``height`` rows) to ``out`` (.gif/.mp4)."""
    topics = RealTopics()
    frames: list[np.ndarray] = []
    with RosBag(resolve_bag(Path(recording))) as bag:
        task, _ = bag_task(bag)
        bag.require(params.top_image_topic, "top camera", "robot.top_image_topic", IMAGE_TYPES)
        wanted = [params.top_image_topic, topics.image, DETECTIONS_TOPIC, topics.action, SKILL_TOPIC]
        kinds = {topic: bag.topics[topic][0].replace("/msg/", "/") for topic in wanted if bag.has(topic)}
        shown = 0
        for _, group in message_groups(bag, list(kinds)):
            if params.top_image_topic not in group:
                continue
            shown += 1
            if (shown - 1) % every:
                continue
            found = (json.loads(group[DETECTIONS_TOPIC].data) if DETECTIONS_TOPIC in group
                     else {"ids": [], "corners": []})
            top = draw_detections(decode_image(group[params.top_image_topic], kinds[params.top_image_topic]), found,
                                  params, None if task is None else task.target_positions)
            first_person = decode_image(group[topics.image], kinds[topics.image]) if topics.image in group else None
            action = str(group[topics.action].data) if topics.action in group else "end"
            skill = f" ({group[SKILL_TOPIC].data} skill)" if SKILL_TOPIC in group else ""
            frames.append(_side_by_side(top, first_person, height, f"step {shown - 1}: {action}{skill}"))
    return write_video(out, frames, fps)


__all__ = ["draw_detections", "write_run_video"]
