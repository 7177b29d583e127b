"""The ``mor`` command line: one subcommand per job, parameters from a params.yaml profile."""

from __future__ import annotations

import os
import sys
from collections.abc import Callable
from functools import wraps
from pathlib import Path
from typing import Annotated, Any, TypeVar

import typer

from mor.config import DEFAULT_PARAMS, load_profile
from mor.errors import ConfigError, MorError
from pipelines import paths

app = typer.Typer(help="MOR: Mobile Object Rearrangement toolkit.", no_args_is_help=True, add_completion=False)
sim_app = typer.Typer(help="The simulator: oracle evaluation, rendered views and videos.", no_args_is_help=True)
bench_app = typer.Typer(help="Benchmarks that write JSON.", no_args_is_help=True)
app.add_typer(sim_app, name="sim")
app.add_typer(bench_app, name="bench")

F = TypeVar("F", bound=Callable[..., Any])

ProfileOption = Annotated[str, typer.Option("--profile", "-p", help="params.yaml profile: tiny, default or paper.")]
ParamsOption = Annotated[Path, typer.Option("--params", help="The parameters file.")]
TaskOption = Annotated[str, typer.Option("--task", "-t", help="pick, drop or rearrange.")]
TASK_NAMES = ("pick", "drop", "rearrange")


def one_line_errors(command: F) -> F:
    """Turn a MorError into one line on stderr and exit status 2."""

    @wraps(command)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return command(*args, **kwargs)
        except MorError as error:
            typer.echo(f"error: {error}", err=True)
            raise typer.Exit(2) from None

    return wrapper  # type: ignore[return-value]


def _check_task(task: str) -> str:
    if task not in TASK_NAMES:
        raise ConfigError(f"--task: unknown task {task!r}; choose one of {', '.join(TASK_NAMES)}")
    return task


@sim_app.command("oracle")
@one_line_errors
def sim_oracle(
    task: Annotated[list[str] | None, typer.Option("--task", "-t", help="Task(s): pick, drop, rearrange; repeat.")] = None,
    episodes: Annotated[int | None, typer.Option(help="Episodes per seed (default: the profile's).")] = None,
    seeds: Annotated[str | None, typer.Option(help="Comma-separated seeds (default: the profile's).")] = None,
    out: Annotated[Path, typer.Option(help="Metrics JSON to write.")] = Path("datasets/oracle/metrics.json"),
    profile: ProfileOption = "default",
    params: ParamsOption = DEFAULT_PARAMS,
) -> None:
    """Evaluate the ground-truth oracle; print and write mean +- std over seeds of each task's metrics."""
    from pipelines import sim_oracle

    config = load_profile(profile, params)
    tasks = [_check_task(name) for name in (task or list(TASK_NAMES))]
    seed_list = [int(s) for s in seeds.split(",")] if seeds else list(config.oracle.seeds)
    payload = sim_oracle.run(config, tasks, episodes or config.oracle.episodes, seed_list, out)
    for name, result in payload["tasks"].items():
        summary = "  ".join(f"{k} {v['mean']:.3f} ± {v['std']:.3f}" for k, v in result["summary"].items())
        typer.echo(f"{name:<10} {summary}")
    typer.echo(f"wrote {out}")


@sim_app.command("render")
@one_line_errors
def sim_render(
    task: TaskOption = "rearrange",
    seed: Annotated[int, typer.Option(help="Episode seed.")] = 0,
    out_dir: Annotated[Path, typer.Option(help="Folder for the PNGs.")] = Path("datasets/renders"),
    profile: ProfileOption = "default",
    params: ParamsOption = DEFAULT_PARAMS,
) -> None:
    """Write the first-person image and the top-down view of an episode's first state as PNG."""
    from pipelines.demo import render_views

    for path in render_views(load_profile(profile, params).sim, _check_task(task), seed, out_dir):
        typer.echo(f"wrote {path}")


@sim_app.command("video")
@one_line_errors
def sim_video(
    task: Annotated[str | None, typer.Option("--task", "-t", help="pick, drop or rearrange (default: the profile's).")] = None,
    policy: Annotated[str | None, typer.Option(help="oracle or random (default: the profile's).")] = None,
    seed: Annotated[int | None, typer.Option(help="Episode seed (default: the profile's).")] = None,
    out: Annotated[Path, typer.Option(help="Video file: .mp4 or .gif.")] = Path("datasets/renders/demo.mp4"),
    profile: ProfileOption = "default",
    params: ParamsOption = DEFAULT_PARAMS,
) -> None:
    """Play one episode and write it with the first-person and top-down views side by side."""
    from mor.config import DemoParams
    from pipelines.demo import record_video

    config = load_profile(profile, params)
    overrides = {"task": task and _check_task(task), "policy": policy, "seed": seed}
    demo = DemoParams(**{**config.demo.model_dump(), **{k: v for k, v in overrides.items() if v is not None}})
    record = record_video(config.sim, demo, out)
    typer.echo(f"wrote {out} ({record.steps} steps, metrics {record.metrics})")


@sim_app.command("demo")
@one_line_errors
def sim_demo(
    out_dir: Annotated[Path, typer.Option(help="Folder for the PNGs and the MP4.")] = Path("datasets/demo"),
    profile: ProfileOption = "default",
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
@one_line_errors
def collect_command(
    episodes: Annotated[int | None, typer.Option(help="Episodes in the collection (default: the profile's).")] = None,
    workers: Annotated[int | None, typer.Option(help="Worker processes or Ray tasks at once.")] = None,
    backend: Annotated[str | None, typer.Option(help="process (default) or ray.")] = None,
    rejected_from: Annotated[Path | None, typer.Option(help="Validation report whose rejected files to redo.")] = (
        paths.VALIDATION_REPORT),
    out_dir: Annotated[Path, typer.Option(help="Folder of episode MCAP files.")] = paths.EPISODES,
    profile: ProfileOption = "default",
    params: ParamsOption = DEFAULT_PARAMS,
) -> None:
    """Collect random-action episodes as MCAP files; resumes, and redoes what validation rejected."""
    from pipelines import collect

    if backend not in (None, "process", "ray"):
        raise ConfigError(f"--backend: unknown backend {backend!r}; choose 'process' or 'ray'")
    result = collect.run(load_profile(profile, params), out_dir, paths.COLLECT_STATS, rejected_from, workers,
                         backend, episodes)
    typer.echo(f"collected {result['collected']} episodes ({result['skipped']} already there), "
               f"{result['frames']} frames at {result['frames_per_s']:.0f} frames/s into {out_dir}")


@app.command("build-dataset")
@one_line_errors
def build_dataset_command(
    workers: Annotated[int | None, typer.Option(help="Worker processes (default: the profile's).")] = None,
    profile: ProfileOption = "default",
    params: ParamsOption = DEFAULT_PARAMS,
) -> None:
    """Write the manifest, one LeRobot dataset per split (8:1:1) and the dataset card."""
    from pipelines import build

    result = build.run(load_profile(profile, params), workers)
    typer.echo(f"dataset {result['dataset_version']}: {result['episodes']} episodes per split in {paths.LEROBOT}; "
               f"card {result['card']}; {result['seconds']['total']:.0f} s ({paths.BUILD_STATS})")


@app.command("validate")
@one_line_errors
def validate_command() -> None:
    """Check every episode file and split against the manifest; exit 1 if anything is wrong."""
    from pipelines import validate

    report = validate.run()
    for problem in report.problems:
        typer.echo(problem, err=True)
    typer.echo(f"checked {report.episodes_checked} episodes: {len(report.rejected)} rejected; "
               f"splits {report.splits}; report {paths.VALIDATION_REPORT}")
    if not report.ok:
        raise typer.Exit(1)


@app.command("import-real")
@one_line_errors
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
    from mor.data.real import import_rosbag, make_import_params, make_real_topics

    topics = make_real_topics(
        "import-real", image=image_topic, agent_pose=agent_pose_topic, object_pose=object_pose_topic,
        action=action_topic or None, cmd_vel=cmd_vel_topic or None, held=held_topic or None,
    )
    try:
        classes = [int(c) for c in object_classes.split(",")]
        target_list = [tuple(float(v) for v in pair.split(",")) for pair in targets.split(";")]
    except ValueError:
        raise ConfigError("--object-classes/--targets: expected e.g. --object-classes 0,7 --targets '1,2;-1,0.5'") from None
    import_params = make_import_params(
        "import-real", n_objects=len(classes), object_classes=classes, target_positions=target_list,
        episode_id=episode_id, fps=fps, image_size=image_size, timestamps=timestamps,
    )
    typer.echo(f"wrote {import_rosbag(bag, out_dir, topics, import_params)}")


@app.command("train-lnet")
@one_line_errors
def train_lnet_command(profile: ProfileOption = "default", params: ParamsOption = DEFAULT_PARAMS) -> None:
    """Train the L-Net on the train split (early stopping on validation); resumes from its last checkpoint."""
    from pipelines import train_lnet

    summary = train_lnet.run(load_profile(profile, params))
    typer.echo(f"trained {summary['steps']} steps on {summary['device']}; best validation loss "
               f"{summary['best_validation_loss']:.3f}; outputs in {paths.LNET}")


@app.command("calibrate-lnet")
@one_line_errors
def calibrate_lnet_command(profile: ProfileOption = "default", params: ParamsOption = DEFAULT_PARAMS) -> None:
    """Fit the uncertainty scales of the trained L-Net on the validation split."""
    from pipelines import calibrate_lnet

    result = calibrate_lnet.run(load_profile(profile, params))
    typer.echo(f"agent sigma x{result['agent_scale']:.3f}, objects sigma x{result['object_scale']:.3f}, "
               f"kappa x{result['kappa_scale']:.3f}; wrote {paths.LNET_CALIBRATION}")


@app.command("eval-lnet")
@one_line_errors
def eval_lnet_command(profile: ProfileOption = "default", params: ParamsOption = DEFAULT_PARAMS) -> None:
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
@one_line_errors
def ablate_lnet_command(
    study: Annotated[str, typer.Option(help="Which variants: actions (previous action as LSTM input or not) or "
                                            "object_head (global MLP or class attention).")] = "actions",
    steps: Annotated[int, typer.Option(help="Training steps per variant.")] = 300,
    episodes: Annotated[int, typer.Option(help="Validation/test episodes used to calibrate and score.")] = 100,
    profile: ProfileOption = "default",
    params: ParamsOption = DEFAULT_PARAMS,
) -> None:
    """Train the variants of one L-Net study at equal budgets and compare them on test."""
    from mor.lnet.params import ABLATIONS
    from pipelines import ablate_lnet

    result = ablate_lnet.run(load_profile(profile, params), study, steps, episodes)
    for name in ABLATIONS[study]:
        m = result[name]
        typer.echo(f"{name}: agent {m['agent_position_error_m']['median']:.3f} m, heading "
                   f"{m['heading_error_deg']['median']:.2f} deg, seen objects "
                   f"{m['object_position_error_m']['seen']['median']:.3f} m, NLL agent {m['nll']['agent_position']:.3f}")
    typer.echo(f"wrote {ablate_lnet.ABLATION / study / 'results.json'}")


@bench_app.command("sim")
@one_line_errors
def bench_sim(
    task: Annotated[list[str] | None, typer.Option("--task", "-t", help="Task(s) to time; repeat.")] = None,
    steps: Annotated[int, typer.Option(help="Steps per run.")] = 5000,
    repeats: Annotated[int, typer.Option(help="Runs per measurement; the median is reported.")] = 3,
    workers: Annotated[int, typer.Option(help="Worker processes for the parallel measurement.")] = os.cpu_count() or 2,
    image_size: Annotated[int, typer.Option(help="Image side, pixels.")] = 64,
    out: Annotated[Path, typer.Option(help="JSON to write.")] = Path("datasets/bench/sim.json"),
) -> None:
    """Environment steps/s with 64x64 rendering: one process, and one worker per core."""
    from mor.sim.bench import benchmark_sim

    from mor.sim import TASKS
    from pipelines.io import write_json

    env_ids = [TASKS[_check_task(name)][0] for name in (task or ["rearrange"])]
    result = benchmark_sim(env_ids, steps, repeats, workers, {"image_size": image_size})
    for env_id, numbers in result["results"].items():
        typer.echo(f"{env_id}: " + ", ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}"
                                            for k, v in numbers.items() if not k.startswith("runs")))
    typer.echo(f"wrote {write_json(out, result)}")


@bench_app.command("collect")
@one_line_errors
def bench_collect(
    episodes: Annotated[int, typer.Option(help="Episodes per run. Worker start-up (about 2 s) is in the wall "
                                         "clock, so short runs understate the rate of a long collection.")] = 200,
    repeats: Annotated[int, typer.Option(help="Runs per worker count; the median is reported.")] = 3,
    out: Annotated[Path, typer.Option(help="JSON to write.")] = Path("datasets/bench/collect.json"),
    profile: ProfileOption = "default",
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
@one_line_errors
def bench_lnet(
    repeats: Annotated[int, typer.Option(help="Timed runs per batch size; the median is reported.")] = 5,
    out: Annotated[Path, typer.Option(help="JSON to write.")] = Path("datasets/bench/lnet.json"),
    profile: ProfileOption = "default",
    params: ParamsOption = DEFAULT_PARAMS,
) -> None:
    """L-Net inference frames/s (PoseNet + one LSTM step) at batch 1 and 64 on the CPU."""
    from mor.lnet.bench import benchmark_lnet
    from pipelines.io import write_json

    config = load_profile(profile, params)
    result = benchmark_lnet(config.lnet.model, config.sim.image_size, [1, 64], repeats)
    for name, entry in result["results"].items():
        typer.echo(f"{name}: {entry['frames_per_s']:.0f} frames/s")
    typer.echo(f"wrote {write_json(out, result)}")


def main() -> None:  # pragma: no cover - console entry point
    app()


if __name__ == "__main__":  # pragma: no cover
    sys.exit(app())
