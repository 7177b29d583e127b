"""What `mor policy train` runs is decided in one place (``mor.policy.plan``) and printed by `mor policy plan`."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from mor.config import load_profile
from mor.errors import ConfigError
from mor.policy.params import ObservationParams
from mor.policy.plan import training_plan
from mor.policy.signature import PolicySignature, write_signature
from mor.policy.variants import VARIANTS
from pipelines.cli import app
from pipelines.settings import setting_profile

FEATURES = ObservationParams()  # the default policy.observation settings


def test_the_lnet_variants_fine_tune_gt_pose_for_lnet_steps_and_gt_pose_starts_afresh(tmp_path: Path) -> None:
    profile = load_profile("default")
    gt_pose = training_plan(profile, VARIANTS["gt_pose"], ("pick", "drop", "decision"), tmp_path / "own",
                            tmp_path / "main")
    assert [(p.task, p.params.steps, p.start) for p in gt_pose] == [
        ("pick", profile.policy.pick.steps, None), ("drop", profile.policy.drop.steps, None),
        ("decision", profile.policy.decision.steps, None)]
    lnet = training_plan(profile, VARIANTS["lnet"], ("pick",), tmp_path / "own", tmp_path / "main")
    assert lnet[0].params.steps == profile.policy.lnet_steps["pick"] != profile.policy.pick.steps
    assert lnet[0].start == tmp_path / "own" / "gt_pose" / "pick" and "lnet_steps" in lnet[0].why
    assert [p.task for p in training_plan(profile, VARIANTS["baseline_landmark"], ("pick", "drop"), tmp_path,
                                          tmp_path)] == \
        ["drop"]  # its Pick is baseline_img's
    for name in ("default", "paper"):  # both profiles' baselines imitate the oracle first, each skill its own way
        imitation = load_profile(name).policy.baseline.imitation
        assert imitation.pick.round_steps * imitation.pick.rounds > imitation.drop.round_steps * imitation.drop.rounds
        for plan in training_plan(load_profile(name), VARIANTS["baseline_img"], ("pick", "drop"), tmp_path, tmp_path):
            own = getattr(imitation, plan.task)
            assert own.rounds > 0 and plan.start is None
            assert plan.why.startswith(f"from {own.rounds} DAgger rounds of {own.round_steps:,} steps")


def test_a_setting_fine_tunes_the_main_policies_and_its_own_decision_when_the_objects_differ(tmp_path: Path) -> None:
    profile = setting_profile("objects_4", "default")
    main = tmp_path / "main"
    write_signature(main / "lnet" / "decision" / "meta.json", PolicySignature.of("decision", VARIANTS["lnet"], 3,
                                                                                 "square", "x", FEATURES))
    plans = training_plan(profile, VARIANTS["lnet"], ("pick", "decision"), tmp_path / "own", main)
    assert plans[0].start == main / "lnet" / "pick" and "finetune_from_main" in plans[0].why
    assert plans[0].params.steps == profile.policy.finetune_steps["pick"] != profile.policy.lnet_steps["pick"]
    assert plans[1].start == tmp_path / "own" / "gt_pose" / "decision"  # 3 decision actions there, 4 here


def test_mor_policy_plan_prints_each_task_its_steps_and_its_start() -> None:
    result = CliRunner().invoke(app, ["policy", "plan", "--profile", "tiny", "--variant", "lnet"])
    assert result.exit_code == 0, result.output
    assert "pick: 32 steps, fine-tunes this workspace's gt_pose policy" in result.output
    assert "n_epochs 1" in result.output


def test_more_steps_continues_the_committed_policies_and_refuses_a_baseline(tmp_path: Path) -> None:
    profile = load_profile("default")
    plans = training_plan(profile, VARIANTS["lnet"], ("pick", "drop"), tmp_path / "own", tmp_path / "main", seed=2,
                          more_steps=400_000)
    assert [(p.start, p.params.steps) for p in plans] == [
        (tmp_path / "own" / "lnet" / "seed_2" / "pick", 400_000), (tmp_path / "own" / "lnet" / "seed_2" / "drop", 400_000)]
    assert "--more-steps" in plans[0].why and plans[0].params.n_epochs == profile.policy.pick.n_epochs
    result = CliRunner().invoke(app, ["policy", "train", "--profile", "tiny", "--variant", "baseline_img",
                                      "--more-steps", "10"])
    assert result.exit_code != 0 and "--more-steps: baseline_img is a baseline" in result.output
    with pytest.raises(ConfigError, match="--more-steps: 0 is not a number of steps"):
        training_plan(profile, VARIANTS["lnet"], ("pick",), tmp_path / "own", tmp_path / "main", more_steps=0)
