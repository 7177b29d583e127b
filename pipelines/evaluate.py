"""Stages ``evaluate`` (one method: per-episode records and its results row) and ``results`` (every row into
``cards/results/results.json``)."""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable, Iterator
from functools import cache
from pathlib import Path
from typing import Any

from mor.config import Profile, load_profile
from mor.data.parallel import unordered_map
from mor.errors import ConfigError
from mor.eval.card import write_readme_results, write_results_card
from mor.eval.methods import METHODS, MethodSpec, TrainedPolicies, method_spec
from mor.eval.policy_card import write_policy_card
from mor.eval.protocol import (EpisodeKey, decider, method_inputs, metric_summaries, play_records, run_protocol,
                               sim_of)
from mor.eval.results import ROW_KEYS, arena_label, is_zero_shot, merge_rows
from mor.eval.tables import localisation_headline
from mor.eval.video import write_policy_video
from mor.locking import writer_lock
from mor.policy.hierarchy import POLICY_FILE
from mor.policy.names import TASKS, VARIANTS
from mor.policy.observations import BatchTracker, GroundTruthBatchTracker, RenderingTruthTracker
from mor.policy.signature import read_signature
from mor.sim.arena import Arena
from pipelines import paths, settings
from pipelines.compute import update_compute
from pipelines.io import write_json
from pipelines.committed_lnet import lnet_runner


def policy_root(profile: Profile, zero_shot: bool) -> Path:
    """Where the policies a method plays are committed: this workspace's, or (zero-shot, only in a setting) the
    main workspace's."""
    if not zero_shot:
        return paths.POLICY_CARD
    if profile.setting is None:
        raise ConfigError("--zero-shot: plays the main workspace's policies in a setting; run it as "
                          "mor --setting NAME eval run --method M --zero-shot")
    return paths.MAIN / paths.POLICY_CARD


def load_method(profile: Profile, method: MethodSpec, zero_shot: bool = False
                ) -> tuple[TrainedPolicies, Callable[[int], BatchTracker], str | None]:
    """A learned method's committed policies (checked against what they were trained on), its tracker factory and
    the identity of the L-Net it observes through (None without one); zero_shot: the main workspace's policies
    through this workspace's L-Net (``policy_root``)."""
    sim, root = profile.sim, policy_root(profile, zero_shot)
    if method.is_baseline:
        policies = TrainedPolicies.load_baseline(root, method.variant, sim.n_objects, sim.arena,
                                                 sim.image_size, profile.policy.skills_deterministic)
        return policies, lambda n: RenderingTruthTracker(), None
    runner = lnet_runner(method.variant, profile)
    version = runner.identity if runner is not None else None
    policies = TrainedPolicies.load(root, method.variant, sim.n_objects, sim.arena, version,
                                    with_decision=method.decision == "learned",
                                    deterministic=profile.policy.skills_deterministic, zero_shot=zero_shot)
    if runner is None:
        return policies, lambda n: GroundTruthBatchTracker(), None
    from mor.policy.lnet_tracking import LNetBatchTracker  # noqa: PLC0415

    return policies, lambda n: LNetBatchTracker(runner, n), version


def policy_folders(method: MethodSpec, root: Path) -> dict[str, Path]:
    """The committed folder of each policy a learned method plays (``MethodSpec.skill_owners``)."""
    return {task: root / owner / task for task, owner in method.skill_owners().items()}


def policy_digests(folders: dict[str, Path]) -> dict[str, str]:
    """task -> the digest (``mor.lnet.runtime.file_digest``) of the policy file in its folder (``policy_folders``)."""
    from mor.lnet.runtime import file_digest  # noqa: PLC0415 - torch only where needed

    return {task: file_digest(folder / POLICY_FILE) for task, folder in folders.items()}


def evaluate_job(job: tuple[Path, Profile, str, bool, list[EpisodeKey]]) -> list[dict[str, Any]]:
    """One parallel evaluation job (a worker process or a Ray task): (the workspace folder, the profile, the
    method's name, zero-shot, its episode keys) -> their records; the method's policies are loaded here."""
    root, profile, method_name, zero_shot, keys = job
    os.chdir(root)  # the workspace's relative paths (a Ray worker starts elsewhere)
    os.environ.setdefault("LP_NUM_THREADS", "1")  # one llvmpipe render thread per worker
    method = method_spec(method_name)
    policies, tracker_factory, _ = load_method(profile, method, zero_shot) if method.variant is not None else (
        None, None, None)
    evaluate = profile.evaluate
    return list(play_records(method, profile.sim, keys, policies, tracker_factory, evaluate.n_envs, evaluate.horizon))


def run(profile: Profile, profile_name: str, method_name: str, progress: bool = True, zero_shot: bool = False
        ) -> dict[str, Any]:
    """Evaluate ``method_name`` with the profile's protocol; write its row to ``cards/results/rows/``.
    zero_shot: play the main workspace's policies in this setting (rows and records named ``<method>_zero_shot``)."""
    method = method_spec(method_name)
    name = f"{method.name}_zero_shot" if zero_shot else method.name
    command = f"mor eval run --method {method.name}" + (" --zero-shot" if zero_shot else "")
    with writer_lock(paths.EVAL / f"{name}.jsonl", command):
        return _evaluate(profile, profile_name, method, name, progress, zero_shot)


def _evaluate(profile: Profile, profile_name: str, method: MethodSpec, name: str, progress: bool, zero_shot: bool
              ) -> dict[str, Any]:
    """``run``'s work, under the lock of the method's records: its records, then its row (named ``name``)."""
    sim, protocol = profile.sim, profile.evaluate
    policies, tracker_factory, train_steps, policy_arena = None, None, None, sim.arena
    played_by: dict[str, Any] = {}
    if method.variant is not None:
        policies, tracker_factory, lnet_version = load_method(profile, method, zero_shot)
        folders = policy_folders(method, policy_root(profile, zero_shot))
        played_by = {"policies": policy_digests(folders), "lnet_version": lnet_version}
        train_steps = {task: json.loads((folder / "summary.json").read_text())["steps"]
                       for task, folder in folders.items()}
        policy_arena = read_signature(folders["pick"] / "meta.json").arena
    run_jobs = None
    if protocol.workers > 1 or protocol.backend == "ray":
        def run_jobs(jobs: list[list[EpisodeKey]]) -> Iterator[list[dict[str, Any]]]:
            return unordered_map(evaluate_job, [(Path.cwd(), profile, method.name, zero_shot, job) for job in jobs],
                                 protocol.workers, protocol.backend)
    started = time.perf_counter()
    records = run_protocol(method, sim, protocol.seeds, protocol.episodes, paths.EVAL / f"{name}.jsonl",
                           policies, tracker_factory, protocol.n_envs, progress, protocol.horizon, run_jobs,
                           played_by)
    row = {"method": method.name, "encoder": profile.policy.baseline.encoder if method.is_baseline else None,
           "arena": arena_label(sim.arena), "policy_arena": arena_label(policy_arena), "n_objects": sim.n_objects,
           "seeds": protocol.seeds, "episodes_per_seed": protocol.episodes, "train_steps": train_steps,
           "metrics": metric_summaries(records, protocol.bootstrap_resamples), "profile": profile_name,
           "wall_seconds": round(time.perf_counter() - started, 1), "workers": protocol.workers,
           "played_by": played_by}
    write_json(paths.RESULTS_CARD / "rows" / f"{name}.json", row)
    return row


def policy_video(profile: Profile, method_name: str, seed: int, out: Path) -> dict[str, float]:
    """One rearrangement episode of a learned method, first-person beside the truth and its belief, to ``out``."""
    method = method_spec(method_name)
    if method.variant is None:
        raise ConfigError(f"--policy: {method_name!r} is scripted; use mor sim video --policy {method_name}")
    policies, tracker_factory, _ = load_method(profile, method)
    arena = Arena.build(profile.sim.arena, profile.sim.arena_size)
    return write_policy_video(out, sim_of(method, profile.sim), tracker_factory(1),
                              {"pick": policies.pick, "drop": policies.drop}, decider(method, policies, arena),
                              method_inputs(method), seed, horizon=profile.evaluate.horizon)


def collect_results(profile_name: str) -> Path:
    """Merge every row in ``cards/results/rows/`` (and each setting's, ``settings/*/cards/results/rows/``) of this
    profile into ``cards/results/results.json``, render the tables into ``cards/results/README.md`` and the headline
    table into the main workspace's README.md (its results block; a workspace without a README, such as a test's,
    has none to fill).

    Each row gets the ``workspace`` it was evaluated in ("." or "settings/NAME"); ``localisation`` maps each
    workspace to the headline errors of the L-Net its rows observed through (for the card's shortfall notes)."""
    workspaces = [Path("."), *sorted(folder for folder in paths.SETTINGS.glob("*")
                                     if (folder / paths.RESULTS_CARD / "rows").is_dir())]  # Tables 3 and 4
    rows = [{**json.loads(p.read_text()), "workspace": workspace.as_posix()} for workspace in workspaces
            for p in sorted((workspace / paths.RESULTS_CARD / "rows").glob("*.json"))]
    path = paths.RESULTS_CARD / "results.json"
    existing = json.loads(path.read_text()) if path.is_file() else {"profile": profile_name, "rows": []}
    if existing.get("profile") != profile_name:
        existing = {"profile": profile_name, "rows": []}
    merged = merge_rows(existing["rows"], [r for r in rows if r.get("profile") == profile_name])
    identity = cache(_identity)  # this call's: a card changed since an earlier call is read again
    merged = [{**row, "stale": stale(row, profile_name, identity)} for row in merged]
    results = {"profile": profile_name, "row_keys": list(ROW_KEYS), "rows": merged,
               "localisation": localisation(workspaces, profile_name),
               "compute": update_compute(paths.RESULTS_CARD / "compute.json", profile_name)}
    write_json(path, results)
    write_results_card(results, paths.RESULTS_CARD)
    if paths.README.is_file():
        write_readme_results(paths.README, results, paths.RESULTS_CARD.as_posix())
    return path


def workspace_profile(workspace: Path, profile_name: str) -> Profile:
    """Profile ``profile_name`` as ``workspace`` (".": the main one, or ``settings/NAME``) sees it."""
    return settings.setting_profile(workspace.name, profile_name) if workspace != Path(".") else \
        load_profile(profile_name)


def lnet_card(workspace: Path, profile_name: str) -> Path:
    """The folder of the L-Net the L-Net rows of ``workspace`` observe through: the setting's own, or the main one
    where the setting says ``lnet_from_main`` (and for the main workspace, ".")."""
    setting = workspace_profile(workspace, profile_name).setting
    own = setting is not None and not setting.lnet_from_main
    return workspace / paths.LNET_CARD if own else paths.LNET_CARD


def _identity(card: Path, encoder_precision: str) -> str:
    """The identity of the L-Net in ``card`` loaded with ``encoder_precision`` (``collect_results`` reads each
    card's checkpoint once per call)."""
    from mor.lnet.runtime import checkpoint_identity  # noqa: PLC0415 - torch only where needed

    return checkpoint_identity(card / "model.pt", encoder_precision)


def stale(row: dict[str, Any], profile_name: str, identity: Callable[[Path, str], str] = _identity) -> bool:
    """Whether ``row`` was played by other policies or through another L-Net than the ones committed now: an L-Net
    row whose ``lnet_version`` is not the identity of its workspace's L-Net (``lnet_card``; a row from before rows
    recorded it counts as stale), or a row whose recorded policy digests differ from its policy files'."""
    method, workspace = method_spec(row["method"]), Path(row.get("workspace", "."))
    played_by = row.get("played_by") or {}
    precision = workspace_profile(workspace, profile_name).lnet.encoder_precision
    if method.uses_lnet and played_by.get("lnet_version") != identity(lnet_card(workspace, profile_name), precision):
        return True
    if not played_by.get("policies"):
        return False
    root = paths.POLICY_CARD if is_zero_shot(row) else workspace / paths.POLICY_CARD
    return played_by["policies"] != policy_digests(policy_folders(method, root))


def localisation(workspaces: list[Path], profile_name: str) -> dict[str, dict[str, Any]]:
    """workspace -> ``localisation_headline`` of the L-Net its L-Net rows observed through (``lnet_card``) and that
    metrics file's path; workspaces whose L-Net has no metrics are left out."""
    found = {}
    for workspace in workspaces:
        metrics = lnet_card(workspace, profile_name) / "metrics.json"
        if metrics.is_file():
            found[workspace.as_posix()] = {**localisation_headline(json.loads(metrics.read_text())),
                                           "file": metrics.as_posix()}
    return found


def write_policy_cards(profile: Profile, profile_name: str, video_seed: int = 0) -> list[Path]:
    """``cards/policy/<variant>/README.md`` and ``episode.mp4`` for every variant with trained policies; each card
    shows this workspace's rows that played those policies (a zero-shot row played the main workspace's)."""
    rows = [row for row in (json.loads(p.read_text()) for p in sorted((paths.RESULTS_CARD / "rows").glob("*.json")))
            if row.get("profile") == profile_name and not is_zero_shot(row)]
    written = []
    for variant in VARIANTS:
        folder = paths.POLICY_CARD / variant
        summaries = {task: json.loads((folder / task / "summary.json").read_text()) for task in TASKS
                     if (folder / task / "summary.json").is_file()}
        if len(summaries) < len(TASKS):
            continue
        mine = [r for r in rows if r["method"] in METHODS and METHODS[r["method"]].variant == variant]
        policy_video(profile, variant, video_seed, folder / "episode.mp4")
        written.append(write_policy_card(folder, variant, summaries, mine, "episode.mp4", profile_name, rows))
    return written
