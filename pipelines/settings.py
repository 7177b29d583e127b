"""Settings: the paper's other worlds (Table 3's polygon arena, Table 4's 1 to 5 objects) as workspaces.

``mor --setting NAME <command>`` runs any stage in ``settings/NAME/``: a workspace with the same layout as the
repository root (``datasets/``, ``cards/``) whose ``params.yaml`` is the root's with ``settings.NAME`` merged into
every profile (written on entry, never edited by hand). The stages' code is unchanged; what a setting reuses from
the main workspace (its L-Net, its policies to fine-tune or to play zero-shot) is ``Profile.setting`` and
``pipelines.paths.MAIN``.
"""

from __future__ import annotations

import os
from pathlib import Path

import yaml

from mor.atomic import atomic_output
from mor.config import DEFAULT_PARAMS, Profile, setting_document, validated
from pipelines import paths

HEADER = "# Written by `mor --setting {name}` from ../../params.yaml (settings.{name}); edit that file, not this.\n"


def workspace(name: str) -> Path:
    """Where setting ``name``'s stages run: ``settings/<name>/``."""
    return paths.SETTINGS / name


def enter(name: str, params: Path = DEFAULT_PARAMS) -> Path:
    """Write ``settings/<name>/params.yaml`` from ``params`` (ConfigError if there is no such setting) and make
    that workspace the current directory; returns the folder that was current before."""
    document = setting_document(params, name)
    folder = workspace(name)
    folder.mkdir(parents=True, exist_ok=True)
    with atomic_output(folder / "params.yaml") as partial:
        partial.write_text(HEADER.format(name=name) + yaml.safe_dump(document, sort_keys=False))
    previous = Path.cwd()
    os.chdir(folder)
    return previous


def setting_profile(name: str, profile_name: str, params: Path = DEFAULT_PARAMS) -> Profile:
    """Profile ``profile_name`` as setting ``name``'s workspace sees it (read from the root's ``params``)."""
    document = setting_document(params, name)
    return validated(Profile, f"{params}: settings.{name} (profiles.{profile_name})",
                     **(document["profiles"][profile_name] or {}))

