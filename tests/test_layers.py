"""The layering of docs/design.md: data flows sim -> data -> lnet -> policy -> eval -> robot, and nothing in ``mor/``
imports ``pipelines/`` (the wiring, the command line included, sits above the library)."""

from __future__ import annotations

import ast

import pytest
from repo_imports import direct_imports, imports_of_tree, repo_modules

#: The library's layers, lowest first; a module may import only its own layer and lower ones.
LAYERS: tuple[str, ...] = ("sim", "data", "lnet", "policy", "eval", "robot")


def _layer(module: str) -> int | None:
    parts = module.split(".")
    return LAYERS.index(parts[1]) if parts[0] == "mor" and len(parts) > 1 and parts[1] in LAYERS else None


LIBRARY = sorted(m for m in repo_modules() if m.split(".")[0] == "mor")


@pytest.mark.parametrize("module", LIBRARY)
def test_library_does_not_import_pipelines(module: str) -> None:
    upward = sorted(m for m in direct_imports(module) if m.split(".")[0] == "pipelines")
    assert not upward, f"{module} imports {upward}: mor/ must not depend on pipelines/ (move the code down)"


@pytest.mark.parametrize("module", [m for m in LIBRARY if _layer(m) is not None])
def test_no_layer_imports_a_higher_one(module: str) -> None:
    own = _layer(module)
    higher = sorted(m for m in direct_imports(module) if (_layer(m) is not None and _layer(m) > own))
    assert not higher, f"{module} (layer {LAYERS[own]}) imports higher layers: {higher}"


def test_the_rule_catches_a_pipelines_import() -> None:
    """The import reader sees lazy, aliased and relative imports, so the tests above can fail."""
    code = "def f():\n    from pipelines import paths\n    import pipelines.io as io\n"
    assert imports_of_tree(ast.parse(code), "mor.sim.env") >= {"pipelines", "pipelines.paths", "pipelines.io"}
    relative = imports_of_tree(ast.parse("from ..data import collect\n"), "mor.sim.env")
    assert "mor.data.collect" in relative


#: pipelines/ modules that are shared wiring or the command line, not stages (any stage may import them)
PIPELINE_HELPERS = frozenset({"pipelines", "pipelines.paths", "pipelines.io", "pipelines.lnet_io", "pipelines.workspaces",
                              "pipelines.shapes",
                              "pipelines.settings", "pipelines.compute", "pipelines.cli", "pipelines.cli_policy",
                              "pipelines.cli_robot"})
STAGES = sorted(m for m in repo_modules() if m.split(".")[0] == "pipelines" and m not in PIPELINE_HELPERS)


@pytest.mark.parametrize("module", STAGES)
def test_no_stage_module_imports_another(module: str) -> None:
    others = sorted(m for m in direct_imports(module) if m in STAGES and m != module)
    assert not others, f"{module} imports the stage modules {others}: move what they share to a helper module"


def test_a_variants_name_is_written_in_at_most_three_files() -> None:
    """Each variant is defined once (``mor.policy.variants``); besides it, only the methods (``mor.eval.methods``) and
    the paper's tables (``mor.eval.tables``, which name their rows) may spell a variant's name; everything else asks
    the variant. ("lnet" is left out: it also names the L-Net, its pose source and its stages.)"""
    import re
    from pathlib import Path

    from mor.policy.variants import VARIANTS

    root = Path(__file__).resolve().parents[1]
    files = [*root.glob("mor/**/*.py"), *root.glob("pipelines/**/*.py")]
    for name in (name for name in VARIANTS if name != "lnet"):
        spelled = sorted(p.relative_to(root).as_posix() for p in files if re.search(rf"\b{name}\b", p.read_text()))
        assert len(spelled) <= 3, f"{name} is written in {spelled}: ask mor.policy.variants instead"
