"""The search-aware observation: the stated belief's found and lost parts and the search sectors."""

from __future__ import annotations

import numpy as np

from mor.lnet.search import SearchMap
from mor.policy.belief import PoseBelief
from mor.policy.features import feature_names, observation_vector
from mor.policy.search_view import SEARCH_RINGS, SEARCH_SECTORS, sector_masses
from mor.policy.signature import PolicySignature
from mor.policy.variants import VARIANTS
from mor.sim.arena import Arena

ARENA = Arena.build("square", 6.0)


def test_sectors_hold_the_unlooked_mass_around_the_agent() -> None:
    search = SearchMap(ARENA, 2)
    search.update(np.zeros((2, 2)), np.zeros(2))  # both looked straight ahead (+x) from the centre
    masses = sector_masses(search.density(0.9), search.grid, search.cell_area, np.zeros((2, 2)),
                           np.array([0.0, np.pi]), np.array([True, False]))
    assert masses.shape == (2, SEARCH_SECTORS * SEARCH_RINGS)
    assert np.isclose(masses[0].sum(), 1.0) and not masses[1].any()  # nothing searched: all zero
    by_sector = masses[0].reshape(SEARCH_SECTORS, SEARCH_RINGS).sum(1)
    assert by_sector[0] == by_sector.min() and by_sector[0] < 0.05  # ahead: looked at, little mass left
    turned = sector_masses(search.density(0.9), search.grid, search.cell_area, np.zeros((1, 2)), np.array([np.pi]),
                           np.array([True]))[0].reshape(SEARCH_SECTORS, SEARCH_RINGS).sum(1)
    assert np.isclose(turned[SEARCH_SECTORS // 2], by_sector[0], atol=1e-6)  # the same place, now behind


def test_the_truth_states_everything_found_and_only_the_search_variant_reads_it() -> None:
    belief = PoseBelief.from_truth(np.array([[0.0, 0.0, 0.0]]), np.array([[[1.0, 0.0], [0.0, 2.0]]]))
    names = feature_names("pick", 2, True, search=True)
    vector = observation_vector(belief, np.array([2]), "pick", np.array([1]), True, ARENA, search=True)[0]
    found = dict(zip(names, vector, strict=True))
    assert found["object0_found"] == found["goal_found"] == 1.0 and found["object1_lost"] == 0.0
    assert not any(found[name] for name in names if name.startswith("search_"))
    assert len(names) == len(feature_names("pick", 2, True)) + 2 * 2 + 2 + SEARCH_SECTORS * SEARCH_RINGS
    with_search = PolicySignature.of("pick", VARIANTS["lnet_search"], 2, "square", "x").observation
    assert with_search == names and PolicySignature.of("pick", VARIANTS["lnet"], 2, "square", "x").observation == \
        feature_names("pick", 2, True)
