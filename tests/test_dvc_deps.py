"""Every DVC stage lists the code it runs, so that ``dvc repro`` never skips a stage whose code changed.

A stage's code is found from its ``cmd``: ``mor <group> <command> ...`` names a command of the CLI; that command's
function and the module-level imports of the module defining it name the stage's modules (``pipelines/<stage>.py``
and whatever of ``mor/`` it calls directly); the stage needs every file those modules import, transitively (read
with ``ast``, see repo_imports.py). A stage whose ``cmd`` is not a ``mor`` command declares its modules in
``EXPLICIT_STAGE_MODULES``. The CLI modules themselves (argument parsing only) are neither required nor refused,
so that adding a command does not re-run every stage. The test fails when a needed file is not covered by a
listed dep (a file, or a folder above it), and when a listed code dep (under mor/ or pipelines/) covers nothing
the stage needs.
"""

from __future__ import annotations

import ast
import inspect
import textwrap
from collections.abc import Callable
from typing import Any

import pytest
import typer
import yaml
from repo_imports import REPO_ROOT, closure, imports_of_tree, module_file, repo_modules

from pipelines.cli import app

#: stage name -> its modules, for stages whose cmd is not a `mor` command.
EXPLICIT_STAGE_MODULES: dict[str, set[str]] = {}
CODE_ROOTS: tuple[str, ...] = ("mor", "pipelines")


def _commands(group: typer.Typer, path: tuple[str, ...] = ()) -> dict[tuple[str, ...], Callable[..., Any]]:
    """Every command of ``group``: its words (``("sim", "oracle")``) -> the function that runs it."""
    found = {(*path, info.name or info.callback.__name__): info.callback for info in group.registered_commands}
    for sub in group.registered_groups:
        found |= _commands(sub.typer_instance, (*path, sub.name))
    return found


COMMANDS = _commands(app)
#: The modules that define commands: argument parsing, not stage logic.
CLI_MODULES: frozenset[str] = frozenset({"pipelines.cli", *(f.__module__ for f in COMMANDS.values())})


def _stages() -> dict[str, dict[str, Any]]:
    """dvc.yaml's stages (a ``foreach``/``matrix`` stage once, by its template)."""
    stages = yaml.safe_load((REPO_ROOT / "dvc.yaml").read_text())["stages"]
    return {name: body.get("do", body) for name, body in stages.items()}


def _words(cmd: str) -> list[str]:
    """A ``mor`` command's words without the root option ``--setting NAME`` (which runs pipelines.settings)."""
    words = cmd.split()
    return words[:1] + words[3:] if words[1:2] == ["--setting"] else words


def _command_of(cmd: str) -> Callable[..., Any] | None:
    """The CLI function that a stage's ``cmd`` runs, or None when it is not a ``mor`` command."""
    words = _words(cmd)
    if not words or words[0] != "mor":
        return None
    for length in range(len(words) - 1, 0, -1):
        if tuple(words[1:1 + length]) in COMMANDS:
            return COMMANDS[tuple(words[1:1 + length])]
    raise AssertionError(f"dvc.yaml cmd {cmd!r}: no such mor command")


def _module_level_imports(module: str) -> set[str]:
    """The repo modules that ``module`` imports at its top level (not inside functions)."""
    path = repo_modules()[module]
    top = [node for node in ast.parse(path.read_text()).body if isinstance(node, ast.Import | ast.ImportFrom)]
    return imports_of_tree(ast.Module(body=top, type_ignores=[]), module)


def stage_modules(name: str, stage: dict[str, Any]) -> set[str]:
    """The modules a stage runs directly: what its command imports (or EXPLICIT_STAGE_MODULES), CLI excluded."""
    if name in EXPLICIT_STAGE_MODULES:
        return EXPLICIT_STAGE_MODULES[name]
    function = _command_of(stage["cmd"])
    assert function is not None, f"stage {name}: cmd is not a mor command; declare its modules in EXPLICIT_STAGE_MODULES"
    body = ast.parse(textwrap.dedent(inspect.getsource(function)))
    setting = {"pipelines.settings"} if "--setting" in stage["cmd"].split()[1:2] else set()
    return (imports_of_tree(body, function.__module__) | _module_level_imports(function.__module__) | setting
            ) - CLI_MODULES


def required_files(name: str, stage: dict[str, Any]) -> set[str]:
    """Every repo file the stage's code imports, transitively."""
    return {module_file(m) for m in closure(stage_modules(name, stage), skip=CLI_MODULES)}


def _covers(dep: str, file: str) -> bool:
    dep = dep.rstrip("/")
    return file == dep or file.startswith(dep + "/")


def _code_deps(stage: dict[str, Any]) -> list[str]:
    deps = [next(iter(d)) if isinstance(d, dict) else d for d in stage.get("deps", [])]
    return [d for d in deps if d.split("/")[0] in CODE_ROOTS]


STAGES = _stages()


@pytest.mark.parametrize("name", sorted(STAGES))
def test_stage_lists_every_file_its_code_imports(name: str) -> None:
    stage = STAGES[name]
    deps = _code_deps(stage)
    missing = sorted(f for f in required_files(name, stage) if not any(_covers(d, f) for d in deps))
    assert not missing, f"dvc.yaml stage {name}: add these deps (files its code imports; a folder is fine): {missing}"


@pytest.mark.parametrize("name", sorted(STAGES))
def test_stage_lists_no_code_it_does_not_run(name: str) -> None:
    stage = STAGES[name]
    needed = required_files(name, stage) | {module_file(m) for m in CLI_MODULES}
    stale = [d for d in _code_deps(stage) if not any(_covers(d, f) for f in needed)]
    assert not stale, f"dvc.yaml stage {name}: these code deps are not imported by its command, remove them: {stale}"
    absent = [d for d in _code_deps(stage) if not (REPO_ROOT / d).exists()]
    assert not absent, f"dvc.yaml stage {name}: these deps do not exist: {absent}"


def test_the_rule_finds_a_stage_module_and_what_it_imports() -> None:
    """The oracle stage runs pipelines/sim_oracle.py, which imports mor/config.py (so the test above can fail)."""
    files = required_files("oracle", {"cmd": "mor sim oracle --out x.json"})
    assert {"pipelines/sim_oracle.py", "mor/config.py", "mor/__init__.py"} <= files
    assert "pipelines/cli.py" not in files
    assert not _covers("mor/sim", "mor/simulation.py") and _covers("mor/sim/", "mor/sim/env.py")


def _tracked() -> set[str]:
    import subprocess

    listed = subprocess.run(["git", "ls-files"], cwd=REPO_ROOT, capture_output=True, text=True, check=True).stdout
    return set(listed.splitlines())


def _outputs(stage: dict[str, Any]) -> list[str]:
    """A stage's outs, metrics and plots, as paths."""
    found = []
    for key in ("outs", "metrics", "plots"):
        for item in stage.get(key) or []:
            found.append(next(iter(item)) if isinstance(item, dict) else item)
    return found


def test_every_dep_is_committed_or_made_by_another_stage() -> None:
    """A fresh clone's `dvc repro` finds every dep: a committed file or folder, or another stage's output."""
    stages, tracked = _stages(), _tracked()
    made = {out: name for name, stage in stages.items() for out in _outputs(stage)}
    for name, stage in stages.items():
        for dep in stage.get("deps") or []:
            committed = dep in tracked or any(path.startswith(dep.rstrip("/") + "/") for path in tracked)
            producer = made.get(dep) or next((made[out] for out in made if dep.startswith(out.rstrip("/") + "/")),
                                             None)
            assert committed or (producer is not None and producer != name), (
                f"dvc.yaml stage {name}: dep {dep} is neither committed nor an output of another stage")
