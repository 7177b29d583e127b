"""The ``mor robot`` command group and ``mor bench robot`` (registered on ``pipelines.cli.app``)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from mor.config import DEFAULT_PARAMS, load_profile
from mor.errors import ConfigError
from mor.policy.variants import GROUND_TRUTH, POSE_VARIANTS
from pipelines import paths
from pipelines.cli import (ParamsOption, ProfileOption, RepeatsOption, _parse_seeds, app, bench_app, new_group,
                           parse_objects)

if TYPE_CHECKING:
    from mor.robot.pose import RobotTask

robot_app = new_group("The robot controller: sim-as-robot runs, replays of recordings, a live ROS 2 node.")
app.add_typer(robot_app, name="robot")

MethodOption = Annotated[str, typer.Option("--method", "-m", help=f"A method that reads a pose belief: one of "
                                                                   f"{', '.join(POSE_VARIANTS)} or *_nearest_rule.")]


@robot_app.command("sim")
def robot_sim(
    loop: Annotated[str, typer.Option(help="aruco_topdown (poses from the top camera's tags) or fpv_lnet (the "
                                           "first-person frames through the L-Net).")] = "aruco_topdown",
    method: MethodOption = GROUND_TRUTH.name,
    seeds: Annotated[str | None, typer.Option(help="Evaluation seeds, e.g. 0,1 (default: the profile's).")] = None,
    episodes: Annotated[int | None, typer.Option(min=1, help="Episodes per seed (default: the profile's).")] = None,
    profile: ProfileOption = None,
    params: ParamsOption = DEFAULT_PARAMS,
) -> None:
    """Sim-as-robot: the controller plays the evaluation's episodes in the simulator; each run recorded (rosbag2
    MCAP) and written as an episode under datasets/robot/<loop>/; the row in cards/robot/results.json."""
    from pipelines import robot  # noqa: PLC0415

    row = robot.sim(load_profile(profile, params), loop, method, _parse_seeds(seeds) if seeds else None, episodes)
    success, pose = row["rearrange_success"], row["pose_error"]
    typer.echo(f"{loop} {method}: {row['episodes']} episodes, rearrange success {success['mean']:.3f} "
               f"[{success['ci95'][0]:.3f}, {success['ci95'][1]:.3f}], agent position error "
               f"{pose['agent_position_m']} m, heading {pose['heading_deg']} deg (medians), step "
               f"{row['step_latency_ms']} ms; wrote {paths.ROBOT_CARD / 'results.json'}")


@robot_app.command("card")
def robot_card() -> None:
    """Write cards/robot/README.md from cards/robot/results.json and the evaluation's rows."""
    from pipelines import robot  # noqa: PLC0415

    typer.echo(f"wrote {robot.card()}")


SourceOption = Annotated[str, typer.Option(help="Pose source: aruco (the top camera's tags) or lnet (the "
                                                "first-person frames through the L-Net).")]
ObjectsOption = Annotated[str | None, typer.Option("--object-classes", help="Class id of each object, comma-"
                                                   "separated (e.g. 0,7,13).")]
TargetsOption = Annotated[str | None, typer.Option(help="Target x,y of each object in metres, ';'-separated.")]


def _task(object_classes: str | None, targets: str | None, seed: int = 0) -> RobotTask | None:
    """The run's task from --object-classes and --targets (both or neither), checked as mor import-real's."""
    from mor.data.real import make_import_params  # noqa: PLC0415
    from pipelines import robot  # noqa: PLC0415

    if object_classes is None and targets is None:
        return None
    if object_classes is None or targets is None:
        raise ConfigError("--object-classes/--targets: give both (one class id and one x,y target per object)")
    classes, target_list = parse_objects(object_classes, targets)
    checked = make_import_params("--object-classes/--targets", n_objects=len(classes), object_classes=classes,
                                 target_positions=target_list)
    return robot.task_of(checked.object_classes, checked.target_positions, seed)


def _check_source(source: str) -> str:
    if source not in ("aruco", "lnet"):
        raise ConfigError(f"--source: unknown pose source {source!r}; choose aruco or lnet")
    return source


@robot_app.command("replay")
def robot_replay(
    bag: Annotated[Path, typer.Argument(help="A recorded run: a rosbag2 MCAP (a controller's recording or a "
                                             "TurtleBot bag with the top camera).")],
    method: MethodOption = GROUND_TRUTH.name,
    source: SourceOption = "aruco",
    object_classes: ObjectsOption = None,
    targets: TargetsOption = None,
    out: Annotated[Path | None, typer.Option(help="The replay's recording (default: "
                                                  "datasets/robot/replay/<bag>.mcap).")] = None,
    profile: ProfileOption = None,
    params: ParamsOption = DEFAULT_PARAMS,
) -> None:
    """Replay a recorded run through the controller: each camera frame is one step; the decisions are recorded
    and compared with the bag's own /mor/action."""
    from pipelines import robot  # noqa: PLC0415

    summary = robot.replay(load_profile(profile, params), bag, method, _check_source(source),
                           _task(object_classes, targets), out)
    agreement = (f"; {summary.agreeing} of {summary.compared} recorded actions decided again" if summary.compared
                 else "; the bag records no actions to compare")
    typer.echo(f"replayed {summary.steps} steps ({len(summary.notes)} stops){agreement}; wrote {summary.recording}"
               + (f" and {summary.episode}" if summary.episode else ""))


@robot_app.command("video")
def robot_video(
    recording: Annotated[Path, typer.Argument(help="A controller's recording (rosbag2 MCAP).")],
    out: Annotated[Path, typer.Option(help=".gif or .mp4 to write.")] = paths.ROBOT_CARD / "sim_as_robot.gif",
    every: Annotated[int, typer.Option(min=1, help="Keep every n-th frame (a smaller file).")] = 2,
    profile: ProfileOption = None,
    params: ParamsOption = DEFAULT_PARAMS,
) -> None:
    """A run's video: the top camera with the detected tags and the targets beside the first-person view."""
    from mor.sim.views import check_video_path  # noqa: PLC0415
    from pipelines import robot  # noqa: PLC0415

    typer.echo(f"wrote {robot.video(load_profile(profile, params), recording, check_video_path(out), every)}")


@robot_app.command("run")
def robot_run(
    object_classes: Annotated[str, typer.Option("--object-classes", help="Class id of each object, comma-separated "
                                                                         "(e.g. 0,7,13).")],
    targets: Annotated[str, typer.Option(help="Target x,y of each object in metres, ';'-separated.")],
    method: MethodOption = GROUND_TRUTH.name,
    source: SourceOption = "aruco",
    seed: Annotated[int, typer.Option(min=0, help="Seed of the skills' draws.")] = 0,
    max_steps: Annotated[int, typer.Option(min=1, help="Stop after this many actions.")] = 1000,
    profile: ProfileOption = None,
    params: ParamsOption = DEFAULT_PARAMS,
) -> None:
    """Drive a TurtleBot live with ROS 2 (needs rclpy: source your ROS 2 setup first; docs/robot.md). The run is
    recorded under datasets/robot/live/ and its episode written to datasets/real/."""
    from pipelines import robot  # noqa: PLC0415

    steps, recording = robot.live(load_profile(profile, params), method, _check_source(source),
                                  _task(object_classes, targets, seed), max_steps)
    typer.echo(f"{steps} actions; wrote {recording}")


@bench_app.command("robot")
def bench_robot(
    frames: Annotated[int, typer.Option(min=2, help="Frames of the sim-as-robot episode timed.")] = 200,
    repeats: RepeatsOption = 3,
    camera: Annotated[str | None, typer.Option(help="The simulated top camera's size WxH (default: the profile's "
                                                    "robot.top_camera), e.g. 640x480.")] = None,
    out: Annotated[Path, typer.Option(help="JSON to write.")] = Path("datasets/bench/robot.json"),
    profile: ProfileOption = None,
    params: ParamsOption = DEFAULT_PARAMS,
) -> None:
    """The controller's step on one core (torch.set_num_threads(1)): ArUco detection + the ground truth's policy,
    and the L-Net's step + ours; medians in ms against the 50 ms target; and the tags' pose errors on those frames."""
    os.environ.setdefault("LP_NUM_THREADS", "1")
    from mor.config import validated  # noqa: PLC0415
    from mor.sim.tags import TopCamera  # noqa: PLC0415
    from pipelines import robot  # noqa: PLC0415

    config = load_profile(profile, params)
    if camera is not None:
        try:
            width, height = (int(side) for side in camera.lower().split("x"))
        except ValueError:
            raise ConfigError(f"--camera: expected WIDTHxHEIGHT such as 640x480 (got {camera!r})") from None
        top = validated(TopCamera, "--camera", **{**config.robot.top_camera.model_dump(), "width": width,
                                                  "height": height})
        config = config.model_copy(update={"robot": config.robot.model_copy(update={"top_camera": top})})
    result = robot.bench(config, frames, repeats, out)
    quality = result["detection"]
    typer.echo(f"top camera {camera or 'as configured'}: robot's tag missed in {quality['agent_missed']} of "
               f"{quality['frames']} frames, object sightings missed {quality['object_sightings_missed']}; median "
               f"errors {quality['agent_position_m']} m, {quality['heading_deg']} deg")
    for loop, timing in result["loops"].items():
        typer.echo(f"{loop}: step {timing['step_ms']:.1f} ms (pose source {timing['pose_source_ms']:.1f} ms, "
                   f"policy {timing['policy_ms']:.1f} ms), median of {timing['steps']}")
    typer.echo(f"wrote {out}")
