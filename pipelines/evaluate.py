"""Stages ``evaluate`` (one method: per-episode records and its results row) and ``results`` (every row into
``cards/results/results.json``)."""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from dataclasses import asdict, replace
from functools import cache
from pathlib import Path
from typing import Any

from mor.config import Profile, load_profile
from mor.data.parallel import unordered_map
from mor.errors import ConfigError
from mor.eval.card import write_readme_results, write_results_card
from mor.eval.failures import count_endings
from mor.eval.methods import METHODS, Method, load_method, method_spec
from mor.eval.policy_card import write_policy_card
from mor.eval.protocol import (EpisodeKey, decider, method_inputs, metric_summaries, metric_values, play_job,
                               run_protocol, sim_of)
from mor.eval.results import ROW_KEYS, comparisons, gather_rows, is_zero_shot, row_name, stale_row
from mor.eval.tables import localisation_headline
from mor.eval.video import write_policy_video
from mor.locking import writer_lock
from mor.policy.names import TASKS
from mor.policy.signature import read_signature
from mor.policy.variants import POSE_VARIANTS
from mor.policy.workspace import Workspace
from mor.sim.arena import Arena
from pipelines import paths, settings
from pipelines.compute import update_compute
from pipelines.io import write_json
from pipelines.workspaces import workspace_record


def run(profile: Profile, profile_name: str, method_name: str, progress: bool = True, zero_shot: bool = False,
        training_seed: int = 0, held_out: bool = False) -> dict[str, Any]:
    """Evaluate ``method_name``'s run with ``training_seed`` with the profile's protocol; write its row to
    ``cards/results/rows/``. zero_shot: play the main workspace's policies in this setting (rows and records named
    ``<method>_zero_shot``); a training seed S > 0 adds ``.seed_S`` to the names; held_out: the profile's evaluation
    seeds are not the protocol's (``mor eval run --seeds``): ``.held_out`` is added, and the row says
    ``episodes: held_out``."""
    method = method_spec(method_name)
    name = row_name(f"{method.name}_zero_shot" if zero_shot else method.name, training_seed, held_out)
    command = (f"mor eval run --method {method.name}" + (" --zero-shot" if zero_shot else "")
               + (f" --training-seed {training_seed}" if training_seed else "")
               + (f" --seeds {','.join(map(str, profile.evaluate.seeds))}" if held_out else ""))
    with writer_lock(paths.EVAL / f"{name}.jsonl", command):
        row = _evaluate(profile, profile_name, method, name, progress, zero_shot, training_seed)
        row["episodes"] = "held_out" if held_out else None
        write_json(paths.RESULTS_CARD / "rows" / f"{name}.json", row)
        return row


def _evaluate(profile: Profile, profile_name: str, method: Method, name: str, progress: bool, zero_shot: bool,
              training_seed: int) -> dict[str, Any]:
    """``run``'s work, under the lock of the method's records (``datasets/eval/<name>.jsonl``): its row."""
    sim, protocol = profile.sim, profile.evaluate
    workspace = workspace_record(Path("."), profile)
    loaded = load_method(method, workspace, profile, zero_shot, training_seed)
    summaries = {task: json.loads((folder / "summary.json").read_text()) for task, folder in loaded.folders.items()}
    train_steps = {task: summary["steps"] for task, summary in summaries.items()} or None
    policy_arena = read_signature(loaded.folders["pick"] / "meta.json").arena if loaded.folders else sim.arena
    run_jobs = None
    if protocol.workers > 1 or protocol.backend == "ray":
        def run_jobs(jobs: list[list[EpisodeKey]]) -> Iterator[list[dict[str, Any]]]:
            return unordered_map(play_job, [(workspace, profile, method.name, zero_shot, training_seed, job)
                                            for job in jobs],
                                 protocol.workers, protocol.backend)
    started = time.perf_counter()
    records = run_protocol(loaded, sim, protocol.seeds, protocol.episodes, paths.EVAL / f"{name}.jsonl",
                           protocol.n_envs, progress, protocol.horizon, run_jobs)
    row = {"method": method.name, "encoder": baseline_recipe(summaries, profile) if method.is_baseline else None,
           "arena": sim.arena, "policy_arena": policy_arena, "n_objects": sim.n_objects,
           "seeds": protocol.seeds, "episodes_per_seed": protocol.episodes, "train_steps": train_steps,
           "metrics": metric_summaries(records, protocol.bootstrap_resamples), "profile": profile_name,
           "training_seed": training_seed if loaded.folders else None, "outcomes": metric_values(records),
           "failures": count_endings(records),
           "wall_seconds": round(time.perf_counter() - started, 1), "workers": protocol.workers,
           "played_by": loaded.played_by()}
    return row


def baseline_recipe(summaries: dict[str, dict[str, Any]], profile: Profile) -> str:
    """How a baseline's skills were made, as its row and tables name it: their encoder (the profile's, for policies
    whose summary predates the field), "+ goal gate" where a skill's encoder was gated by its target's class, and
    "+ oracle DAgger" where a skill imitated the oracle before PPO."""
    encoders = {summary.get("encoder", profile.policy.baseline.encoder) for summary in summaries.values()}
    gated = any(summary.get("goal_gating", False) for summary in summaries.values())
    imitated = any(summary.get("imitation", {}).get("rounds", 0) for summary in summaries.values())
    return " / ".join(sorted(encoders)) + (" + goal gate" if gated else "") + (" + oracle DAgger" if imitated else "")


def policy_video(profile: Profile, method_name: str, seed: int, out: Path) -> dict[str, float]:
    """One rearrangement episode of a learned method, first-person beside the truth and its belief, to ``out``."""
    method = method_spec(method_name)
    if method.variant is None:
        raise ConfigError(f"--policy: {method_name!r} is scripted; use mor sim video --policy {method_name}")
    loaded = load_method(method, workspace_record(Path("."), profile), profile)
    policies, arena = loaded.policies, Arena.build(profile.sim.arena, profile.sim.arena_size)
    return write_policy_video(out, sim_of(method, profile.sim), loaded.tracker_factory(1, looks=True),
                              {"pick": policies.pick, "drop": policies.drop},
                              decider(method, policies, arena, loaded.features), method_inputs(method, loaded.features),
                              seed, horizon=profile.evaluate.horizon)


def pick_probe(profile: Profile, variant_name: str, training_seed: int, episodes: int, seed: int,
               negative_information: bool = False) -> dict[str, Any]:
    """``mor.eval.pick_probe.probe_pick`` of the committed Pick skill that ``variant_name`` plays (its run with
    ``training_seed``), in a Pick env with that skill's observation; ``negative_information``: its L-Net tracks
    with that rule on (``mor.lnet.unseen``), whatever its calibration was fitted with."""
    from mor.eval.pick_probe import probe_pick  # noqa: PLC0415
    from mor.policy.baselines import BaselineObservation  # noqa: PLC0415
    from mor.policy.envs import make_policy_env, make_task_env  # noqa: PLC0415
    from mor.policy.features import ObservationLayout  # noqa: PLC0415
    from mor.policy.observations import GroundTruthTracker, SingleTracker  # noqa: PLC0415

    method = method_spec(variant_name)
    if method.variant is None:
        raise ConfigError(f"--variant: {variant_name!r} has no Pick skill to probe; choose a trained variant")
    loaded = load_method(method, workspace_record(Path("."), profile), profile, training_seed=training_seed,
                         tasks=("pick",))
    sim = sim_of(method, profile.sim)
    variant = method.skill_owners()["pick"]
    if negative_information:
        if loaded.lnet is None:
            raise ConfigError(f"--negative-information: {variant_name!r} does not observe through the L-Net")
        try:
            loaded.lnet.model.use_tracking(replace(loaded.lnet.model.tracking, negative_information=True))
        except ValueError as error:
            raise ConfigError(f"--negative-information: {variant_name!r}: {error}") from None
    if variant.is_baseline:
        env = BaselineObservation(make_task_env("pick", sim, render_frames=True), variant.baseline_input)
    else:
        tracker = GroundTruthTracker() if variant.source == "truth" else SingleTracker(loaded.tracker_factory(1))
        env = make_policy_env("pick", sim, tracker, ObservationLayout.of(variant, loaded.features))
    try:
        result = probe_pick(env, loaded.policies.pick, episodes, seed)
    finally:
        env.close()
    return {"variant": variant_name, "pick_from": variant.name, "training_seed": training_seed,
            "policy": loaded.played_by()["policies"]["pick"],
            "skills_deterministic": profile.policy.skills_deterministic,
            "tracking": None if loaded.lnet is None else asdict(loaded.lnet.model.tracking), **result}


def read_probe(path: Path, episodes: int, seed: int) -> dict[str, Any]:
    """A probe JSON (``mor eval probe-pick``) to compare against: one clear error unless it played the same
    ``episodes`` from reset seed ``seed`` and holds each episode's outcome."""
    try:
        probe = json.loads(Path(path).read_text())
    except (OSError, ValueError) as error:
        raise ConfigError(f"--against: {path}: not a readable probe JSON ({error}); write one with mor eval "
                          "probe-pick --out") from None
    if not isinstance(probe, dict):
        probe = {}
    played = (probe.get("episodes"), probe.get("seed"), len(probe.get("outcomes") or []))
    if played != (episodes, seed, episodes):
        raise ConfigError(f"--against: {path} did not play these episodes ({episodes} from reset seed {seed}, each "
                          "outcome recorded); probe it again with the same --episodes and --seed")
    return probe


def collect_results(profile_name: str) -> Path:
    """Merge every row in ``cards/results/rows/`` (and each setting's, ``settings/*/cards/results/rows/``) of this
    profile into ``cards/results/results.json`` (``mor.eval.results.gather_rows``, each marked ``stale`` or not),
    render the tables into ``cards/results/README.md`` and the headline table into the main workspace's README.md
    (its results block; a workspace without a README, such as a test's, has none to fill). ``localisation`` maps each
    workspace to the headline errors of the L-Net its rows observed through (for the card's shortfall notes)."""
    folders = [Path("."), *sorted(folder for folder in paths.SETTINGS.glob("*")
                                  if (folder / paths.RESULTS_CARD / "rows").is_dir())]  # Tables 3 and 4
    profiles = {folder.as_posix(): workspace_profile(folder, profile_name) for folder in folders}
    workspaces = {name: workspace_record(Path(name), profile) for name, profile in profiles.items()}
    path = paths.RESULTS_CARD / "results.json"
    resamples = profiles["."].evaluate.bootstrap_resamples
    rows = gather_rows({name: Path(name) / paths.RESULTS_CARD / "rows" for name in workspaces}, profile_name,
                       resamples)
    identity = cache(_identity)  # this call's: a card changed since an earlier call is read again
    rows = [{**row, "stale": stale_row(row, workspaces[row["workspace"]], lambda card, row=row: identity(
        card, profiles[row["workspace"]].lnet.encoder_precision))} for row in rows]
    results = {"profile": profile_name, "row_keys": list(ROW_KEYS), "rows": rows,
               "comparisons": comparisons(rows, resamples),
               "localisation": localisation(workspaces),
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


def _identity(card: Path, encoder_precision: str) -> str:
    """The identity of the L-Net in ``card`` loaded with ``encoder_precision`` (``collect_results`` reads each
    card's checkpoint once per call)."""
    from mor.lnet.runtime import checkpoint_identity  # noqa: PLC0415 - torch only where needed

    return checkpoint_identity(card / "model.pt", encoder_precision)


def localisation(workspaces: dict[str, Workspace]) -> dict[str, dict[str, Any]]:
    """workspace name -> ``localisation_headline`` of the L-Net its L-Net rows observed through and that metrics
    file's path (relative to the main workspace); workspaces whose L-Net has no metrics are left out."""
    found = {}
    for name, workspace in workspaces.items():
        metrics = workspace.lnet_card / "metrics.json"
        if metrics.is_file():
            found[name] = {**localisation_headline(json.loads(metrics.read_text())),
                           "file": metrics.relative_to(Path.cwd().resolve()).as_posix()}
    return found


def write_policy_cards(profile: Profile, profile_name: str, variants: list[str] | None = None,
                       video_seed: int = 0) -> list[Path]:
    """``cards/policy/<variant>/README.md`` and ``episode.mp4`` for every variant of ``variants`` (None: all) with
    trained policies; each card shows this workspace's rows that played those policies (a zero-shot row played the
    main workspace's)."""
    rows = [row for row in (json.loads(p.read_text()) for p in sorted((paths.RESULTS_CARD / "rows").glob("*.json")))
            if row.get("profile") == profile_name and not is_zero_shot(row)]
    written = []
    for variant in (v for v in POSE_VARIANTS if variants is None or v in variants):
        folder = paths.POLICY_CARD / variant
        summaries = {task: json.loads((folder / task / "summary.json").read_text()) for task in TASKS
                     if (folder / task / "summary.json").is_file()}
        if len(summaries) < len(TASKS):
            continue
        mine = [r for r in rows if r["method"] in METHODS and METHODS[r["method"]].variant is not None
                and METHODS[r["method"]].variant.name == variant]
        policy_video(profile, variant, video_seed, folder / "episode.mp4")
        written.append(write_policy_card(folder, variant, summaries, mine, "episode.mp4", profile_name, rows))
    return written
