"""The search-aware observation: the stated belief's found and lost parts and the search sectors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from mor.errors import ConfigError
from mor.lnet.search import SearchMap
from mor.policy.belief import PoseBelief, SearchBelief
from mor.policy.features import ObservationLayout, feature_names, observation_vector
from mor.policy.params import ObservationParams
from mor.policy.search_view import sector_count, sector_masses
from mor.policy.signature import PolicySignature, check_signature, warm_start_names, write_signature
from mor.policy.variants import VARIANTS
from mor.sim.arena import Arena

ARENA = Arena.build("square", 6.0)
DEFAULTS = ObservationParams()
SECTORS, EDGES = DEFAULTS.search_sectors, DEFAULTS.search_ring_edges_m


def _looked_ahead(n_envs: int, searching: list[bool]) -> SearchBelief:
    """Each of n_envs looked once straight ahead (+x) from the centre."""
    search = SearchMap(ARENA, n_envs, 64, 0.1)  # the default looks cap and grid spacing
    search.update(np.zeros((n_envs, 2)), np.zeros(n_envs))
    return SearchBelief(search.density(0.9), search.grid, search.cell_area, np.array(searching))


def test_sectors_hold_the_unlooked_mass_around_the_agent() -> None:
    looked = _looked_ahead(2, [True, False])
    masses = sector_masses(looked, np.zeros((2, 2)), np.array([0.0, np.pi]), SECTORS, EDGES)
    assert masses.shape == (2, sector_count(SECTORS, EDGES)) == (2, 16)
    assert np.isclose(masses[0].sum(), 1.0) and not masses[1].any()  # nothing searched: all zero
    by_sector = masses[0].reshape(SECTORS, -1).sum(1)
    assert by_sector[0] == by_sector.min() and by_sector[0] < 0.05  # ahead: looked at, little mass left
    turned = sector_masses(looked.take(np.array([0])), np.zeros((1, 2)), np.array([np.pi]), SECTORS,
                           EDGES)[0].reshape(SECTORS, -1).sum(1)
    assert np.isclose(turned[SECTORS // 2], by_sector[0], atol=1e-6)  # the same place, now behind


def test_the_sectors_and_rings_are_the_profiles_settings() -> None:
    """policy.observation's sectors and ring edges shape and name the search entries."""
    settings = ObservationParams(search_sectors=4, search_ring_edges_m=[0.5, 2.0])
    layout = ObservationLayout(search=True, features=settings)
    names = [name for name in feature_names("drop", 2, layout) if name.startswith("search_")]
    assert len(names) == sector_count(4, [0.5, 2.0]) == 12
    assert names[:3] == ["search_+0deg_within0.5m", "search_+0deg_within2m", "search_+0deg_beyond2m"]
    belief = PoseBelief.from_truth(np.zeros((1, 3)), np.array([[[1.0, 0.0], [0.0, 2.0]]]))
    searched = PoseBelief(*(getattr(belief, f) for f in ("agent_mean", "agent_cov", "heading", "heading_var",
                                                         "object_mean", "object_cov")),
                          search=_looked_ahead(1, [True]))
    vector = observation_vector(searched, np.array([2]), "drop", np.array([[1.0, 1.0]]), layout, ARENA)[0]
    assert np.isclose(vector[-12:].sum(), 1.0)
    with pytest.raises(ValueError, match="increasing"):
        ObservationParams(search_ring_edges_m=[2.0, 1.0])


def test_the_truth_states_everything_found_and_only_the_search_variant_reads_it() -> None:
    belief = PoseBelief.from_truth(np.array([[0.0, 0.0, 0.0]]), np.array([[[1.0, 0.0], [0.0, 2.0]]]))
    layout = ObservationLayout(search=True)
    names = feature_names("pick", 2, layout)
    vector = observation_vector(belief, np.array([2]), "pick", np.array([1]), layout, ARENA)[0]
    found = dict(zip(names, vector, strict=True))
    assert found["object0_found"] == found["goal_found"] == 1.0 and found["object1_lost"] == 0.0
    assert not any(found[name] for name in names if name.startswith("search_"))
    assert len(names) == len(feature_names("pick", 2, ObservationLayout())) + 2 * 2 + 2 + sector_count(SECTORS, EDGES)
    with_search = PolicySignature.of("pick", VARIANTS["lnet_search"], 2, "square", "x", DEFAULTS).observation
    assert with_search == names
    assert PolicySignature.of("pick", VARIANTS["lnet"], 2, "square", "x", DEFAULTS).observation == \
        feature_names("pick", 2, ObservationLayout())


def test_a_policy_trained_with_other_observation_settings_is_refused_by_name(tmp_path) -> None:
    """A cut the rays' names do not show is still checked: the signature holds the settings. A meta.json from
    before they were settings reads as their defaults."""
    path = tmp_path / "meta.json"
    write_signature(path, PolicySignature.of("pick", VARIANTS["lnet"], 2, "square", "x", DEFAULTS))
    other = ObservationParams(clearance_max_m=2.0)
    with pytest.raises(ConfigError, match=r"policy\.observation\.clearance_max_m=3\.0 but this run needs 2\.0"):
        check_signature(path, PolicySignature.of("pick", VARIANTS["lnet"], 2, "square", "x", other))
    older = PolicySignature.of("pick", VARIANTS["lnet"], 2, "square", "x", DEFAULTS).model_dump(exclude={"features"})
    path.write_text(json.dumps(older))
    check_signature(path, PolicySignature.of("pick", VARIANTS["lnet"], 2, "square", "x", DEFAULTS))


def test_a_setting_a_layout_does_not_read_refuses_none_of_its_policies(tmp_path) -> None:
    """Other search sectors leave every policy without the stated belief loadable, and refuse lnet_search's."""
    path, other = tmp_path / "meta.json", ObservationParams(search_sectors=4)
    for variant, refused in (("lnet", False), ("lnet_search", True)):
        write_signature(path, PolicySignature.of("pick", VARIANTS[variant], 2, "square", "x", DEFAULTS))
        expected = PolicySignature.of("pick", VARIANTS[variant], 2, "square", "x", other)
        if refused:
            with pytest.raises(ConfigError, match=r"policy\.observation\.search_sectors=8 but this run needs 4"):
                check_signature(path, expected)
        else:
            check_signature(path, expected)


def test_a_warm_start_from_a_policy_with_other_shared_settings_is_refused(tmp_path) -> None:
    """gt_pose's policy starts lnet_search's whatever the search sectors (gt_pose reads none), not across a cut."""
    path = tmp_path / "meta.json"
    write_signature(path, PolicySignature.of("pick", VARIANTS["gt_pose"], 2, "square", None, DEFAULTS))
    sectors = PolicySignature.of("pick", VARIANTS["lnet_search"], 2, "square", "x", ObservationParams(search_sectors=4))
    assert warm_start_names(path, sectors) == feature_names("pick", 2, ObservationLayout())
    cut = PolicySignature.of("pick", VARIANTS["lnet"], 2, "square", "x", ObservationParams(clearance_max_m=2.0))
    with pytest.raises(ConfigError, match=r"policy\.observation\.clearance_max_m=3\.0 but this run needs 2\.0"):
        warm_start_names(path, cut)


@pytest.mark.parametrize("settings", [{"clearance_rays_deg": [10.2, 10.4]}, {"search_sectors": 7},
                                      {"search_ring_edges_m": [0.0]}])
def test_settings_that_would_misname_a_feature_are_refused(settings) -> None:
    with pytest.raises(ValueError, match="clearance rays|search sectors|search ring edges"):
        ObservationParams(**settings)


def test_a_policy_that_reads_the_stated_belief_is_refused_under_another_calibration_of_it(tmp_path) -> None:
    """The L-Net identity leaves the stated belief's parameters out; lnet_search records them apart, lnet does not."""
    from mor.lnet.calibration_file import FittedCalibration  # noqa: PLC0415
    from mor.lnet.runtime import stated_identity  # noqa: PLC0415
    from mor.lnet.stated import StatedParams  # noqa: PLC0415

    fitted, refitted = FittedCalibration(), FittedCalibration(stated=StatedParams(search_find=0.3))
    assert stated_identity(fitted) != stated_identity(refitted)
    path = tmp_path / "meta.json"
    for variant, refused in (("lnet", False), ("lnet_search", True)):
        write_signature(path, PolicySignature.of("pick", VARIANTS[variant], 2, "square", "x", DEFAULTS,
                                                 stated_identity(fitted)))
        expected = PolicySignature.of("pick", VARIANTS[variant], 2, "square", "x", DEFAULTS, stated_identity(refitted))
        if refused:
            with pytest.raises(ConfigError, match=r"trained with stated_version="):
                check_signature(path, expected)
        else:
            check_signature(path, expected)
