"""The catalog's colour rule: which objects of an episode share their colour (what the L-Net confuses)."""

from __future__ import annotations

import numpy as np
import torch

from mor.sim.catalog import COLOURS, object_class, shares_colour


def test_objects_that_differ_by_shape_alone_share_their_colour_and_empty_slots_never_do() -> None:
    blue_cube, blue_sphere, red_cube = 2, 2 + len(COLOURS), 0
    assert object_class(blue_cube).colour == object_class(blue_sphere).colour == "blue"
    classes = np.array([[blue_cube, blue_sphere, red_cube, -1, -1], [red_cube, blue_cube, -1, -1, -1]])
    expected = [[True, True, False, False, False], [False, False, False, False, False]]
    assert shares_colour(classes).tolist() == expected
    assert shares_colour(torch.as_tensor(classes)).tolist() == expected  # the same rule on tensors
