"""Which objects the camera sees on each recorded frame, by the simulator's own rule (``mor.sim.rules.visible``).

Derived from a frame's recorded state (agent pose, object positions, held index), so it can be computed for any
episode file, simulated or real; the dataset stores it as ``ground_truth.object_visible``.
"""

from __future__ import annotations

import numpy as np

from mor.sim.rules import WorldState, visible


def visible_per_frame(agent_poses: np.ndarray, object_positions: np.ndarray, held: np.ndarray) -> np.ndarray:
    """(T, n) bool: object i is in the field of view and not occluded at frame t (a held object never is).

    agent_poses (T, 3) [x m, y m, theta rad]; object_positions (T, n, 2) m (the held one's row is ignored);
    held (T,) index or -1.
    """
    t_max, n = object_positions.shape[:2]
    out = np.zeros((t_max, n), dtype=bool)
    for t in range(t_max):
        state = WorldState(np.asarray(agent_poses[t], float), np.asarray(object_positions[t], float), int(held[t]))
        out[t] = [visible(state, i) for i in range(n)]
    return out
