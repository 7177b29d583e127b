"""The ``mor`` command line: one subcommand per job, parameters from a params.yaml profile.

Commands live in groups (``app`` at the top, ``sim``, ``bench``); a new group is ``new_group(summary)`` added with
``app.add_typer(group, name=...)``. Every group turns a MorError from a command, and a usage error (a bad option
value, an unknown command), into one line on stderr and exit status 2, so commands need no error handling of
their own: raise ConfigError with a line that names the option and says what to do.
"""

from __future__ import annotations

import os
import sys
import typing
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Any

import typer
from typer import _click  # typer vendors click: its exceptions and contexts are these, not the `click` package's
from typer.core import TyperGroup

from mor.config import DEFAULT_PARAMS, active_profile, load_profile
from mor.errors import ConfigError, MorError
from mor.policy.variants import VARIANTS
from pipelines import paths


@contextmanager
def _one_line_errors() -> Iterator[None]:
    """Turn a MorError or a click usage error into ``error: ...`` on stderr and exit status 2."""
    try:
        yield
    except _click.exceptions.NoArgsIsHelpError:
        raise  # `mor sim` alone prints the group's help
    except _click.exceptions.UsageError as error:
        where = error.ctx.command_path if error.ctx is not None else "mor"
        message = " ".join(error.format_message().split())
        typer.echo(f"error: {where}: {message} (see {where} --help)", err=True)
        raise typer.Exit(2) from None
    except MorError as error:
        typer.echo(f"error: {error}", err=True)
        raise typer.Exit(2) from None


class _OneLineErrorGroup(TyperGroup):
    """A typer group whose parsing (``make_context``) and commands (``invoke``) fail in one line."""

    def make_context(self, info_name: str | None, args: list[str], parent: _click.Context | None = None,
                     **extra: Any) -> _click.Context:
        with _one_line_errors():
            return super().make_context(info_name, args, parent, **extra)

    def invoke(self, ctx: _click.Context) -> Any:
        with _one_line_errors():
            return super().invoke(ctx)


def new_group(summary: str) -> typer.Typer:
    """A command group of ``mor`` (bad input fails in one line; no arguments prints its help)."""
    return typer.Typer(cls=_OneLineErrorGroup, help=summary, no_args_is_help=True, add_completion=False)


app = new_group("MOR: Mobile Object Rearrangement toolkit.")
sim_app = new_group("The simulator: oracle evaluation, rendered views and videos.")
bench_app = new_group("Benchmarks that write JSON.")
app.add_typer(sim_app, name="sim")
app.add_typer(bench_app, name="bench")


@app.callback()
def root(ctx: typer.Context, setting: Annotated[str | None, typer.Option(
        "--setting", help="Run the command in the workspace of a setting of params.yaml (settings/<name>/: the "
                          "polygon arena, 1-5 objects).")] = None) -> None:
    """MOR: Mobile Object Rearrangement toolkit."""
    if setting is not None:
        from pipelines import settings  # noqa: PLC0415

        previous = settings.enter(setting)
        ctx.call_on_close(lambda: os.chdir(previous))

ProfileOption = Annotated[str | None, typer.Option(
    "--profile", "-p", help="params.yaml profile: tiny, default or paper (default: `profile:` in params.yaml).")]
ParamsOption = Annotated[Path, typer.Option("--params", help="The parameters file.")]
RepeatsOption = Annotated[int, typer.Option(min=1, help="Timed runs per measurement; the median is reported.")]
TaskOption = Annotated[str, typer.Option("--task", "-t", help="pick, drop or rearrange.")]
TASK_NAMES = ("pick", "drop", "rearrange")


def _check_choice(option: str, value: str, choices: tuple[str, ...]) -> str:
    """``value`` if it is one of ``choices``; ConfigError naming ``option`` (e.g. ``--task``) otherwise."""
    if value not in choices:
        raise ConfigError(f"{option}: unknown {option.lstrip('-')} {value!r}; choose one of {', '.join(choices)}")
    return value


def _check_task(task: str) -> str:
    return _check_choice("--task", task, TASK_NAMES)


def _parse_seeds(text: str, option: str = "--seeds") -> list[int]:
    """``--seeds 0,1,2`` -> [0, 1, 2]; ConfigError (naming ``option``) unless the items are distinct non-negative
    integers."""
    try:
        seeds = [int(item) for item in text.split(",")]
    except ValueError:
        seeds = []
    if not seeds or min(seeds) < 0 or len(set(seeds)) < len(seeds):
        raise ConfigError(f"{option}: expected distinct comma-separated non-negative integers such as 0,1,2 "
                          f"(got {text!r})")
    return seeds


@app.command("profile")
def profile_command(profile: ProfileOption = None, params: ParamsOption = DEFAULT_PARAMS) -> None:
    """Print the active profile's name and its resolved parameters (defaults filled in) as YAML."""
    import yaml

    name = active_profile(profile, params)
    resolved = load_profile(name, params).model_dump(mode="json")
    typer.echo(yaml.safe_dump({"profile": name, "params": resolved}, sort_keys=False), nl=False)


@sim_app.command("oracle")
def sim_oracle(
    task: Annotated[list[str] | None, typer.Option("--task", "-t", help="Task(s): pick, drop, rearrange; repeat.")] = None,
    episodes: Annotated[int | None, typer.Option(min=1, help="Episodes per seed (default: the profile's).")] = None,
    seeds: Annotated[str | None, typer.Option(help="Comma-separated seeds (default: the profile's).")] = None,
    out: Annotated[Path, typer.Option(help="Metrics JSON to write.")] = Path("datasets/oracle/metrics.json"),
    profile: ProfileOption = None,
    params: ParamsOption = DEFAULT_PARAMS,
) -> None:
    """Evaluate the ground-truth oracle; print and write mean +- std over seeds of each task's metrics."""
    from pipelines import sim_oracle

    config = load_profile(profile, params)
    tasks = [_check_task(name) for name in (task or list(TASK_NAMES))]
    seed_list = _parse_seeds(seeds) if seeds is not None else list(config.oracle.seeds)
    payload = sim_oracle.run(config, tasks, episodes or config.oracle.episodes, seed_list, out)
    for name, result in payload["tasks"].items():
        summary = "  ".join(f"{k} {v['mean']:.3f} ± {v['std']:.3f}" for k, v in result["summary"].items())
        typer.echo(f"{name:<10} {summary}")
    typer.echo(f"wrote {out}")


@sim_app.command("render")
def sim_render(
    task: TaskOption = "rearrange",
    seed: Annotated[int, typer.Option(min=0, help="Episode seed.")] = 0,
    out_dir: Annotated[Path, typer.Option(help="Folder for the PNGs.")] = Path("datasets/renders"),
    profile: ProfileOption = None,
    params: ParamsOption = DEFAULT_PARAMS,
) -> None:
    """Write the first-person image and the top-down view of an episode's first state as PNG."""
    from pipelines.demo import render_views

    for path in render_views(load_profile(profile, params).sim, _check_task(task), seed, out_dir):
        typer.echo(f"wrote {path}")


@sim_app.command("video")
def sim_video(
    task: Annotated[str | None, typer.Option("--task", "-t", help="pick, drop or rearrange (default: the profile's).")] = None,
    policy: Annotated[str | None, typer.Option(help=f"oracle, random, or a trained method: {', '.join(VARIANTS)}, "
                                                     "*_nearest_rule (default: the profile's).")] = None,
    seed: Annotated[int | None, typer.Option(min=0, help="Episode seed (default: the profile's).")] = None,
    out: Annotated[Path, typer.Option(help="Video file: .mp4 or .gif.")] = Path("datasets/renders/demo.mp4"),
    profile: ProfileOption = None,
    params: ParamsOption = DEFAULT_PARAMS,
) -> None:
    """Play one episode and write it with the first-person and top-down views side by side."""
    from mor.config import DemoParams, validated
    from mor.sim.views import check_video_path
    from pipelines.demo import record_video

    config = load_profile(profile, params)
    policies = typing.get_args(DemoParams.model_fields["policy"].annotation)
    if policy is not None and policy not in policies:
        from mor.eval.methods import METHODS
        from pipelines.evaluate import policy_video

        if METHODS[_check_choice("--policy", policy, tuple(METHODS))].variant is not None:  # a trained method: its hierarchy plays the full task
            if task not in (None, "rearrange"):
                raise ConfigError(f"--task: a trained policy plays the full task; use --task rearrange (got {task!r})")
            metrics = policy_video(config, policy, seed if seed is not None else config.demo.seed, check_video_path(out))
            typer.echo(f"wrote {out} (metrics {metrics})")
            return
    overrides = {"task": task and _check_task(task), "policy": policy and _check_choice("--policy", policy, policies),
                 "seed": seed}
    demo = validated(DemoParams, "sim video", **{**config.demo.model_dump(),
                                                 **{k: v for k, v in overrides.items() if v is not None}})
    record = record_video(config.sim, demo, check_video_path(out))
    typer.echo(f"wrote {out} ({record.steps} steps, metrics {record.metrics})")


@sim_app.command("demo")
def sim_demo(
    out_dir: Annotated[Path, typer.Option(help="Folder for the PNGs and the MP4.")] = Path("datasets/demo"),
    profile: ProfileOption = None,
    params: ParamsOption = DEFAULT_PARAMS,
) -> None:
    """The profile's demo episode: its first views as PNG and the whole episode as MP4."""
    from pipelines.demo import record_video, render_views

    config = load_profile(profile, params)
    for path in render_views(config.sim, config.demo.task, config.demo.seed, out_dir):
        typer.echo(f"wrote {path}")
    out = out_dir / f"{config.demo.task}_seed{config.demo.seed}_{config.demo.policy}.mp4"
    record = record_video(config.sim, config.demo, out)
    typer.echo(f"wrote {out} ({record.steps} steps, metrics {record.metrics})")


@app.command("collect")
def collect_command(
    episodes: Annotated[int | None, typer.Option(min=1, help="Episodes in the collection (default: the profile's).")] = None,
    workers: Annotated[int | None, typer.Option(min=1, help="Worker processes or Ray tasks at once.")] = None,
    backend: Annotated[str | None, typer.Option(help="process (default) or ray.")] = None,
    rejected_from: Annotated[Path | None, typer.Option(help="Validation report whose rejected files to redo.")] = (
        paths.VALIDATION_REPORT),
    out_dir: Annotated[Path, typer.Option(help="Folder of episode MCAP files.")] = paths.EPISODES,
    profile: ProfileOption = None,
    params: ParamsOption = DEFAULT_PARAMS,
) -> None:
    """Collect random-action episodes as MCAP files; resumes, and redoes what validation rejected."""
    from pipelines import collect

    if backend is not None:
        _check_choice("--backend", backend, ("process", "ray"))
    result = collect.run(load_profile(profile, params), out_dir, paths.COLLECT_STATS, rejected_from, workers,
                         backend, episodes)
    typer.echo(f"collected {result['collected']} episodes ({result['skipped']} already there), "
               f"{result['frames']} frames at {result['frames_per_s']:.0f} frames/s into {out_dir}")


@app.command("build-dataset")
def build_dataset_command(
    workers: Annotated[int | None, typer.Option(min=1, help="Worker processes (default: the profile's).")] = None,
    profile: ProfileOption = None,
    params: ParamsOption = DEFAULT_PARAMS,
) -> None:
    """Write the manifest, one LeRobot dataset per split (8:1:1) and the dataset card."""
    from pipelines import build

    result = build.run(load_profile(profile, params), workers)
    typer.echo(f"dataset {result['dataset_version']}: {result['episodes']} episodes per split in {paths.LEROBOT}; "
               f"card {result['card']}; {result['seconds']['total']:.0f} s ({paths.BUILD_STATS})")


@app.command("validate")
def validate_command(profile: ProfileOption = None, params: ParamsOption = DEFAULT_PARAMS) -> None:
    """Decode every episode file, check it and every split against the manifest and the profile; exit 1 if
    anything is wrong."""
    from pipelines import validate

    report = validate.run(load_profile(profile, params))
    for problem in report.problems:
        typer.echo(problem, err=True)
    typer.echo(f"checked {report.episodes_checked} episodes: {len(report.rejected)} rejected; "
               f"splits {report.splits}; report {paths.VALIDATION_REPORT}")
    if not report.ok:
        raise typer.Exit(1)


def parse_objects(object_classes: str, targets: str) -> tuple[list[int], list[tuple[float, ...]]]:
    """``--object-classes 0,7 --targets '1,2;-1,0.5'`` -> ([0, 7], [(1.0, 2.0), (-1.0, 0.5)]); ConfigError if not."""
    try:
        return ([int(c) for c in object_classes.split(",")],
                [tuple(float(v) for v in pair.split(",")) for pair in targets.split(";")])
    except ValueError:
        raise ConfigError("--object-classes/--targets: expected e.g. --object-classes 0,7 --targets '1,2;-1,0.5'") from None


@app.command("import-real")
def import_real_command(
    bag: Annotated[Path, typer.Argument(help="A ROS 2 rosbag2 recording: an .mcap file or its folder.")],
    object_classes: Annotated[str, typer.Option(help="Class id of each object, comma-separated (e.g. 0,7,13).")],
    targets: Annotated[str, typer.Option(help="Target x,y of each object in metres, ';'-separated.")],
    episode_id: Annotated[str | None, typer.Option(help="Episode id (default: real-<bag name>).")] = None,
    out_dir: Annotated[Path, typer.Option(help="Folder of real episode files.")] = paths.REAL_EPISODES,
    fps: Annotated[float, typer.Option(help="Frame rate to resample onto.")] = 10.0,
    image_size: Annotated[int, typer.Option(help="Square image side, pixels (match the simulated data).")] = 64,
    image_topic: Annotated[str, typer.Option(help="sensor_msgs/CompressedImage topic.")] = "/camera/image_raw/compressed",
    agent_pose_topic: Annotated[str, typer.Option(help="Robot PoseStamped topic (ArUco tracker).")] = (
        "/tracker/robot_pose"),
    object_pose_topic: Annotated[str, typer.Option(help="Object PoseStamped topics, with {i} for the index.")] = (
        "/tracker/object_{i}/pose"),
    action_topic: Annotated[str, typer.Option(help="Executed-action topic ('' to use cmd_vel).")] = "/mor/action",
    cmd_vel_topic: Annotated[str, typer.Option(help="Twist topic used when there is no action topic.")] = "/cmd_vel",
    held_topic: Annotated[str, typer.Option(help="Held-object Int32 topic ('' for none).")] = "/mor/held",
    timestamps: Annotated[str, typer.Option(help="log (receive time) or header (message stamps).")] = "log",
) -> None:
    """Convert a real TurtleBot run into an episode MCAP; `mor build-dataset` then includes it (source=real)."""
    from mor.data.real import episode_path, import_rosbag, make_import_params, make_real_topics, resolve_bag

    topics = make_real_topics(
        "import-real", image=image_topic, agent_pose=agent_pose_topic, object_pose=object_pose_topic,
        action=action_topic or None, cmd_vel=cmd_vel_topic or None, held=held_topic or None,
    )
    classes, target_list = parse_objects(object_classes, targets)
    import_params = make_import_params(
        "import-real", n_objects=len(classes), object_classes=classes, target_positions=target_list,
        episode_id=episode_id, fps=fps, image_size=image_size, timestamps=timestamps,
    )
    existed = episode_path(out_dir, resolve_bag(bag), import_params).exists()
    path = import_rosbag(bag, out_dir, topics, import_params)
    typer.echo(f"{'replaced the existing episode' if existed else 'wrote'} {path}")


@app.command("train-lnet")
def train_lnet_command(profile: ProfileOption = None, params: ParamsOption = DEFAULT_PARAMS) -> None:
    """Train the L-Net on the train split (early stopping on validation); resumes from its last checkpoint."""
    from pipelines import train_lnet

    summary = train_lnet.run(load_profile(profile, params))
    typer.echo(f"trained {summary['steps']} steps on {summary['device']}; best validation loss "
               f"{summary['best_validation_loss']:.3f}; outputs in {paths.LNET}")


@app.command("calibrate-lnet")
def calibrate_lnet_command(profile: ProfileOption = None, params: ParamsOption = DEFAULT_PARAMS) -> None:
    """Fit the uncertainty scales of the trained L-Net on the validation split."""
    from pipelines import calibrate_lnet

    result = calibrate_lnet.run(load_profile(profile, params))
    typer.echo(f"agent sigma x{result['agent_scale']:.3f}, objects sigma x{result['object_scale']:.3f}, "
               f"kappa x{result['kappa_scale']:.3f}; wrote {paths.LNET_CALIBRATION}")


@app.command("eval-lnet")
def eval_lnet_command(profile: ProfileOption = None, params: ParamsOption = DEFAULT_PARAMS) -> None:
    """Evaluate the L-Net on the test split before and after calibration; write figures and the model card."""
    from pipelines import eval_lnet

    result = eval_lnet.run(load_profile(profile, params))
    for when in ("before_calibration", "after_calibration"):
        m = result[when]
        typer.echo(f"{when}: agent {m['agent_position_error_m']['median']:.3f} m, heading "
                   f"{m['heading_error_deg']['median']:.2f} deg, seen objects "
                   f"{m['object_position_error_m']['seen']['median']:.3f} m (medians); 2-sigma coverage agent "
                   f"{m['coverage']['agent_position']['2sigma']:.3f}, objects {m['coverage']['objects_seen']['2sigma']:.3f}")
    typer.echo(f"wrote {paths.LNET_CARD}")


@app.command("ablate-lnet")
def ablate_lnet_command(
    study: Annotated[str, typer.Option(help="Which variants (mor.lnet.params.ABLATIONS): actions, object_head, "
                                            "tracker or training_precision.")] = "actions",
    steps: Annotated[int, typer.Option(min=1, help="Window training steps per variant.")] = 300,
    pretrain_steps: Annotated[int | None, typer.Option(min=0, help="PoseNet pretraining steps per variant (default: "
                                                                    "the profile's).")] = None,
    episodes: Annotated[int, typer.Option(min=1, help="Validation/test episodes used to calibrate and score.")] = 100,
    profile: ProfileOption = None,
    params: ParamsOption = DEFAULT_PARAMS,
) -> None:
    """Train the variants of one L-Net study at equal budgets and compare them on test."""
    from mor.lnet.params import ABLATIONS
    from pipelines import ablate_lnet

    result = ablate_lnet.run(load_profile(profile, params), study, steps, episodes, pretrain_steps)
    for name in ABLATIONS[study]:
        m = result[name]
        typer.echo(f"{name}: agent {m['agent_position_error_m']['median']:.3f} m, heading "
                   f"{m['heading_error_deg']['median']:.2f} deg, seen objects "
                   f"{m['object_position_error_m']['seen']['median']:.3f} m, NLL agent {m['nll']['agent_position']:.3f}")
    typer.echo(f"wrote {ablate_lnet.ABLATION / study / 'results.json'}")


@bench_app.command("sim")
def bench_sim(
    task: Annotated[list[str] | None, typer.Option("--task", "-t", help="Task(s) to time; repeat.")] = None,
    steps: Annotated[int, typer.Option(min=1, help="Steps per run.")] = 5000,
    repeats: Annotated[int, typer.Option(min=1, help="Runs per measurement; the median is reported.")] = 3,
    workers: Annotated[int, typer.Option(min=1, help="Worker processes for the parallel measurement.")] = (
        os.cpu_count() or 2),
    image_size: Annotated[int, typer.Option(help="Image side, pixels (the simulator's bounds apply).")] = 64,
    out: Annotated[Path, typer.Option(help="JSON to write.")] = Path("datasets/bench/sim.json"),
) -> None:
    """Environment steps/s with 64x64 rendering: one process, and one worker per core."""
    from mor.sim import TASKS
    from mor.sim.bench import benchmark_sim
    from mor.sim.config import make_sim_config
    from pipelines.io import write_json

    env_ids = [TASKS[_check_task(name)][0] for name in (task or ["rearrange"])]
    make_sim_config("bench sim", image_size=image_size)  # checked here: a bad size would fail inside every worker
    result = benchmark_sim(env_ids, steps, repeats, workers, {"image_size": image_size})
    for env_id, numbers in result["results"].items():
        typer.echo(f"{env_id}: " + ", ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}"
                                            for k, v in numbers.items() if not k.startswith("runs")))
    typer.echo(f"wrote {write_json(out, result)}")


@bench_app.command("collect")
def bench_collect(
    episodes: Annotated[int, typer.Option(min=1, help="Episodes per run. Worker start-up (about 2 s) is in the wall "
                                         "clock, so short runs understate the rate of a long collection.")] = 200,
    repeats: Annotated[int, typer.Option(min=1, help="Runs per worker count; the median is reported.")] = 3,
    out: Annotated[Path, typer.Option(help="JSON to write.")] = Path("datasets/bench/collect.json"),
    profile: ProfileOption = None,
    params: ParamsOption = DEFAULT_PARAMS,
) -> None:
    """Collection frames/s end to end with one and two workers, bytes per frame, paper-profile projection."""
    from mor.data.bench import benchmark_collect
    from mor.data.collect import CollectionSpec
    from pipelines.io import write_json

    config = load_profile(profile, params)
    spec = CollectionSpec(config.sim, config.collect.exploration, config.collect.seed, config.collect.episode_steps,
                          config.collect.fps)
    result = benchmark_collect(spec, episodes, [1, 2], repeats)
    for name, entry in result["results"].items():
        typer.echo(f"{name}: {entry['frames_per_s']:.0f} frames/s")
    projection = result["paper_profile_projection"]
    typer.echo(f"{result['bytes_per_frame']:.0f} bytes/frame; paper profile ({projection['episodes']} episodes): "
               f"{projection['hours']:.2f} h, {projection['disk_gb']:.1f} GB")
    typer.echo(f"wrote {write_json(out, result)}")


@bench_app.command("lnet")
def bench_lnet(
    repeats: RepeatsOption = 5,
    n_envs: Annotated[int, typer.Option(min=1, help="Environments of the streaming measurement.")] = 8,
    steps: Annotated[int, typer.Option(min=1, help="Vector steps per streaming run.")] = 50,
    out: Annotated[Path, typer.Option(help="JSON to write.")] = Path("datasets/bench/lnet.json"),
    profile: ProfileOption = None,
    params: ParamsOption = DEFAULT_PARAMS,
) -> None:
    """L-Net inference frames/s at batch 1 and 64, and its streaming step (eager; compiled in float32 and with a
    bfloat16 encoder) beside the environments' own rendered steps at batch --n-envs in the same run (one torch
    thread, one render thread). The streaming step is the committed L-Net's with its calibration where
    cards/lnet/model.pt exists (how far bfloat16 moves the estimates depends on the weights), else random weights."""
    os.environ.setdefault("LP_NUM_THREADS", "1")  # one llvmpipe render thread, as in mor bench sim
    import torch

    from mor.lnet.bench import benchmark_lnet, benchmark_streaming
    from mor.lnet.calibration_file import chosen_calibration, recorded_settings
    from mor.lnet.model import LNet
    from mor.lnet.runtime import load_lnet
    from pipelines.io import write_json

    torch.set_num_threads(1)
    config = load_profile(profile, params)
    result = benchmark_lnet(config.lnet.model, config.sim.image_size, [1, 64], repeats)
    for name, entry in result["results"].items():
        typer.echo(f"{name}: {entry['frames_per_s']:.0f} frames/s")
    committed = paths.LNET_CARD / "model.pt"
    runner = load_lnet(committed) if committed.is_file() else None
    if runner is not None and (runner.config, runner.image_size, recorded_settings(runner.fitted)) == (
            config.lnet.model, config.sim.image_size, config.lnet.chosen_settings()):
        model, fitted, weights = runner.model, runner.fitted, committed.as_posix()
    else:  # none committed, or one of another config than this profile's
        model = LNet(config.lnet.model)
        fitted = chosen_calibration(config.lnet.chosen_settings())
        weights = "random"
    streaming = result["streaming"] = benchmark_streaming(model, fitted, config.sim, n_envs, steps, repeats)
    streaming["weights"] = weights
    typer.echo(f"streaming at batch {n_envs}: L-Net {streaming['lnet_frames_per_s']:.0f} frames/s, environments "
               f"{streaming['env_frames_per_s']:.0f} frames/s, ratio {streaming['lnet_over_env']:.2f}")
    for name in ("compiled", "compiled_bfloat16"):
        fused = streaming[name]
        typer.echo(f"{name} step: L-Net {fused['lnet_frames_per_s']:.0f} frames/s, ratio "
                   f"{fused['lnet_over_env']:.2f} ({fused['over_eager']:.2f}x the eager step; estimates within "
                   f"{fused['largest_difference']:.1e}, object means within "
                   f"{fused['difference_by_array']['object_mean']:.1e} m)")
    typer.echo(f"wrote {write_json(out, result)}")


from pipelines import cli_policy  # noqa: E402,F401 - registers the `policy` and `eval` groups on `app`
from pipelines import cli_robot  # noqa: E402,F401 - registers the `robot` group and `bench robot` on `app`


def main() -> None:  # pragma: no cover - console entry point
    app()


if __name__ == "__main__":  # pragma: no cover
    sys.exit(app())
