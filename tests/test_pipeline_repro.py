"""``dvc repro`` of the ``tiny`` profile runs end to end in a fresh clone, and leaves ``dvc status`` clean; a dry
run lists every stage's command there.

This is what a user's first ``make repro`` does, with every stage of ``dvc.yaml`` (Tables 3 and 4's settings too) at
toy sizes: a stage whose dep nothing makes, or whose command writes what another profile committed, stops it here
instead of hours into a ``default`` run. About 7 minutes on 2 cores, so it is marked ``pipeline``: a plain
``pytest`` skips it, ``make test`` (and so CI) runs it. The dry run takes seconds and runs everywhere.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import REPO_ROOT

def _run(args: list[str], cwd: Path, env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(args, cwd=cwd, env=env, capture_output=True, text=True, check=False)


def _fresh_clone(tmp_path: Path) -> tuple[Path, dict[str, str]]:
    """A clone of this repository's committed state and the environment that runs this venv's ``dvc`` and ``mor``
    on it."""
    clone = tmp_path / "clone"
    cloned = subprocess.run(["git", "clone", "--quiet", str(REPO_ROOT), str(clone)], capture_output=True, text=True,
                            check=False)
    assert cloned.returncode == 0, cloned.stderr
    bin_dir = Path(sys.executable).parent
    env = {**os.environ, "PATH": f"{bin_dir}{os.pathsep}{os.environ['PATH']}", "PYTHONPATH": str(clone),
           "DVC_NO_ANALYTICS": "1"}
    assert shutil.which("dvc", path=env["PATH"]), "dvc is not installed in this environment (make install)"
    return clone, env


def test_a_dry_run_in_a_fresh_clone_lists_every_stage(tmp_path: Path) -> None:
    """``dvc repro --dry --force`` (the README's command): plain ``--dry`` stops at the first stage whose input an
    earlier stage makes, because DVC's run cache hashes that input (treeverse/dvc#9021); ``--force`` skips the run
    cache, and on a fresh clone every stage is to run anyway."""
    clone, env = _fresh_clone(tmp_path)
    dry = _run(["dvc", "repro", "--dry", "--force"], clone, env)
    assert dry.returncode == 0, f"dvc repro --dry --force failed:\n{dry.stdout[-4000:]}\n{dry.stderr[-4000:]}"
    listed = _run(["dvc", "stage", "list", "--name-only"], clone, env)
    stages = listed.stdout.split()
    assert len(stages) > 20, listed.stdout
    for stage in stages:
        assert f"Running stage '{stage}'" in dry.stdout, f"the dry run does not list stage {stage}"
    assert not (clone / "datasets" / "episodes").exists(), "a dry run wrote outputs"


@pytest.mark.pipeline
def test_dvc_repro_of_the_tiny_profile_runs_end_to_end_in_a_fresh_clone(tmp_path: Path) -> None:
    clone, env = _fresh_clone(tmp_path)
    params = clone / "params.yaml"
    text = params.read_text()
    assert "\nprofile: default\n" in text or text.startswith("profile: default\n"), "params.yaml: no `profile: default`"
    params.write_text(text.replace("profile: default\n", "profile: tiny\n", 1))
    repro = _run(["dvc", "repro"], clone, env)
    assert repro.returncode == 0, f"dvc repro (tiny) failed:\n{repro.stdout[-4000:]}\n{repro.stderr[-4000:]}"
    status = _run(["dvc", "status"], clone, env)
    assert status.returncode == 0 and "changed" not in status.stdout, f"dvc status after repro:\n{status.stdout}"
