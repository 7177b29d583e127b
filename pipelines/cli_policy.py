"""The ``mor policy`` and ``mor eval`` command groups (registered on ``pipelines.cli.app``)."""

from __future__ import annotations

from typing import Annotated

import typer

from mor.config import DEFAULT_PARAMS, load_profile
from mor.errors import ConfigError
from mor.policy.features import TASKS
from mor.policy.observations import VARIANTS
from pipelines import paths
from pipelines.cli import ParamsOption, ProfileOption, app, new_group

policy_app = new_group("Policies: train the pick, drop and decision policies of an observation variant.")
eval_app = new_group("Evaluation: score methods with the protocol and gather the results card.")
app.add_typer(policy_app, name="policy")
app.add_typer(eval_app, name="eval")


@policy_app.command("train")
def policy_train(
    variant: Annotated[str, typer.Option("--variant", "-v", help=f"One of {', '.join(VARIANTS)}.")],
    task: Annotated[list[str] | None, typer.Option("--task", "-t", help="pick, drop, decision (repeat; default: all, "
                                                                         "in that order).")] = None,
    profile: ProfileOption = "default",
    params: ParamsOption = DEFAULT_PARAMS,
) -> None:
    """Train (or resume) a variant's policies; outputs in datasets/policy/<variant>/ and cards/policy/<variant>/."""
    from pipelines import train_policy  # noqa: PLC0415

    if variant not in VARIANTS:
        raise ConfigError(f"--variant: unknown variant {variant!r}; choose one of {', '.join(VARIANTS)}")
    tasks = tuple(task or TASKS)
    for name in tasks:
        if name not in TASKS:
            raise ConfigError(f"--task: unknown task {name!r}; choose one of {', '.join(TASKS)}")
    for summary in train_policy.run(load_profile(profile, params), variant, tasks):
        typer.echo(f"{summary['label']}: {summary['steps']} steps; policy in {paths.POLICY_CARD / variant}")


@eval_app.command("run")
def eval_run(
    method: Annotated[str, typer.Option("--method", "-m", help="gt_pose, lnet, lnet_no_uncertainty, "
                                                                "*_nearest_rule, oracle or random.")],
    profile: ProfileOption = "default",
    params: ParamsOption = DEFAULT_PARAMS,
) -> None:
    """Play the protocol's episodes with a method; per-episode records in datasets/eval/, its row in cards/results/."""
    from pipelines import evaluate  # noqa: PLC0415

    row = evaluate.run(load_profile(profile, params), profile, method)
    summary = ", ".join(f"{k} {v['mean']:.3f} ± {v['std']:.3f}" for k, v in row["metrics"].items())
    typer.echo(f"{method}: {summary}")


@eval_app.command("results")
def eval_results(profile: ProfileOption = "default") -> None:
    """Gather every method's row of this profile into cards/results/results.json."""
    from pipelines import evaluate  # noqa: PLC0415

    typer.echo(f"wrote {evaluate.collect_results(profile)}")
