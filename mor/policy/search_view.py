"""The policy's compact view of the search belief: where the L-Net has not looked yet, around the agent.

The search belief (``mor.lnet.search``) is a density over the arena grid, shared by every object the L-Net has not
found yet (each is, as far as the L-Net knows, anywhere it has not looked). A policy reads its mass in
``SEARCH_SECTORS`` bearing sectors of equal width around the agent's believed heading (sector 0 straight ahead,
counter-clockwise), each split into ``SEARCH_RINGS`` range rings (within PICK's reach, beyond): a vector that sums
to 1 while something is searched, and is all zero when every object is found.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from mor.sim.rules import PICK_RANGE

SEARCH_SECTORS = 8
#: the rings' outer radii, metres (the last is unbounded)
RING_EDGES: tuple[float, ...] = (PICK_RANGE,)
SEARCH_RINGS = len(RING_EDGES) + 1


def sector_names() -> list[str]:
    """The name of each entry of ``sector_masses``' output, in order."""
    width = 360 // SEARCH_SECTORS
    rings = [f"within{edge:g}m" for edge in RING_EDGES] + [f"beyond{RING_EDGES[-1]:g}m"]
    return [f"search_{s * width:+d}deg_{ring}" for s in range(SEARCH_SECTORS) for ring in rings]


def sector_masses(density: NDArray, grid: NDArray, cell_area: float, agent_mean: NDArray, heading: NDArray,
                  searching: NDArray) -> NDArray[np.float32]:
    """(N, SEARCH_SECTORS * SEARCH_RINGS) the search belief's mass per sector and ring.

    density (N, M) per m^2 at the grid points grid (M, 2) m, each standing for cell_area m^2; agent_mean (N, 2) m
    and heading (N,) rad, the believed pose; searching (N,) bool: some object of the environment is still searched
    (its row is zero otherwise).
    """
    n_envs = density.shape[0]
    delta = grid[None] - np.asarray(agent_mean, float)[:, None]                       # (N, M, 2)
    bearing = np.mod(np.arctan2(delta[..., 1], delta[..., 0]) - np.asarray(heading, float)[:, None]
                     + np.pi / SEARCH_SECTORS, 2 * np.pi)                             # sector 0 centred ahead
    sector = np.minimum((bearing / (2 * np.pi / SEARCH_SECTORS)).astype(int), SEARCH_SECTORS - 1)
    ring = np.searchsorted(np.asarray(RING_EDGES), np.linalg.norm(delta, axis=-1))
    bins = sector * SEARCH_RINGS + ring + np.arange(n_envs)[:, None] * SEARCH_SECTORS * SEARCH_RINGS
    mass = np.bincount(bins.ravel(), (np.asarray(density, float) * cell_area).ravel(),
                       minlength=n_envs * SEARCH_SECTORS * SEARCH_RINGS).reshape(n_envs, -1)
    return (mass * np.asarray(searching, bool)[:, None]).astype(np.float32)
