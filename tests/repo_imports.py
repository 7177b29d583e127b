"""The in-repository import graph of ``mor/`` and ``pipelines/``, read with ``ast`` (nothing is imported).

Used by the layering test and the DVC-dependency test, so that both read imports by one rule: every
``import``/``from ... import`` anywhere in a module (function bodies included, since the code imports lazily),
relative imports resolved, parent packages counted (importing ``mor.data.collect`` runs ``mor/__init__.py`` and
``mor/data/__init__.py``), and entry-point strings such as ``"mor.sim.tasks:PickEnv"`` (Gymnasium's
``register``) counted as imports of their module.
"""

from __future__ import annotations

import ast
from functools import cache
from pathlib import Path

REPO_ROOT: Path = Path(__file__).resolve().parents[1]
#: The top-level packages whose modules make up the graph.
PACKAGES: tuple[str, ...] = ("mor", "pipelines")


@cache
def repo_modules() -> dict[str, Path]:
    """Every module of ``PACKAGES``: dotted name -> its file (a package's file is its ``__init__.py``)."""
    modules: dict[str, Path] = {}
    for package in PACKAGES:
        for path in sorted((REPO_ROOT / package).rglob("*.py")):
            parts = path.relative_to(REPO_ROOT).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            modules[name] = path
    return modules


def _parents(module: str) -> list[str]:
    """``a.b.c`` -> ``[a, a.b]``: the packages Python imports before the module."""
    parts = module.split(".")
    return [".".join(parts[:i]) for i in range(1, len(parts))]


def _resolve(name: str) -> set[str]:
    """The repo modules that importing dotted ``name`` runs (itself if it is one, and its parent packages)."""
    modules = repo_modules()
    return {m for m in (*_parents(name), name) if m in modules}


def imports_of_tree(tree: ast.AST, module: str, is_package: bool = False) -> set[str]:
    """The repo modules that the code in ``tree`` (belonging to ``module``) imports directly."""
    modules = repo_modules()
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                found |= _resolve(alias.name)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base_parts = module.split(".") if is_package else module.split(".")[:-1]
                base_parts = base_parts[: len(base_parts) - (node.level - 1)]
                base = ".".join(base_parts + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            found |= _resolve(base)
            for alias in node.names:  # `from pipelines import sim_oracle` imports the submodule
                if f"{base}.{alias.name}" in modules:
                    found |= _resolve(f"{base}.{alias.name}")
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and ":" in node.value:
            target = node.value.split(":", 1)[0]  # an entry point, "package.module:attribute"
            if target in modules:
                found |= _resolve(target)
    found.discard(module)
    return found


@cache
def direct_imports(module: str) -> frozenset[str]:
    """The repo modules that repo module ``module`` imports directly (anywhere in its file)."""
    path = repo_modules()[module]
    return frozenset(imports_of_tree(ast.parse(path.read_text(), str(path)), module, path.name == "__init__.py"))


def closure(modules: set[str], skip: frozenset[str] = frozenset()) -> set[str]:
    """``modules`` and every repo module they import, transitively (parent packages included); modules in
    ``skip`` are neither included nor followed."""
    seen: set[str] = set()
    todo = [p for m in modules for p in (*_parents(m), m) if p in repo_modules()]
    while todo:
        module = todo.pop()
        if module not in seen and module not in skip:
            seen.add(module)
            todo.extend(direct_imports(module) - seen)
    return seen


def module_file(module: str) -> str:
    """The repository-relative path of a repo module's file, e.g. ``mor/data/collect.py``."""
    return repo_modules()[module].relative_to(REPO_ROOT).as_posix()
