"""Poses from a top camera's image with OpenCV's ArUco module (paper Supplementary D).

The corner tags' centres give the homography from the image to the floor (arena frame: x east, y north, metres).
A raised tag (the robot's, the objects') is seen where its ray meets the floor, displaced away from the camera;
its true position lies on that ray at its height: p = c + (q - c) (Z - h) / Z for the floor point q, the camera's
optical centre (c, Z) and the tag's height h. The robot's heading is its tag's x axis (marker corners 0 -> 1)
plus ``ArucoTags.agent_yaw_rad``, averaged with the y axis turned by -90 degrees.

A tag id seen twice in one frame is refused for that frame (both sightings dropped, logged). Ids of no tag of the
layout are reported in ``TagDetections.unknown``; the caller decides (a replay refuses them, a live run logs them).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import cv2
import numpy as np

from mor.sim.tags import ArucoTags, TopCamera
from mor.sim.topdown import aruco_dictionary

logger = logging.getLogger(__name__)

_REFINEMENT = {"contour": cv2.aruco.CORNER_REFINE_CONTOUR, "subpix": cv2.aruco.CORNER_REFINE_SUBPIX,
               "none": cv2.aruco.CORNER_REFINE_NONE}


@dataclass(frozen=True)
class TagDetections:
    """The layout's tags found in one image: ids (k,) and corners (k, 4, 2) pixels (x right, y down; the marker's
    top-left, top-right, bottom-right, bottom-left). refused: ids seen more than once (dropped); unknown: ids of
    no tag of the layout (dropped)."""

    ids: np.ndarray
    corners: np.ndarray
    refused: tuple[int, ...] = ()
    unknown: tuple[int, ...] = ()

    def corners_of(self, tag_id: int) -> np.ndarray | None:
        """(4, 2) pixels of tag ``tag_id``, None when it was not (or not once) seen."""
        found = np.flatnonzero(self.ids == tag_id)
        return self.corners[found[0]] if len(found) else None

    def as_json(self) -> dict:
        """What a recording stores: ids, corners (pixels, 0.01 px), refused and unknown ids."""
        return {"ids": self.ids.tolist(), "corners": np.round(self.corners, 2).tolist(),
                "refused": list(self.refused), "unknown": list(self.unknown)}


class TagDetector:
    """cv2.aruco's detector for the layout's dictionary; ``detect(image (H, W, 3) uint8 RGB) -> TagDetections``."""

    def __init__(self, tags: ArucoTags, refinement: str = "contour") -> None:
        self.tags = tags
        parameters = cv2.aruco.DetectorParameters()
        parameters.cornerRefinementMethod = _REFINEMENT[refinement]
        self._detector = cv2.aruco.ArucoDetector(aruco_dictionary(tags.dictionary), parameters)

    def detect(self, image: np.ndarray) -> TagDetections:
        corners, ids, _ = self._detector.detectMarkers(cv2.cvtColor(image, cv2.COLOR_RGB2GRAY))
        ids = np.zeros(0, np.int64) if ids is None else ids.reshape(-1).astype(np.int64)
        corners = np.asarray(corners, np.float64).reshape(-1, 4, 2)
        values, counts = np.unique(ids, return_counts=True)
        refused = tuple(int(i) for i in values[counts > 1])
        unknown = tuple(int(i) for i in values if self.tags.role(int(i)) is None)
        if refused:
            logger.warning("tag(s) %s seen more than once in one frame: refused for this frame", list(refused))
        keep = ~np.isin(ids, refused + unknown)
        return TagDetections(ids[keep], corners[keep], refused, unknown)


@dataclass(frozen=True)
class TopDownFix:
    """What one frame says. agent_pose (3,) [x m, y m, theta rad] or None; objects: object index -> (2,) metres
    for the object tags seen; problem: why there is no agent pose (None when there is one)."""

    agent_pose: np.ndarray | None
    objects: dict[int, np.ndarray] = field(default_factory=dict)
    problem: str | None = None


class ArenaLocalizer:
    """Poses in the arena frame from ``TagDetections``: ``locate(detections) -> TopDownFix``."""

    def __init__(self, tags: ArucoTags, camera: TopCamera) -> None:
        self.tags = tags
        self._centre = np.asarray(camera.position_m[:2], np.float64)
        self._height = float(camera.position_m[2])
        self._corner_world = np.asarray(tags.corner_positions, np.float64)

    def homography(self, detections: TagDetections) -> tuple[np.ndarray | None, str | None]:
        """(3, 3) image -> floor homography from the corner tags' centres, or (None, the reason)."""
        found = [detections.corners_of(i) for i in self.tags.corner_ids]
        missing = [i for i, corners in zip(self.tags.corner_ids, found, strict=True) if corners is None]
        if missing:
            return None, f"corner tag(s) {', '.join(map(str, missing))} not seen: no arena frame"
        centres = np.stack([corners.mean(axis=0) for corners in found])
        matrix, _ = cv2.findHomography(centres, self._corner_world)
        return (matrix, None) if matrix is not None else (None, "corner tags in a degenerate layout")

    def to_floor(self, matrix: np.ndarray, pixels: np.ndarray, height: float) -> np.ndarray:
        """pixels (..., 2) of points ``height`` metres above the floor -> their (..., 2) arena positions."""
        shape = pixels.shape
        floor = cv2.perspectiveTransform(pixels.reshape(1, -1, 2).astype(np.float64), matrix).reshape(shape)
        return self._centre + (floor - self._centre) * (self._height - height) / self._height

    def locate(self, detections: TagDetections) -> TopDownFix:
        matrix, problem = self.homography(detections)
        if matrix is None:
            return TopDownFix(None, problem=problem)
        objects = {}
        for index, tag_id in enumerate(self.tags.object_ids):
            corners = detections.corners_of(tag_id)
            if corners is not None:
                objects[index] = self.to_floor(matrix, corners, self.tags.object_height_m).mean(axis=0)
        corners = detections.corners_of(self.tags.agent_id)
        if corners is None:
            seen_twice = self.tags.agent_id in detections.refused
            why = "seen twice: refused" if seen_twice else "not seen"
            return TopDownFix(None, objects, f"agent tag {self.tags.agent_id} {why}")
        world = self.to_floor(matrix, corners, self.tags.agent_height_m)
        x_axis = (world[1] - world[0]) + (world[2] - world[3])
        y_axis = (world[0] - world[3]) + (world[1] - world[2])
        direction = x_axis + np.array([y_axis[1], -y_axis[0]])
        heading = np.arctan2(direction[1], direction[0]) + self.tags.agent_yaw_rad
        pose = np.array([*world.mean(axis=0), np.arctan2(np.sin(heading), np.cos(heading))])
        return TopDownFix(pose, objects)


__all__ = ["ArenaLocalizer", "TagDetections", "TagDetector", "TopDownFix"]
