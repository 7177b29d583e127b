"""The ``mor policy`` and ``mor eval`` command groups (registered on ``pipelines.cli.app``)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from mor.config import DEFAULT_PARAMS, active_profile, load_profile, validated
from mor.policy.params import EvalParams
from mor.errors import ConfigError
from mor.policy.names import TASKS
from mor.policy.variants import OURS, VARIANTS, Variant
from pipelines import paths
from pipelines.cli import ParamsOption, ProfileOption, RepeatsOption, _parse_seeds, app, bench_app, new_group

policy_app = new_group("Policies: train the pick, drop and decision policies of an observation variant.")
eval_app = new_group("Evaluation: score methods with the protocol and gather the results card.")
app.add_typer(policy_app, name="policy")
app.add_typer(eval_app, name="eval")


VariantOption = Annotated[str, typer.Option("--variant", "-v", help=f"One of {', '.join(VARIANTS)}.")]


@policy_app.command("train")
def policy_train(
    variant: VariantOption,
    task: Annotated[list[str] | None, typer.Option("--task", "-t", help="pick, drop, decision (repeat; default: all, "
                                                                         "in that order).")] = None,
    seed: Annotated[str | None, typer.Option("--seed", help="Training seed(s), e.g. 0 or 0,1,2 (default: the "
                                                            "profile's policy.training_seeds).")] = None,
    jobs: Annotated[int, typer.Option(min=1, help="Seeds trained at once (worker processes or Ray tasks).")] = 1,
    backend: Annotated[str, typer.Option(help="process (this machine) or ray (Ray tasks; a local Ray instance "
                                              "unless one is running).")] = "process",
    more_steps: Annotated[int | None, typer.Option(
        "--more-steps", min=1, help="A budget study: continue each task's committed policy (cards/policy/) for this many "
                             "more steps; the card's policy is replaced, so run it in a copy of the repository.")
    ] = None,
    profile: ProfileOption = None,
    params: ParamsOption = DEFAULT_PARAMS,
) -> None:
    """Train (or resume) a variant's policies, one run per training seed; outputs in datasets/policy/<variant>/ and
    cards/policy/<variant>/ (seed S > 0: their seed_S/ folders)."""
    from pipelines import train_policy  # noqa: PLC0415

    chosen = _variant(variant)
    tasks = tuple(task or TASKS)
    for name in tasks:
        if name not in TASKS:
            raise ConfigError(f"--task: unknown task {name!r}; choose one of {', '.join(TASKS)}")
    if backend not in ("process", "ray"):
        raise ConfigError(f"--backend: unknown backend {backend!r}; choose process or ray")
    config = load_profile(profile, params)
    seeds = _parse_seeds(seed, "--seed") if seed is not None else config.policy.training_seeds
    for summaries in train_policy.run_seeds(config, chosen, tasks, seeds, jobs, backend, more_steps):
        for summary in summaries:
            typer.echo(f"{summary['label']}: {summary['steps']} steps")


@policy_app.command("pretrain-encoder")
def policy_pretrain_encoder(profile: ProfileOption = None, params: ParamsOption = DEFAULT_PARAMS) -> None:
    """Learn the pixel baselines' frame encoder without labels (policy.baseline.encoder: autoencoder): an
    autoencoder on frames of the exploration walk; its weights, figure and card in cards/baseline_encoder/."""
    from pipelines import pretrain_encoder  # noqa: PLC0415

    summary = pretrain_encoder.run(load_profile(profile, params))
    typer.echo(f"{paths.ENCODER_CARD}: held-out reconstruction MSE {summary['validation_mse']:.5f} (mean frame "
               f"{summary['mean_frame_validation_mse']:.5f})")


@policy_app.command("plan")
def policy_plan(
    variant: Annotated[list[str] | None, typer.Option("--variant", "-v", help="Variant(s) (repeat; default: the "
                                                                               "profile's policy.variants).")] = None,
    profile: ProfileOption = None,
    params: ParamsOption = DEFAULT_PARAMS,
) -> None:
    """Print what `mor policy train` will run for each variant: its observation (policy.observation), each task's
    steps, start point and PPO parameters, after the setting's overrides and policy.lnet_steps."""
    from pipelines import train_policy  # noqa: PLC0415

    config = load_profile(profile, params)
    for name in variant or list(config.policy.variants):
        typer.echo(f"{name}:")
        chosen = _variant(name)
        if not chosen.is_baseline:
            settings = config.policy.observation.model_dump()
            typer.echo(f"  observation: uncertainty {chosen.uncertainty}, search {chosen.search}, "
                       + ", ".join(f"{key} {value}" for key, value in settings.items()))
        for task_plan in train_policy.plan(config, chosen, seed=config.policy.training_seeds[0]):
            ppo = task_plan.params.model_dump()
            steps = ppo.pop("steps")
            typer.echo(f"  {task_plan.task}: {steps:,} steps, {task_plan.why}"
                       + (f" ({task_plan.start})" if task_plan.start is not None else ""))
            typer.echo("    " + ", ".join(f"{key} {value}" for key, value in ppo.items()))


def _variant(name: str) -> Variant:
    """The variant ``--variant`` names; one error line listing the known ones otherwise."""
    if name not in VARIANTS:
        raise ConfigError(f"--variant: unknown variant {name!r}; choose one of {', '.join(VARIANTS)}")
    return VARIANTS[name]


@policy_app.command("convert")
def policy_convert(
    files: Annotated[list[Path] | None, typer.Argument(help="policy.pth files (default: every committed one, "
                                                             "cards/policy/ and settings/*/cards/policy/).")] = None,
) -> None:
    """Convert policy files from SB3's pickled format to MOR's safe one, once. This UNPICKLES them (it runs what
    they contain): only for files you trust, such as the ones this repository committed. The weights come out
    bit-identical, and the results rows that recorded the old files' digests are re-pointed at the new ones."""
    from pipelines import convert_policies  # noqa: PLC0415

    targets = files or sorted([*paths.POLICY_CARD.glob("*/*/policy.pth"),
                               *paths.SETTINGS.glob(f"*/{paths.POLICY_CARD}/*/*/policy.pth")])
    for path in targets:
        if not path.is_file():
            raise ConfigError(f"{path}: no such policy file")
    converted = convert_policies.run(targets)
    for path, old, new in converted:
        typer.echo(f"converted {path} (digest {old} -> {new}; weights identical)")
    typer.echo(f"{len(converted)} of {len(targets)} policy files converted; the others were already safe")


@eval_app.command("run")
def eval_run(
    method: Annotated[str, typer.Option("--method", "-m", help=f"A variant ({', '.join(VARIANTS)}), "
                                                                "*_nearest_rule, oracle or random.")],
    zero_shot: Annotated[bool, typer.Option("--zero-shot", help="In a setting (mor --setting NAME ...): play the "
                                                                "main workspace's policies (paper Table 3).")] = False,
    training_seed: Annotated[int, typer.Option("--training-seed", min=0, help="Play the policies of this training "
                                                                              "run (mor policy train --seed).")] = 0,
    seeds: Annotated[str | None, typer.Option(help="Evaluation seeds outside the protocol, e.g. 100,101 (held-out "
                                                   "episodes: the row says episodes held_out).")] = None,
    workers: Annotated[int | None, typer.Option(min=1, help="Jobs (one per task and seed) at once (default: the "
                                                            "profile's evaluate.workers).")] = None,
    backend: Annotated[str | None, typer.Option(help="process (this machine) or ray (Ray tasks; a local Ray "
                                                     "instance unless one is running).")] = None,
    profile: ProfileOption = None,
    params: ParamsOption = DEFAULT_PARAMS,
) -> None:
    """Play the protocol's episodes with a method; per-episode records in datasets/eval/, its row in cards/results/."""
    from pipelines import evaluate  # noqa: PLC0415

    name = active_profile(profile, params)
    config = load_profile(name, params)
    held_out = _parse_seeds(seeds) if seeds is not None else None
    if held_out is not None and set(held_out) & set(config.evaluate.seeds):
        raise ConfigError(f"--seeds: {sorted(set(held_out) & set(config.evaluate.seeds))} are the protocol's own "
                          f"evaluation seeds ({config.evaluate.seeds}); held-out seeds must differ")
    overrides = {key: value for key, value in (("workers", workers), ("backend", backend), ("seeds", held_out))
                 if value is not None}
    if overrides:
        config = config.model_copy(update={"evaluate": validated(
            EvalParams, "--workers/--backend/--seeds", **{**config.evaluate.model_dump(), **overrides})})
    row = evaluate.run(config, name, method, zero_shot=zero_shot, training_seed=training_seed,
                       held_out=held_out is not None)
    summary = ", ".join(f"{k} {v['mean']:.3f} ± {v['std']:.3f}" for k, v in row["metrics"].items())
    typer.echo(f"{method}: {summary}")


@eval_app.command("probe-pick")
def eval_probe_pick(
    variant: VariantOption,
    training_seed: Annotated[int, typer.Option(min=0, help="The training run whose Pick skill to probe.")] = 0,
    episodes: Annotated[int, typer.Option(min=1, help="Pick episodes to play.")] = 100,
    seed: Annotated[int, typer.Option(min=0, help="Reset seed of the first episode (then +1 each).")] = 1000,
    out: Annotated[Path | None, typer.Option(help="JSON to write (default: cards/results/pick_probe/<variant>"
                                                   ".seed_<S>[.negative_information].json).")] = None,
    negative_information: Annotated[bool, typer.Option(
        help="Track with the filter's negative information (mor.lnet.unseen) switched on for this probe, over the "
             "calibration fitted without it: a first look at the rule, not a row.")] = False,
    against: Annotated[Path | None, typer.Option(
        help="Another probe's JSON on the same episodes: this probe's success minus its, per episode, with a 95% "
             "interval and its verdict.")] = None,
    profile: ProfileOption = None,
    params: ParamsOption = DEFAULT_PARAMS,
) -> None:
    """Where a Pick skill goes wrong: per step, whether the target (or another object) was within PICK's reach, in
    view, or out of view, and the skill's PICK probability there (mor.eval.pick_probe)."""
    from mor.eval.pick_probe import against_probe  # noqa: PLC0415
    from pipelines.evaluate import pick_probe, read_probe  # noqa: PLC0415
    from pipelines.io import write_json  # noqa: PLC0415

    baseline = None if against is None else read_probe(against, episodes, seed)
    result = pick_probe(load_profile(profile, params), _variant(variant).name, training_seed, episodes, seed,
                        negative_information)
    typer.echo(f"success {result['success']:.3f}, target ever in reach {result['target_ever_in_reach']:.3f}, "
               f"median closest approach {result['median_closest_m']:.2f} m")
    for name, probability in result["pick_probability"].items():
        typer.echo(f"  {name}: {result['steps'][name]} steps, mean P(PICK) "
                   + ("-" if probability is None else f"{probability:.4f}"))
    typer.echo("episodes ended by an obstructed MOVE into " + ", ".join(
        f"{what}: {count}" for what, count in result["obstructed_by"].items()))
    for row in result["target_belief_by_range"]:
        if row["steps"]:
            span = f"{row['from_m']:.2f}-" + ("" if row["to_m"] is None else f"{row['to_m']:.2f}") + " m"
            typer.echo(f"  target in view at {span}: {row['steps']} steps, range error {row['median_range_error_m']:+.3f}"
                       f" m, position error {row['median_position_error_m']:.3f} m, sigma {row['median_sigma_m']:.3f} m,"
                       f" inside its 95% ellipse {row['inside_95_ellipse']:.2f}")
    if baseline is not None:
        result["against"] = against_probe(result, baseline, str(against))
        difference = result["against"]["difference"]
        low, high = difference["ci95"]
        typer.echo(f"success minus {against}'s ({baseline['success']:.3f}), per episode: {difference['mean']:+.3f} "
                   f"[{low:+.3f}, {high:+.3f}] {difference['verdict']}")
    rule = ".negative_information" if negative_information else ""
    path = out or paths.RESULTS_CARD / "pick_probe" / f"{variant}.seed_{training_seed}{rule}.json"
    typer.echo(f"wrote {write_json(path, result)}")


@eval_app.command("results")
def eval_results(profile: ProfileOption = None) -> None:
    """Gather every method's row of this profile into cards/results/results.json, its card and README.md's table."""
    from pipelines import evaluate  # noqa: PLC0415

    typer.echo(f"wrote {evaluate.collect_results(active_profile(profile))}")


RowsArgument = Annotated[str, typer.Argument(help="FOLDER:METHOD: the method's rows in a folder of row files, e.g. "
                                                 "cards/results/rows:lnet (every training run's on the protocol's episodes; "
                                                 "lnet.held_out: on held-out ones).")]


@eval_app.command("compare")
def eval_compare(
    a: RowsArgument,
    b: RowsArgument,
    out: Annotated[Path | None, typer.Option(help="JSON to write the differences to.")] = None,
    profile: ProfileOption = None,
    params: ParamsOption = DEFAULT_PARAMS,
) -> None:
    """Each metric's difference a - b between two rows, with the results card's statistics (a 95% interval over
    training runs and episodes, and its verdict): e.g. rows evaluated in another workspace or with another params
    file against the committed ones."""
    from mor.eval.results import compare, method_row  # noqa: PLC0415
    from pipelines.io import write_json  # noqa: PLC0415

    resamples = load_profile(profile, params).evaluate.bootstrap_resamples
    rows = []
    for name, value in (("a", a), ("b", b)):
        folder, _, method = value.rpartition(":")
        if not folder or not method:
            raise ConfigError(f"{name}: {value!r} is not FOLDER:METHOD (e.g. cards/results/rows:lnet)")
        rows.append(method_row(Path(folder), method, resamples))
    found = compare(*rows, resamples, names=(a, b))
    for entry in found:
        low, high = entry["difference"]["ci95"]
        sides = ", ".join(f"{name} {row['metrics'][entry['metric']]['mean']:.3f}" for name, row in zip("ab", rows))
        typer.echo(f"{entry['metric']}: {entry['difference']['mean']:+.3f} [{low:+.3f}, {high:+.3f}] "
                   f"{entry['verdict']} ({sides}; a: training seeds {entry['training_seeds'][a]}, b: "
                   f"{entry['training_seeds'][b]})")
    if out is not None:  # each side's metrics (mean, std, 95% interval over its runs) beside the differences
        metrics = {name: row["metrics"] for name, row in zip((a, b), rows)}
        typer.echo(f"wrote {write_json(out, {'a': a, 'b': b, 'metrics': metrics, 'comparisons': found})}")


@bench_app.command("policy")
def bench_policy_command(
    seconds: Annotated[float, typer.Option(min=1.0, help="Seconds per measurement (bounds the run's time).")] = 10.0,
    repeats: RepeatsOption = 3,
    out: Annotated[Path, typer.Option(help="JSON to write.")] = Path("datasets/bench/policy.json"),
    lnet: Annotated[bool, typer.Option("--lnet/--no-lnet", help="Also the rendered paths with the committed L-Net "
                                       "(--no-lnet: the ground truth's paths only, e.g. to compare learner "
                                       "settings).")] = True,
    profile: ProfileOption = None,
    params: ParamsOption = DEFAULT_PARAMS,
) -> None:
    """Env steps/s without rendering (the ground truth's path) and with rendering + the L-Net, and PPO training
    steps/s on both, all in one run (the profile's pick PPO settings; the committed L-Net)."""
    from mor.policy.bench import bench_policy  # noqa: PLC0415
    from pipelines.io import write_json  # noqa: PLC0415
    from mor.policy.workspace import committed_lnet  # noqa: PLC0415
    from pipelines.workspaces import workspace_record  # noqa: PLC0415

    config = load_profile(profile, params)
    runner = committed_lnet(workspace_record(Path("."), config), OURS, config.lnet) if lnet else None
    result = bench_policy(config.sim, config.policy.pick, config.policy.observation, runner, seconds, repeats)
    typer.echo(", ".join(f"{k} {v:.0f} steps/s" for k, v in result["steps_per_second"].items()))
    typer.echo(f"wrote {write_json(out, result)}")


@eval_app.command("tables")
def eval_tables(
    table: Annotated[list[int] | None, typer.Option("--table", min=1, max=4, help="Table number (repeat; default: "
                                                                                   "every table).")] = None,
) -> None:
    """Print Tables 1-4 from cards/results/results.json; a table with rows missing is one error naming them."""
    import json  # noqa: PLC0415

    from mor.eval.tables import LEGEND, TABLES, require_complete, table_markdown  # noqa: PLC0415

    path = paths.RESULTS_CARD / "results.json"
    if not path.is_file():
        raise ConfigError(f"{path}: no results yet; run mor eval run --method <method>, then mor eval results")
    rows = json.loads(path.read_text())["rows"]
    for number in table or sorted(TABLES):
        if number not in TABLES:
            raise ConfigError(f"--table: Table {number} is not built yet; available: {', '.join(map(str, TABLES))}")
        require_complete(TABLES[number], rows)
        typer.echo(f"Table {number}: {TABLES[number].title}\n{table_markdown(TABLES[number], rows)}\n")
    typer.echo(LEGEND)


@eval_app.command("cards")
def eval_cards(
    variant: Annotated[list[str] | None, typer.Option("--variant", "-v", help="Only these variants (repeat; "
                                                      "default: every trained one).")] = None,
    profile: ProfileOption = None,
    params: ParamsOption = DEFAULT_PARAMS,
) -> None:
    """Write a policy card and an episode video for every trained variant (cards/policy/<variant>/)."""
    from pipelines import evaluate  # noqa: PLC0415

    chosen = [_variant(v).name for v in variant] if variant else None
    name = active_profile(profile, params)
    for path in evaluate.write_policy_cards(load_profile(name, params), name, chosen):
        typer.echo(f"wrote {path}")
