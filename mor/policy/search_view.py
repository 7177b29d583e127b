"""The policy's compact view of the search belief: where the L-Net has not looked yet, around the agent.

The search belief (``mor.lnet.search``) is a density over the arena grid, shared by every object the L-Net has not
found yet (each is, as far as the L-Net knows, anywhere it has not looked). A policy reads its mass in ``sectors``
bearing sectors of equal width around the agent's believed heading (sector 0 straight ahead, counter-clockwise),
each split into range rings at ``ring_edges`` (default: within PICK's reach, beyond): a vector that sums to 1
while something is searched, and is all zero when every object is found. The settings are ``policy.observation``
(``mor.policy.params.ObservationParams``).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from mor.policy.belief import SearchBelief


def sector_names(sectors: int, ring_edges: Sequence[float]) -> list[str]:
    """The name of each entry of ``sector_masses``' output, in order."""
    width = 360 // sectors
    rings = [f"within{edge:g}m" for edge in ring_edges] + [f"beyond{ring_edges[-1]:g}m"]
    return [f"search_{s * width:+d}deg_{ring}" for s in range(sectors) for ring in rings]


def sector_count(sectors: int, ring_edges: Sequence[float]) -> int:
    """The length of ``sector_masses``' rows: sectors x (len(ring_edges) + 1) rings."""
    return sectors * (len(ring_edges) + 1)


def sector_masses(search: SearchBelief, agent_mean: NDArray, heading: NDArray, sectors: int,
                  ring_edges: Sequence[float]) -> NDArray[np.float32]:
    """(N, sectors x rings) the search belief's mass per bearing sector and range ring, rings innermost.

    agent_mean (N, 2) m and heading (N,) rad, the believed pose; ring_edges (R,) m, increasing: the rings' outer
    radii (a last ring beyond them). A row is zero where the environment searches nothing (``search.searching``).
    """
    n_envs, rings = search.density.shape[0], len(ring_edges) + 1
    delta = search.grid[None] - np.asarray(agent_mean, float)[:, None]                # (N, M, 2)
    bearing = np.mod(np.arctan2(delta[..., 1], delta[..., 0]) - np.asarray(heading, float)[:, None]
                     + np.pi / sectors, 2 * np.pi)                                    # sector 0 centred ahead
    sector = np.minimum((bearing / (2 * np.pi / sectors)).astype(int), sectors - 1)
    ring = np.searchsorted(np.asarray(ring_edges, float), np.linalg.norm(delta, axis=-1))
    bins = sector * rings + ring + np.arange(n_envs)[:, None] * sectors * rings
    mass = np.bincount(bins.ravel(), (np.asarray(search.density, float) * search.cell_area).ravel(),
                       minlength=n_envs * sectors * rings).reshape(n_envs, -1)
    return (mass * np.asarray(search.searching, bool)[:, None]).astype(np.float32)
