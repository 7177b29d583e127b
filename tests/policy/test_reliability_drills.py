"""Reliability drills of policy training and loading: a run killed (SIGKILL) at a checkpoint or at a random step
and started again ends exactly as the uninterrupted run; a crafted file that would run code when unpickled is
refused in one line and runs nothing; a damaged file names itself."""

from __future__ import annotations

import csv
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import torch

from mor.errors import MorError
from mor.policy.hierarchy import Skill
from mor.policy.params import ObservationParams
from mor.policy.policy_file import load_policy_file, save_policy_file
from mor.policy.train import CHECKPOINT_FILE
from mor.policy.variants import VARIANTS
from mor.tensor_files import UnsafeFile

FEATURES = ObservationParams()  # the default policy.observation settings

CHILD = textwrap.dedent("""
    import os, signal, sys
    from pathlib import Path
    import mor.policy.train as train
    from mor.policy.envs import make_training_env
    from mor.policy.hierarchy import Skill
    from mor.policy.params import ObservationParams, PPOParams
    from mor.policy.signature import PolicySignature
    from mor.policy.variants import VARIANTS
    from mor.sim.config import SimConfig

    task, out, kill, skills_dir = sys.argv[1], Path(sys.argv[2]), sys.argv[3], sys.argv[4]
    sim = SimConfig(n_objects=2, image_size=16)
    params = PPOParams(steps=192, n_envs=2, n_steps=16, batch_size=16, n_epochs=2, hidden=[16, 16],
                       checkpoint_every=64) if task == "pick" else PPOParams(
                       steps=24, n_envs=2, n_steps=4, batch_size=8, n_epochs=2, hidden=[16, 16], checkpoint_every=8)
    skills = None if task == "pick" else tuple(Skill.load(Path(skills_dir) / f"{name}.pth", False)
                                               for name in ("pick", "drop"))
    if kill == "checkpoint":  # right after the first checkpoint is written
        save = train.save_checkpoint
        def save_then_die(*args):
            save(*args)
            os.kill(os.getpid(), signal.SIGKILL)
        train.save_checkpoint = save_then_die
    elif kill.startswith("step"):  # in the middle of a rollout
        at, step = int(kill[4:]), train.TrainingMonitor._on_step
        def step_then_die(self):
            if self.num_timesteps >= at:
                os.kill(os.getpid(), signal.SIGKILL)
            return step(self)
        train.TrainingMonitor._on_step = step_then_die
    features = ObservationParams()
    train.train_policy(lambda: make_training_env(task, VARIANTS["gt_pose"], sim, params, features, skills=skills),
                       params, PolicySignature.of(task, VARIANTS["gt_pose"], 2, "square", None, features), out, 0,
                       "drill", progress=False)
""")


def _train(task: str, out: Path, kill: str, skills_dir: Path) -> int:
    """Run the training of ``task`` in a child process (killed as ``kill`` says); its exit status."""
    done = subprocess.run([sys.executable, "-c", CHILD, task, str(out), kill, str(skills_dir)],
                          capture_output=True, text=True, timeout=300, env={**os.environ, "PYTHONHASHSEED": "0"})
    assert done.returncode in (0, -9), done.stderr[-2000:]
    return done.returncode


def _log_rows(path: Path) -> list[dict[str, str]]:
    """log.csv without its wall-clock columns (they differ between any two runs)."""
    with path.open() as handle:
        return [{k: v for k, v in row.items() if k not in ("wall_seconds", "steps_per_second")}
                for row in csv.DictReader(handle)]


def _assert_same_run(a: Path, b: Path) -> None:
    first, second = load_policy_file(a / "policy.pth").state_dict(), load_policy_file(b / "policy.pth").state_dict()
    assert first.keys() == second.keys()
    for key in first:
        assert torch.equal(first[key], second[key]), key
    assert _log_rows(a / "log.csv") == _log_rows(b / "log.csv")


@pytest.fixture(scope="module")
def random_skills(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Untrained pick and drop skills (seeded) for the decision drill."""
    from sb3_contrib import MaskablePPO

    from mor.policy.envs import make_training_env
    from mor.policy.params import PPOParams
    from mor.sim.config import SimConfig

    folder = tmp_path_factory.mktemp("skills")
    for task in ("pick", "drop"):
        env = make_training_env(task, VARIANTS["gt_pose"], SimConfig(n_objects=2, image_size=16), PPOParams(n_envs=1),
                                FEATURES)
        save_policy_file(MaskablePPO("MlpPolicy", env, seed=0, policy_kwargs={"net_arch": [16, 16]}).policy,
                         folder / f"{task}.pth")
        env.close()
    return folder


@pytest.mark.parametrize("task", ["pick", "decision"])
def test_a_run_killed_at_a_checkpoint_or_at_a_random_step_resumes_to_the_uninterrupted_one(
        task: str, tmp_path: Path, random_skills: Path) -> None:
    reference = tmp_path / "uninterrupted"
    assert _train(task, reference, "none", random_skills) == 0
    total = int(_log_rows(reference / "log.csv")[-1]["steps"])
    at_step = int(np.random.default_rng(abs(hash(task)) % 1000).integers(1, total))  # noqa: NPY002
    for kill in ("checkpoint", f"step{at_step}"):
        run = tmp_path / kill
        assert _train(task, run, kill, random_skills) == -9, "the drill must kill the run before it ends"
        assert not (run / "policy.pth").exists()
        assert _train(task, run, "none", random_skills) == 0
        _assert_same_run(reference, run)


class _RunsCode:
    """Unpickling this creates ``marker``: what a crafted model file could do."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self) -> tuple:
        return (Path.touch, (self.marker,))


def test_a_crafted_policy_file_is_refused_in_one_line_and_runs_nothing(tmp_path: Path) -> None:
    marker, crafted = tmp_path / "ran", tmp_path / "policy.pth"
    torch.save({"state_dict": {}, "data": _RunsCode(marker)}, crafted)
    with pytest.raises(UnsafeFile, match=r"policy.pth: refused, loading it would run code.*mor policy convert"):
        Skill.load(crafted)
    assert not marker.exists()


def test_a_crafted_lnet_checkpoint_is_refused_and_runs_nothing(tmp_path: Path) -> None:
    from mor.lnet.checkpoint import load_checkpoint

    marker, crafted = tmp_path / "ran", tmp_path / "model.pt"
    torch.save({"config": {}, "model": _RunsCode(marker), "dataset_version": "x", "image_size": 16}, crafted)
    with pytest.raises(MorError, match=r"model.pt: refused, loading it would run code"):
        load_checkpoint(crafted, {}, "cpu")
    assert not marker.exists()


def test_a_crafted_or_cut_training_checkpoint_is_one_error(tmp_path: Path) -> None:
    from mor.policy.envs import make_training_env
    from mor.policy.params import PPOParams
    from mor.policy.signature import PolicySignature
    from mor.policy.train import train_policy
    from mor.sim.config import SimConfig

    params = PPOParams(steps=32, n_envs=2, n_steps=16, batch_size=16, n_epochs=1, hidden=[8], checkpoint_every=32)
    signature = PolicySignature.of("pick", VARIANTS["gt_pose"], 2, "square", None, FEATURES)
    train_policy(lambda: make_training_env("pick", VARIANTS["gt_pose"], SimConfig(n_objects=2, image_size=16), params,
                                           FEATURES), params,
                 signature, tmp_path, 0, "pick", progress=False)
    checkpoint, marker = tmp_path / CHECKPOINT_FILE, tmp_path / "ran"
    longer = params.model_copy(update={"steps": 64})
    retrain = lambda: train_policy(  # noqa: E731
        lambda: make_training_env("pick", VARIANTS["gt_pose"], SimConfig(n_objects=2, image_size=16), longer,
                                  FEATURES), longer,
        signature, tmp_path, 0, "pick", progress=False)
    checkpoint.write_bytes(checkpoint.read_bytes()[:1000])
    with pytest.raises(MorError, match=r"checkpoint.pt: not a readable training checkpoint \(.*cut short or damaged"):
        retrain()
    torch.save({"format": "mor.policy/1", "architecture": _RunsCode(marker)}, checkpoint)
    with pytest.raises(UnsafeFile, match=r"checkpoint.pt: refused"):
        retrain()
    assert not marker.exists()


def test_a_cut_policy_file_names_itself(tmp_path: Path, random_skills: Path) -> None:
    cut = tmp_path / "policy.pth"
    cut.write_bytes((random_skills / "pick.pth").read_bytes()[:500])
    with pytest.raises(MorError, match=r"policy.pth: not a readable policy file .*train it again or fetch it again"):
        Skill.load(cut)
