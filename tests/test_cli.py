"""The stage contracts of the ``mor`` command line, run on the ``tiny`` profile from the repository root."""

from __future__ import annotations

import json
import re
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest
import typer
import yaml
from PIL import Image
from typer.testing import CliRunner

from pipelines.cli import app

TASKS = ("pick", "drop", "rearrange")


@pytest.fixture
def cli(repo_root: Path, monkeypatch: pytest.MonkeyPatch):
    """``cli(*args)``: run ``mor *args`` from the repository root; fail with the output if it exits non-zero."""
    monkeypatch.chdir(repo_root)
    runner = CliRunner()

    def invoke(*args: str):
        result = runner.invoke(app, list(args))
        assert result.exit_code == 0, f"exit {result.exit_code}: {result.output}\n{result.exception!r}"
        return result

    return invoke


def test_oracle_writes_metrics_json(cli, tmp_path: Path) -> None:
    out = tmp_path / "tmp" / "metrics.json"
    result = cli("sim", "oracle", "--profile", "tiny", "--episodes", "1", "--seeds", "0", "--out", str(out))
    payload = json.loads(out.read_text())
    assert set(payload["tasks"]) == set(TASKS)
    for task in TASKS:
        entry = payload["tasks"][task]
        assert entry["policy"] == "oracle" and entry["episodes_per_seed"] == 1 and entry["seeds"] == [0]
        assert entry["env_kwargs"]["image_size"] == 32 and entry["env_kwargs"]["n_objects"] == 3
        summary = entry["summary"]
        assert {"success", "steps"} <= set(summary)
        for name, stats in summary.items():
            assert set(stats) == {"mean", "std"}, name
            assert stats["std"] == 0.0  # one seed
        assert 0.0 <= summary["success"]["mean"] <= 1.0
    assert {"fixed_strict", "energy_remaining"} <= set(payload["tasks"]["rearrange"]["summary"])
    assert f"wrote {out}" in result.stdout
    assert not list(out.parent.glob("*.partial*"))


def test_oracle_single_task(cli, tmp_path: Path) -> None:
    out = tmp_path / "m.json"
    cli("sim", "oracle", "--profile", "tiny", "--task", "drop", "--episodes", "1", "--seeds", "3", "--out", str(out))
    payload = json.loads(out.read_text())
    assert list(payload["tasks"]) == ["drop"]
    assert payload["tasks"]["drop"]["seeds"] == [3]


def test_render_writes_two_pngs(cli, tmp_path: Path) -> None:
    result = cli("sim", "render", "--profile", "tiny", "--task", "drop", "--seed", "2", "--out-dir", str(tmp_path))
    pngs = sorted(tmp_path.glob("*.png"))
    assert [p.name for p in pngs] == ["drop_seed2_first_person.png", "drop_seed2_top_down.png"]
    first_person, top_down = (Image.open(p) for p in pngs)
    assert first_person.size == (32, 32) and first_person.mode == "RGB"
    assert top_down.size == (256, 256) and top_down.mode == "RGB"
    assert np.asarray(first_person).std() > 0
    assert result.stdout.count("wrote ") == 2


def test_video_writes_a_gif(cli, tmp_path: Path) -> None:
    out = tmp_path / "tmp" / "x.gif"
    result = cli("sim", "video", "--profile", "tiny", "--out", str(out))
    frames = iio.imread(out, index=None)
    assert frames.ndim == 4 and frames.shape[0] >= 2
    assert frames.shape[1:3] == (256, 516)  # first-person scaled to 256 beside the 256 top-down view
    assert "steps" in result.stdout and str(out) in result.stdout


def test_video_random_policy_other_task(cli, tmp_path: Path) -> None:
    out = tmp_path / "r.gif"
    cli("sim", "video", "--profile", "tiny", "--task", "drop", "--policy", "random", "--seed", "1", "--out", str(out))
    assert iio.imread(out, index=None).shape[0] >= 2


def test_demo_writes_pngs_and_mp4(cli, tmp_path: Path) -> None:
    result = cli("sim", "demo", "--profile", "tiny", "--out-dir", str(tmp_path))
    names = sorted(p.name for p in tmp_path.iterdir())
    # tiny profile: demo task pick, seed 0, oracle policy
    assert names == ["pick_seed0_first_person.png", "pick_seed0_oracle.mp4", "pick_seed0_top_down.png"]
    mp4 = tmp_path / "pick_seed0_oracle.mp4"
    assert mp4.read_bytes()[4:8] == b"ftyp"
    frames = iio.imread(mp4, index=None, plugin="pyav")
    assert frames.shape[0] >= 2 and frames.shape[1:] == (256, 516, 3)
    assert result.stdout.count("wrote ") == 3


def test_help_lists_the_commands(cli) -> None:
    result = cli("sim", "--help")
    for command in ("oracle", "render", "video", "demo"):
        assert command in result.stdout


def test_the_ablation_help_names_every_study(cli) -> None:
    from mor.lnet.params import ABLATIONS  # noqa: PLC0415

    words = set(re.findall(r"\w+", cli("ablate-lnet", "--help").stdout))  # rich wraps and boxes the text
    assert set(ABLATIONS) <= words


# ---- the active profile: `profile:` in params.yaml, unless --profile says otherwise ------------------------------
def _params_with_profile(repo_root: Path, tmp_path: Path, name: str) -> Path:
    document = yaml.safe_load((repo_root / "params.yaml").read_text())
    path = tmp_path / "params.yaml"
    path.write_text(yaml.safe_dump({**document, "profile": name}))
    return path


def test_profile_prints_the_active_profile(cli, repo_root: Path, tmp_path: Path) -> None:
    params = _params_with_profile(repo_root, tmp_path, "tiny")
    shown = yaml.safe_load(cli("profile", "--params", str(params)).stdout)
    assert shown["profile"] == "tiny"
    assert shown["params"]["sim"]["image_size"] == 32 and shown["params"]["collect"]["episode_steps"] == 30
    assert "exploration" in shown["params"]["collect"]  # resolved: defaults filled in
    overridden = yaml.safe_load(cli("profile", "--params", str(params), "--profile", "default").stdout)
    assert overridden["profile"] == "default" and overridden["params"]["sim"]["image_size"] == 64


def test_commands_use_the_profile_of_params_yaml(cli, repo_root: Path, tmp_path: Path) -> None:
    params = _params_with_profile(repo_root, tmp_path, "tiny")
    cli("sim", "render", "--params", str(params), "--out-dir", str(tmp_path / "out"))
    assert Image.open(tmp_path / "out" / "rearrange_seed0_first_person.png").size == (32, 32)  # tiny: 32 px


def test_every_profile_option_defaults_to_params_yaml() -> None:
    """No command carries its own default profile: --profile left out means params.yaml's `profile:`."""

    def walk(command, path=()):
        for name, sub in (getattr(command, "commands", None) or {}).items():
            yield from walk(sub, (*path, name))
        yield from ((" ".join(path), p) for p in command.params if p.name == "profile")

    own = [(name, param.default) for name, param in walk(typer.main.get_command(app)) if param.default is not None]
    assert not own, f"these commands default --profile to a name instead of params.yaml's profile: {own}"
