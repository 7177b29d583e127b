"""What a policy knows of the world at one step: a Gaussian belief over the agent's and the objects' poses, and
what the L-Net states beyond it (which objects it has not found, which it may have lost, where it has not looked).

Every pose variant (``mor.policy.variants``) reads the same belief: the ground truth's variant fills it from the
simulator's truth (zero covariances, zero heading variance), the L-Net variants from the L-Net's estimates. The observation
layout built from it is in ``mor.policy.features``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

Float = NDArray[np.float32]


@dataclass(frozen=True)
class SearchBelief:
    """Where N environments' unfound objects may be (``mor.lnet.search``), on one grid shared by all of them.

    density (N, M) per m² at grid (M, 2) m, each point standing for cell_area m²; searching (N,) bool: the
    environment still searches some object (the policy's view of it is all zero otherwise).
    """

    density: NDArray
    grid: NDArray
    cell_area: float
    searching: NDArray

    def take(self, index: NDArray) -> SearchBelief:
        """The search belief of the environments ``index`` (the grid is shared)."""
        return replace(self, density=self.density[index], searching=self.searching[index])


@dataclass(frozen=True)
class PoseBelief:
    """A belief for N environments with n objects each. World frame, metres and radians, float32.

    agent_mean (N, 2); agent_cov (N, 2, 2) m²; heading (N,) rad; heading_var (N,) rad² (1/κ of the von Mises,
    0 for the truth); object_mean (N, n, 2) (a held object sits at the agent); object_cov (N, n, 2, 2) m².
    The stated belief's parts (``mor.lnet.stated``; None where the source states none, as the truth):
    object_found (N, n) 1.0 where the belief has found its object, 0.0 where it is still the search belief;
    object_lost (N, n) the probability that the object is not where its Gaussian says; search: where the objects
    not found yet may be (``SearchBelief``; a policy reads it through ``mor.policy.search_view``).
    object_visible (N, n): the probability that each object is in view on this frame, by the L-Net's own detection
    (``mor.lnet.stated.Estimates.object_visible``; None where the source gives none, as the truth).
    """

    agent_mean: Float
    agent_cov: Float
    heading: Float
    heading_var: Float
    object_mean: Float
    object_cov: Float
    object_found: Float | None = None
    object_lost: Float | None = None
    object_visible: Float | None = None
    search: SearchBelief | None = None

    @property
    def n_envs(self) -> int:
        return int(self.agent_mean.shape[0])

    @property
    def n_objects(self) -> int:
        return int(self.object_mean.shape[1])

    @classmethod
    def from_truth(cls, agent_poses: NDArray, object_positions: NDArray) -> PoseBelief:
        """agent_poses (N, 3) [x, y, θ]; object_positions (N, n, 2): a belief with zero uncertainty."""
        agent = np.asarray(agent_poses, np.float32).reshape(-1, 3)
        objects = np.asarray(object_positions, np.float32).reshape(agent.shape[0], -1, 2)
        n_envs, n_objects = objects.shape[:2]
        return cls(
            agent_mean=agent[:, :2].copy(),
            agent_cov=np.zeros((n_envs, 2, 2), np.float32),
            heading=agent[:, 2].copy(),
            heading_var=np.zeros(n_envs, np.float32),
            object_mean=objects.copy(),
            object_cov=np.zeros((n_envs, n_objects, 2, 2), np.float32),
        )

    def take(self, index: NDArray | int) -> PoseBelief:
        """The belief of the environments ``index`` (an int keeps a batch of one)."""
        index = np.atleast_1d(index)
        return PoseBelief(*(None if getattr(self, name) is None else getattr(self, name)[index]
                            for name in self.__dataclass_fields__ if name != "search"),
                          search=None if self.search is None else self.search.take(index))
