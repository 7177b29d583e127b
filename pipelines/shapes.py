"""The data shape of a profile: what collect writes and what build-dataset and validate check episode files
against (shared wiring, not a stage)."""

from __future__ import annotations

from mor.config import PROFILES, Profile, load_profile
from mor.data.collect import CollectionSpec, ProfileShape
from mor.errors import ConfigError


def collection_spec(profile: Profile) -> CollectionSpec:
    """The collection parameters of ``profile``."""
    params = profile.collect
    return CollectionSpec(profile.sim, params.exploration, params.seed, params.episode_steps, params.fps)


def profile_shape(profile: Profile) -> ProfileShape:
    """``profile``'s data-shaping params, named after the params.yaml profile equal to it (for messages), with the
    other named profiles' (to suggest the one a mismatched file was made with)."""
    named = {}
    for name in PROFILES:
        try:
            named[name] = load_profile(name)
        except ConfigError:
            continue
    own = next((name for name, other in named.items() if other == profile), "")
    return ProfileShape(collection_spec(profile), own, tuple((n, collection_spec(p)) for n, p in named.items()))
