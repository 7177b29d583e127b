"""Stage contracts on the tiny profile: the CLI stages in order, each reading the previous one's outputs."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pyarrow.parquet as pq
import pytest
import torch
import yaml
from typer.testing import CliRunner

from mor.policy.frame_encoder import read_frame_autoencoder
from mor.policy.policy_file import load_policy_file
from pipelines.cli import app


@pytest.fixture
def workspace(tmp_path: Path, repo_root: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """An empty project folder with the repository's params.yaml, as the current directory."""
    shutil.copy(repo_root / "params.yaml", tmp_path / "params.yaml")
    monkeypatch.chdir(tmp_path)
    return tmp_path


def _run(*args: str) -> str:
    result = CliRunner().invoke(app, list(args))
    assert result.exit_code == 0, result.output
    return result.output


def test_data_and_lnet_stages_in_order(workspace: Path) -> None:
    tiny = yaml.safe_load((workspace / "params.yaml").read_text())["profiles"]["tiny"]
    episodes = tiny["collect"]["episodes"]

    _run("collect", "--profile", "tiny")
    files = sorted((workspace / "datasets/episodes").glob("*.mcap"))
    assert len(files) == episodes
    stats = json.loads((workspace / "datasets/collect_stats.json").read_text())
    assert stats["frames"] == episodes * (tiny["collect"]["episode_steps"] + 1)

    _run("build-dataset", "--profile", "tiny")
    manifest = pq.read_table(workspace / "datasets/manifest.parquet")
    assert manifest.num_rows == episodes and manifest.schema.metadata[b"dataset_version"]
    for split in ("train", "validation", "test"):
        info = json.loads((workspace / f"datasets/lerobot/{split}/meta/info.json").read_text())
        assert info["total_episodes"] == sum(1 for s in manifest["split"].to_pylist() if s == split)
    assert (workspace / "cards/dataset/README.md").is_file()
    build_stats = json.loads((workspace / "datasets/build_stats.json").read_text())
    assert build_stats["frames"] == stats["frames"] and sum(build_stats["episodes"].values()) == episodes
    assert build_stats["seconds"]["total"] >= build_stats["seconds"]["lerobot"] > 0

    _run("validate", "--profile", "tiny")
    report = json.loads((workspace / "datasets/validation/report.json").read_text())
    assert report["ok"] and report["seconds"] > 0

    # A second collect changes nothing: everything is already there.
    assert "collected 0 episodes" in _run("collect", "--profile", "tiny")
    assert json.loads((workspace / "datasets/collect_stats.json").read_text()) == stats  # the collecting run's

    _run("train-lnet", "--profile", "tiny")
    assert (workspace / "datasets/lnet/model.pt").is_file()
    assert (workspace / "datasets/lnet/learning_curve.png").is_file()
    _run("calibrate-lnet", "--profile", "tiny")
    assert json.loads((workspace / "datasets/lnet/calibration.json").read_text())["agent_scale"] > 0
    _run("eval-lnet", "--profile", "tiny")
    card = workspace / "cards/lnet"
    metrics = json.loads((card / "metrics.json").read_text())
    assert set(metrics) >= {"before_calibration", "after_calibration", "dataset_version", "oracle", "real"}
    assert metrics["oracle"]["after_calibration"]["episodes"] == tiny["lnet"]["oracle_episodes"]
    # the same test frames through a bfloat16 encoder, beside the profile's float32, in the card
    assert set(metrics["encoder_precision"]) == {"float32", "bfloat16"}
    assert metrics["encoder_precision"]["float32"]["objects_seen_median_m"] == metrics["after_calibration"][
        "object_position_error_m"]["seen"]["median"]
    assert "## Encoder precision" in (card / "README.md").read_text()
    # both calibration criteria, with and without lost probabilities, fitted on validation and scored on test;
    # the profile's (nll, no lost probabilities) is the one used
    calibration = json.loads((workspace / "datasets/lnet/calibration.json").read_text())
    criteria = {"nll", "coverage", "nll+lost", "coverage+lost"}
    assert calibration["criterion"] == "nll" and set(calibration["criteria"]) == criteria
    assert calibration["criteria"]["nll"]["object_scale"] == calibration["object_scale"]
    assert calibration["lost_own"] == 0.0 and 0.0 <= calibration["criteria"]["nll+lost"]["lost_own"] < 1.0
    assert calibration["search_find"] is None  # with lost probabilities only: the search belief of mor.lnet.search
    find = calibration["criteria"]["coverage+lost"]["search_find"]  # None where no belief is still unfound
    assert find is None or 0.0 <= find <= 1.0
    assert set(metrics["calibration_criteria"]) == criteria
    assert metrics["after_calibration"]["stated"]["coverage"]["objects_seen"] == metrics["after_calibration"][
        "coverage"]["objects_seen"]  # without lost probabilities the stated belief is the Gaussian
    assert metrics["calibration_criteria"]["nll"]["coverage_heading"] == metrics["after_calibration"]["coverage"][
        "heading"]
    assert "| nll (used) |" in (card / "README.md").read_text()
    for name in ("README.md", "model.pt", "reliability.png", "estimates_strip.png", "estimates.gif", "since_seen.png"):
        assert (card / name).is_file(), name

    # The policy half: every variant's policies (the L-Net ones on the tiny L-Net above), methods, tables, cards.
    for variant in ("gt_pose", "lnet", "lnet_no_uncertainty"):
        _run("policy", "train", "--variant", variant, "--profile", "tiny")
        for task in ("pick", "drop", "decision"):
            assert (workspace / f"cards/policy/{variant}/{task}/policy.pth").is_file(), (variant, task)
    lnet_pick = json.loads((workspace / "cards/policy/lnet/pick/summary.json").read_text())
    assert lnet_pick["warm_start"] and lnet_pick["steps"] == tiny["policy"]["lnet_steps"]["pick"]
    for method in ("oracle", "gt_pose", "lnet", "lnet_no_uncertainty", "lnet_nearest_rule"):
        _run("eval", "run", "--method", method, "--profile", "tiny")
    for method in ("gt_pose", "lnet", "lnet_nearest_rule"):  # `mor sim video --policy` offers every method
        out = workspace / f"{method}.gif"
        assert f"wrote {out}" in _run("sim", "video", "--policy", method, "--profile", "tiny", "--out", str(out))
    records = (workspace / "datasets/eval/lnet.jsonl").read_text().splitlines()
    protocol = tiny["evaluate"]
    assert len(records) == 3 * len(protocol["seeds"]) * protocol["episodes"]
    # a second training run of each (lnet warm-starts from gt_pose's run of the same seed), and held-out episodes
    _run("policy", "train", "--variant", "gt_pose", "--seed", "1", "--profile", "tiny")
    _run("policy", "train", "--variant", "lnet", "--seed", "1", "--profile", "tiny")
    assert json.loads((workspace / "cards/policy/lnet/seed_1/pick/summary.json").read_text())["seed"] == 1
    _run("eval", "run", "--method", "lnet", "--training-seed", "1", "--profile", "tiny")
    _run("eval", "run", "--method", "lnet", "--seeds", "7,8", "--profile", "tiny")
    _run("eval", "results", "--profile", "tiny")
    results = json.loads((workspace / "cards/results/results.json").read_text())
    assert {r["method"] for r in results["rows"]} == {"oracle", "gt_pose", "lnet", "lnet_no_uncertainty",
                                                       "lnet_nearest_rule"}
    lnet = next(r for r in results["rows"] if r["method"] == "lnet" and r["episodes"] is None)
    assert lnet["training_seeds"] == [0, 1] and len(lnet["runs"]) == 2 and not lnet["stale"]
    assert sum(lnet["failures"]["pick"].values()) == 2 * len(protocol["seeds"]) * protocol["episodes"]
    held_out = next(r for r in results["rows"] if r["method"] == "lnet" and r["episodes"] == "held_out")
    assert held_out["seeds"] == [7, 8] and held_out["training_seeds"] == [0]
    assert {(c["a"], c["b"]) for c in results["comparisons"]} == {("lnet", "lnet_no_uncertainty"),
                                                                   ("lnet", "lnet_nearest_rule")}
    card_text = (workspace / "cards/results/README.md").read_text()
    assert "## Comparisons" in card_text and "## How episodes ended" in card_text and "## Held-out" in card_text
    assert "| Ours: policy + uncertainty (lnet) |" in (workspace / "cards/results/README.md").read_text()
    assert "Table 2" in _run("eval", "tables", "--table", "2")
    missing = CliRunner().invoke(app, ["eval", "tables", "--table", "1"])
    assert missing.exit_code == 2 and "mor eval run --method gt_pose_nearest_rule" in missing.output
    assert "wrote cards/policy/lnet/README.md" in _run("eval", "cards", "--variant", "lnet", "--profile", "tiny")
    assert not (workspace / "cards/policy/gt_pose/README.md").exists()  # only the variant asked for
    _run("eval", "cards", "--profile", "tiny")
    for variant in ("gt_pose", "lnet", "lnet_no_uncertainty"):
        assert (workspace / f"cards/policy/{variant}/episode.mp4").stat().st_size > 0
        assert "## Evaluation" in (workspace / f"cards/policy/{variant}/README.md").read_text()

    # The settings of Tables 3 and 4: the polygon arena with its own data and L-Net; 2 objects on the main L-Net.
    polygon = ("--setting", "polygon")
    for stage in ("collect", "build-dataset", "train-lnet", "calibrate-lnet", "eval-lnet"):
        _run(*polygon, stage, "--profile", "tiny")
    assert json.loads((workspace / "settings/polygon/cards/lnet/metrics.json").read_text())["dataset_version"] != (
        metrics["dataset_version"])  # the polygon's own data and L-Net
    _run(*polygon, "eval", "run", "--method", "lnet", "--zero-shot", "--profile", "tiny")
    _run(*polygon, "policy", "train", "--variant", "lnet", "--profile", "tiny")
    fine_tuned = json.loads((workspace / "settings/polygon/cards/policy/lnet/pick/summary.json").read_text())
    assert fine_tuned["warm_start_from"] == "../../cards/policy/lnet/pick/policy.pth"
    _run(*polygon, "eval", "run", "--method", "lnet", "--profile", "tiny")
    objects = ("--setting", "objects_2")
    for variant in ("gt_pose", "lnet"):
        _run(*objects, "policy", "train", "--variant", variant, "--profile", "tiny")
    _run(*objects, "eval", "run", "--method", "lnet", "--profile", "tiny")
    _run("eval", "results", "--profile", "tiny")
    rows = json.loads((workspace / "cards/results/results.json").read_text())["rows"]
    settings = {(r["arena"], r["policy_arena"], r["n_objects"]) for r in rows if r["method"] == "lnet"}
    assert settings == {("square", "square", 3), ("polygon", "square", 3), ("polygon", "polygon", 3), ("square", "square", 2)}
    readme = (workspace / "cards/results/README.md").read_text()
    assert "| Ours (lnet), policies trained in the square arena: zero-shot |" in readme and "| 2 objects: Ours (lnet) |" in readme
    localisation = json.loads((workspace / "cards/results/results.json").read_text())["localisation"]
    assert localisation["settings/polygon"]["file"] == "settings/polygon/cards/lnet/metrics.json"  # its own L-Net
    assert localisation["settings/objects_2"]["file"] == "cards/lnet/metrics.json"  # lnet_from_main
    missing = CliRunner().invoke(app, ["eval", "tables", "--table", "3"])
    assert missing.exit_code == 2 and "mor --setting polygon eval run --method baseline_delta_pose" in missing.output
    assert not any(r["stale"] for r in rows)
    # Another main L-Net committed (here: the polygon's): every row played through the main L-Net is now stale.
    for name in ("model.pt", "calibration.json"):
        shutil.copyfile(workspace / "settings/polygon/cards/lnet" / name, workspace / "cards/lnet" / name)
    _run("eval", "results", "--profile", "tiny")
    rows = json.loads((workspace / "cards/results/results.json").read_text())["rows"]
    assert {(r["method"], r["arena"], r["n_objects"]) for r in rows if r["stale"]} == {
        ("lnet", "square", 3), ("lnet_no_uncertainty", "square", 3), ("lnet_nearest_rule", "square", 3), ("lnet", "square", 2)}
    assert "| Ours: policy + uncertainty (lnet) † |" in (workspace / "cards/results/README.md").read_text()


def test_validate_without_a_manifest_is_one_clear_line(workspace: Path) -> None:
    result = CliRunner().invoke(app, ["validate"])
    assert result.exit_code == 2
    assert result.output.strip().splitlines() == ["error: datasets/manifest.parquet: no manifest; run mor build-dataset first"]


def test_an_unknown_ablation_study_is_one_clear_line(workspace: Path) -> None:
    result = CliRunner().invoke(app, ["ablate-lnet", "--study", "colour"])
    assert result.exit_code == 2
    from mor.lnet.params import ABLATIONS  # noqa: PLC0415

    assert result.output.strip().splitlines() == [
        f"error: --study: unknown study 'colour'; choose one of {', '.join(ABLATIONS)}"]


def test_baseline_stages_train_evaluate_and_fill_table_1(workspace: Path) -> None:
    """A tiny baseline trains for a few steps and is scored by the protocol; the others reuse its Pick."""
    tiny = yaml.safe_load((workspace / "params.yaml").read_text())["profiles"]["tiny"]
    _run("policy", "train", "--variant", "baseline_img", "--profile", "tiny")
    _run("policy", "train", "--variant", "baseline_landmark", "--profile", "tiny")
    assert (workspace / "cards/policy/baseline_img/pick/policy.pth").is_file()
    assert not (workspace / "cards/policy/baseline_landmark/pick").exists()
    for task in ("pick", "drop"):  # each skill imitated with its own settings, and its summary says which
        own = tiny["policy"]["baseline"]["imitation"][task]
        summary = json.loads((workspace / f"cards/policy/baseline_img/{task}/summary.json").read_text())
        assert {key: summary["imitation"][key] for key in own} == own
    for variant in ("baseline_img", "baseline_landmark"):  # `mor sim video --policy` offers every method
        out = workspace / f"{variant}.gif"
        assert f"wrote {out}" in _run("sim", "video", "--policy", variant, "--profile", "tiny", "--out", str(out))
    probed = _run("eval", "probe-pick", "--variant", "baseline_landmark", "--episodes", "2", "--profile", "tiny")
    probe = json.loads((workspace / "cards/results/pick_probe/baseline_landmark.seed_0.json").read_text())
    assert probe["pick_from"] == "baseline_img" and probe["episodes"] == 2 and "mean P(PICK)" in probed
    refused = CliRunner().invoke(app, ["eval", "probe-pick", "--variant", "baseline_landmark", "--negative-information",
                                       "--profile", "tiny"])
    assert refused.exit_code == 2 and refused.output.strip().splitlines() == [
        "error: --negative-information: 'baseline_landmark' does not observe through the L-Net"]
    _run("eval", "run", "--method", "baseline_landmark", "--profile", "tiny")
    protocol = tiny["evaluate"]
    records = (workspace / "datasets/eval/baseline_landmark.jsonl").read_text().splitlines()
    assert len(records) == 3 * len(protocol["seeds"]) * protocol["episodes"]
    missing = CliRunner().invoke(app, ["eval", "run", "--method", "baseline_delta_pose", "--profile", "tiny"])
    assert missing.exit_code == 2 and "baseline_delta_pose/drop/meta.json" in missing.output
    # the probe loads the Pick alone: it plays where the variant's Drop was never trained (Table 3's +Img)
    _run("eval", "probe-pick", "--variant", "baseline_delta_pose", "--episodes", "1", "--profile", "tiny")
    _run("eval", "results", "--profile", "tiny")
    row = json.loads((workspace / "cards/results/results.json").read_text())["rows"][0]
    # the tiny profile's skills imitate first
    assert all(tiny["policy"]["baseline"]["imitation"][task]["rounds"] > 0 for task in ("pick", "drop"))
    assert row["method"] == "baseline_landmark" and row["encoder"] == "compact + goal gate + oracle DAgger"
    assert row["train_steps"] == {"pick": 64, "drop": 64}
    readme = (workspace / "cards/results/README.md").read_text()
    assert "| Baseline: CNN + Landmark (paper: ResNet18 + Landmark) [ours: compact + goal gate + oracle DAgger] |" in readme
    compute = json.loads((workspace / "cards/results/compute.json").read_text())
    assert set(compute["stages"]) == {"policy train baseline_img pick", "policy train baseline_img drop",
                                      "policy train baseline_landmark drop", "eval run baseline_landmark"}
    assert compute["total_seconds"] == pytest.approx(sum(compute["stages"].values()), abs=0.2)
    assert "## Compute" in readme


def test_a_pretrained_encoder_is_published_and_stays_frozen_in_a_baselines_training(workspace: Path) -> None:
    """mor policy pretrain-encoder writes the encoder's card; a baseline with encoder autoencoder trains on top of
    it without changing it."""
    params = yaml.safe_load((workspace / "params.yaml").read_text())
    params["profiles"]["tiny"]["policy"]["baseline"]["encoder"] = "autoencoder"
    (workspace / "params.yaml").write_text(yaml.safe_dump(params))
    missing = CliRunner().invoke(app, ["policy", "train", "--variant", "baseline_img", "--task", "pick",
                                       "--profile", "tiny"])
    assert missing.exit_code == 2 and "run mor policy pretrain-encoder first" in missing.output
    assert "held-out reconstruction MSE" in _run("policy", "pretrain-encoder", "--profile", "tiny")
    card = workspace / "cards/baseline_encoder"
    assert {p.name for p in card.iterdir()} == {"encoder.pth", "log.csv", "reconstructions.png", "summary.json",
                                                "README.md"}
    _run("policy", "train", "--variant", "baseline_img", "--task", "pick", "--profile", "tiny")
    pretrained = read_frame_autoencoder(card / "encoder.pth")["encoder"]
    trained = load_policy_file(workspace / "cards/policy/baseline_img/pick/policy.pth").state_dict()
    for name, tensor in pretrained.items():
        for extractor in ("features_extractor", "vf_features_extractor"):  # the critic has its own (share_encoder)
            torch.testing.assert_close(trained[f"{extractor}.encoder.0.{name}"], tensor, rtol=0, atol=0)
    _run("eval", "results", "--profile", "tiny")
    compute = json.loads((workspace / "cards/results/compute.json").read_text())
    assert "pretrain-encoder" in compute["stages"]

@pytest.mark.parametrize("backend", ["process", "ray"])
def test_parallel_evaluation_jobs_give_the_records_of_one_process(workspace: Path, backend: str) -> None:
    """The protocol's jobs (one per task and seed) in 2 worker processes or as Ray tasks on a local Ray instance
    write the same episodes as one process."""
    _run("eval", "run", "--method", "oracle", "--profile", "tiny", "--workers", "1")
    alone = sorted((workspace / "datasets/eval/oracle.jsonl").read_text().splitlines())
    (workspace / "datasets/eval/oracle.jsonl").unlink()
    _run("eval", "run", "--method", "oracle", "--profile", "tiny", "--workers", "2", "--backend", backend)
    assert sorted((workspace / "datasets/eval/oracle.jsonl").read_text().splitlines()) == alone


def test_compute_sums_each_workspaces_stages_and_all_of_them(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from pipelines.compute import update_compute  # noqa: PLC0415

    monkeypatch.chdir(tmp_path)
    for folder, seconds in ((Path("."), 60.0), (Path("settings/polygon"), 30.0), (Path("settings/objects_2"), 6.0)):
        rows = folder / "cards/results/rows"
        rows.mkdir(parents=True)
        (rows / "lnet.json").write_text(json.dumps({"wall_seconds": seconds}))
    (Path("cards/results/rows") / "lnet.seed_1.json").write_text(json.dumps({"wall_seconds": 50.0}))
    (Path("cards/results/rows") / "lnet_search.json").write_text(json.dumps({"wall_seconds": 40.0}))
    skill = Path("cards/policy/baseline_img/pick")  # a baseline's imitation start counts with its PPO run
    skill.mkdir(parents=True)
    (skill / "summary.json").write_text(json.dumps({"wall_seconds_this_run": 10.0}))
    (skill / "log.csv").write_text("steps,wall_seconds\n2048,1.0\n")
    (skill / "imitation.csv").write_text("round,seconds\n0,2.5\n1,4.0\n")
    seed_skill = Path("cards/policy/lnet/seed_2/drop")  # another training seed's run, copied without its summary
    seed_skill.mkdir(parents=True)
    (seed_skill / "log.csv").write_text("steps,wall_seconds\n2048,3.0\n4096,7.0\n")
    Path("dvc.yaml").write_text(yaml.safe_dump({"stages": {"evaluate": {
        "matrix": {"method": ["lnet"]}, "cmd": "mor eval run --method ${item.method}"}}}))
    compute = update_compute(Path("compute.json"), "tiny")
    assert compute["stages"]["polygon: eval run lnet"] == 30.0 and compute["total_seconds"] == 96.0
    assert compute["stages"]["policy train baseline_img pick"] == 14.0  # beside dvc.yaml's stages here: extra
    assert compute["workspace_seconds"] == {"main": 60.0, "objects_2": 6.0, "polygon": 30.0}
    assert compute["stages"]["policy train lnet.seed_2 drop"] == 7.0
    assert compute["extra_runs"] == ["eval run lnet.seed_1", "eval run lnet_search",  # not what dvc repro runs
                                     "policy train baseline_img pick", "policy train lnet.seed_2 drop"]
    assert compute["extra_seconds"] == 111.0
