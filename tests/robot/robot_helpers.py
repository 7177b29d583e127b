"""Helpers of the robot tests: hide or paste tags in a top camera frame."""

from __future__ import annotations

import numpy as np

from mor.robot.aruco import TagDetector
from mor.robot.pose import Frame

FLOOR = (203, 198, 191)  # about the floor's colour in the top camera


def hide_tags(frame: Frame, detector: TagDetector, tag_ids: list[int]) -> Frame:
    """``frame`` with the tags ``tag_ids`` painted over in the floor's colour."""
    image = frame.top_down.copy()
    found = detector.detect(image)
    for tag_id in tag_ids:
        corners = found.corners_of(tag_id)
        (x0, y0), (x1, y1) = np.floor(corners.min(0)).astype(int) - 3, np.ceil(corners.max(0)).astype(int) + 3
        image[y0:y1, x0:x1] = FLOOR
    return Frame(frame.time_ns, frame.held, image, frame.first_person, frame.truth)


def paste(frame: Frame, patch: np.ndarray, at: tuple[int, int]) -> Frame:
    """``frame`` with ``patch`` (h, w, 3) pasted with its top-left corner at pixel ``at`` (x, y)."""
    image = frame.top_down.copy()
    x, y = at
    image[y:y + patch.shape[0], x:x + patch.shape[1]] = patch
    return Frame(frame.time_ns, frame.held, image, frame.first_person, frame.truth)
