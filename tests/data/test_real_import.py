"""Importing a real TurtleBot run: synthetic rosbag2 MCAP recordings with the TurtleBot3 / tracker topics
(30 Hz camera, 20 Hz robot pose, 5 Hz object poses, 2 Hz actions or 20 Hz cmd_vel) become episodes that
``read_episode`` reads back like simulated ones."""

from __future__ import annotations

import hashlib
import io
import math
from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np
import pytest
from mcap_ros2.writer import Writer as Ros2Writer
from PIL import Image

from mor.data.episode_io import read_episode
from mor.data.real import (
    ImportParams,
    RealBagError,
    RealTopics,
    executed_actions,
    import_rosbag,
    make_import_params,
    make_real_topics,
)
from mor.data.ros2_messages import MSGDEFS, stamp, twist, yaw_quaternion
from mor.data.schema import NO_ACTION
from mor.errors import ConfigError, MorError
from mor.sim.rules import Action

# --- a synthetic TurtleBot recording -------------------------------------------------------------------------------

BASE_NS = 1_700_000_123_000_000_000
IMAGE_W, IMAGE_H, BAND = 80, 60, 10  # 4:3 frames; the side bands (red) are what the centre crop removes


def wrap(angle: float) -> float:
    return math.atan2(math.sin(angle), math.cos(angle))


def default_agent(t: float) -> tuple[float, float, float]:
    """x, y (m), yaw (rad): the yaw crosses -pi at t = 0.48 s, so interpolation must unwrap it."""
    return -1.0 + 0.2 * t, 0.3 * math.sin(1.5 * t), wrap(-2.9 - 0.5 * t)


def default_objects(i: int, t: float) -> tuple[float, float]:
    """Object 1 is moved at t = 2 s; the others stay put."""
    if i == 1:
        return (2.0, -1.0) if t < 2.0 else (0.5, 0.5)
    return ((1.0, 1.0), None, (-2.0, 2.0), (0.0, -2.0), (2.0, 2.0))[i]  # type: ignore[return-value]


def image_colour(j: int) -> tuple[int, int, int]:
    """The centre colour of camera image j (so a frame tells which image it took)."""
    return (j * 5) % 250, 100, 200


def _image_bytes(j: int, image_format: str) -> tuple[bytes, str]:
    pixels = np.zeros((IMAGE_H, IMAGE_W, 3), np.uint8)
    pixels[:] = (255, 0, 0)
    pixels[:, BAND:IMAGE_W - BAND] = image_colour(j)
    if image_format == "raw":
        return pixels[:, :, ::-1].tobytes(), "bgr8"
    buffer = io.BytesIO()
    Image.fromarray(pixels).save(buffer, format="JPEG" if image_format == "jpeg" else "PNG", quality=95)
    return buffer.getvalue(), image_format


def _ns(t: float) -> int:
    return BASE_NS + int(round(t * 1e9))


def _stamp(t: float) -> dict[str, int]:
    return stamp(_ns(t))


def write_synthetic_turtlebot_bag(
    path: Path,
    n_seconds: float = 4.0,
    *,
    n_objects: int = 3,
    agent: Callable[[float], tuple[float, float, float]] = default_agent,
    objects: Callable[[int, float], tuple[float, float]] = default_objects,
    actions: Iterable[tuple[float, str | int]] | None = None,
    twists: Iterable[tuple[float, float, float]] | None = None,
    held: Iterable[tuple[float, int]] | None = None,
    image_format: str = "png",
    image_latency: float = 0.0,
    pose_latency: float = 0.0,
    omit: Iterable[str] = (),
    empty: Iterable[str] = (),
) -> Path:
    """A rosbag2-style MCAP (profile ros2, CDR) of a TurtleBot run with the ``RealTopics`` defaults.

    Camera images j at j / 30 s for j = 0 .. 30 n_seconds; robot poses at -0.02 + j / 20 s (past the end);
    object poses at 0.013 + j / 5 s. ``actions``: (t, name or int) on /mor/action (String, or Int32 for ints);
    ``twists``: (t, linear.x, angular.z) on /cmd_vel; ``held``: (t, index) on /mor/held. Header stamps are the
    true times; log times add ``image_latency`` / ``pose_latency``. Topics in ``omit`` are left out; topics in
    ``empty`` get a channel and no messages.
    """
    topics = RealTopics()
    omitted, empty = set(omit), set(empty)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as stream:
        writer = Ros2Writer(stream)
        schemas = {name: writer.register_msgdef(name, text) for name, text in MSGDEFS.items()}
        for topic in empty:  # a channel that the recorder saw but that got no message
            writer._writer.register_channel(topic, "cdr", schemas["std_msgs/msg/Int32"].id)

        def write(topic: str, kind: str, message: dict, t: float, latency: float = 0.0) -> None:
            if topic not in omitted and topic not in empty:
                writer.write_message(topic, schemas[kind], message, log_time=_ns(t + latency))

        events: list[tuple[float, str, str, dict, float]] = []
        for j in range(int(round(n_seconds * 30)) + 1):
            t = j / 30
            data, fmt = _image_bytes(j, image_format)
            header = {"stamp": _stamp(t), "frame_id": "camera"}
            if image_format == "raw":
                events.append((t, topics.image, "sensor_msgs/msg/Image", {
                    "header": header, "height": IMAGE_H, "width": IMAGE_W, "encoding": fmt, "is_bigendian": 0,
                    "step": IMAGE_W * 3, "data": data}, image_latency))
            else:
                events.append((t, topics.image, "sensor_msgs/msg/CompressedImage",
                               {"header": header, "format": fmt, "data": data}, image_latency))
        for j in range(int(round((n_seconds + 0.1) * 20)) + 1):
            t = -0.02 + j / 20
            x, y, yaw = agent(t)
            events.append((t, topics.agent_pose, "geometry_msgs/msg/PoseStamped", {
                "header": {"stamp": _stamp(t), "frame_id": "map"},
                "pose": {"position": {"x": x, "y": y, "z": 0.0}, "orientation": yaw_quaternion(yaw)}}, pose_latency))
        for j in range(int(n_seconds * 5) + 1):
            t = 0.013 + j / 5
            for i, topic in enumerate(topics.object_topics(n_objects)):
                x, y = objects(i, t)
                events.append((t, topic, "geometry_msgs/msg/PoseStamped", {
                    "header": {"stamp": _stamp(t), "frame_id": "map"},
                    "pose": {"position": {"x": x, "y": y, "z": 0.0}, "orientation": yaw_quaternion(0.3)}}, pose_latency))
        for t, action in actions or ():
            kind = "std_msgs/msg/Int32" if isinstance(action, int) else "std_msgs/msg/String"
            events.append((t, topics.action, kind, {"data": action}, 0.0))
        for t, linear, angular in twists or ():
            events.append((t, topics.cmd_vel, "geometry_msgs/msg/Twist", twist(linear, angular), 0.0))
        for t, index in held or ():
            events.append((t, topics.held, "std_msgs/msg/Int32", {"data": index}, 0.0))
        for t, topic, kind, message, latency in sorted(events, key=lambda e: e[0] + e[4]):
            write(topic, kind, message, t, latency)
        writer.finish()
    return path


def params(**overrides: object) -> ImportParams:
    values: dict[str, object] = {"n_objects": 3, "object_classes": [0, 7, 13],
                                 "target_positions": [(1.0, -1.0), (-1.5, 0.5), (2.0, 2.0)], "image_size": 32}
    values.update(overrides)
    return ImportParams(**values)


# The 2 Hz action stream of the default run, at 0.25 + 0.5 m s (m = 0 .. 7).
ACTION_STREAM = ["MOVE", "turn_left", "MOVE", "PICK", "TURN_RIGHT", "DROP", "FORWARD", "NONE"]
ACTION_IDS = [0, 1, 0, 3, 2, 4, 0, NO_ACTION]
HELD_STREAM = [(0.25 * j, 1 if 2.0 <= 0.25 * j < 3.0 else -1) for j in range(17)]  # 4 Hz


def expected_string_actions() -> list[int]:
    """Frame k's window [k/10, (k+1)/10) holds event m when k = 2 + 5m; the event then stays 'executing' for the
    next four frames (younger than action_hold_s = 1 s); the idle event at 3.75 s falls in frame 37's window: the
    robot stopped there, so frame 37 is idle too (the MOVE of 3.25 s no longer counts)."""
    actions = [NO_ACTION, NO_ACTION]
    for m in range(7):
        actions += [ACTION_IDS[m]] * 5
    return actions + [NO_ACTION] * 4


def expected_object(i: int, t: float) -> tuple[float, float]:
    """The latest 5 Hz tracker sample at or before t (the first sample before it)."""
    j = max(0, math.floor((t - 0.013) * 5 + 1e-9))
    return default_objects(i, 0.013 + j / 5)


def assert_poses_match(episode, agent=default_agent, tol: float = 1e-3, start: float = 0.0) -> None:
    times = start + np.arange(episode.n_frames) / episode.header.fps
    truth = np.array([agent(t) for t in times])
    np.testing.assert_allclose(episode.agent_poses[:, :2], truth[:, :2], atol=tol)
    yaw_error = np.angle(np.exp(1j * (episode.agent_poses[:, 2] - truth[:, 2])))
    assert np.max(np.abs(yaw_error)) < tol


# --- imports --------------------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def string_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    stream = [(0.25 + 0.5 * m, name) for m, name in enumerate(ACTION_STREAM)]
    return write_synthetic_turtlebot_bag(tmp_path_factory.mktemp("bags") / "run_string.mcap",
                                         actions=stream, held=HELD_STREAM)


def test_string_actions_poses_objects_images(string_bag: Path, tmp_path: Path) -> None:
    path = import_rosbag(string_bag, tmp_path, RealTopics(), params(episode_id="real-000"))
    assert path == tmp_path / "real-000.mcap" and not list(tmp_path.glob("*.partial"))
    episode = read_episode(path)
    header = episode.header
    assert (header.source, header.seed, header.fps, header.episode_id) == ("real", None, 10.0, "real-000")
    assert header.object_classes.tolist() == [0, 7, 13]
    np.testing.assert_allclose(header.target_positions, [(1.0, -1.0), (-1.5, 0.5), (2.0, 2.0)])
    assert header.wall_textures == ()
    assert header.params["bag"] == {"file": "run_string.mcap",
                                    "sha256": hashlib.sha256(string_bag.read_bytes()).hexdigest()}
    assert header.params["topics"] == RealTopics().model_dump()
    assert header.params["import"]["fps"] == 10.0
    assert header.params["sources"]["actions"] == "action" and header.params["sources"]["held"] == "topic"

    assert episode.n_frames == 41  # 4 s of images at 10 fps, both ends included
    assert episode.images.shape == (41, 32, 32, 3)
    for k in range(episode.n_frames):  # the latest image at or before k / 10 s is image 3k; its side bands cropped
        assert (episode.images[k] == image_colour(3 * k)).all(), k

    assert_poses_match(episode)
    times = np.arange(41) / 10
    held = np.array([1 if 2.0 <= t < 3.0 else -1 for t in times])
    assert episode.held.tolist() == held.tolist()
    for k, t in enumerate(times):
        for i in range(3):
            want = episode.agent_poses[k, :2] if held[k] == i else expected_object(i, t)
            np.testing.assert_allclose(episode.object_positions[k, i], want, atol=1e-6, err_msg=f"frame {k}")
    assert episode.actions.tolist() == expected_string_actions()


def test_action_fill_none_labels_only_new_actions(string_bag: Path, tmp_path: Path) -> None:
    episode = read_episode(import_rosbag(string_bag, tmp_path, RealTopics(), params(action_fill="none")),
                           with_images=False)
    want = [NO_ACTION] * 41
    for m in range(7):
        want[2 + 5 * m] = ACTION_IDS[m]
    assert episode.actions.tolist() == want


@pytest.mark.parametrize("image_format", ["jpeg", "raw"])
def test_jpeg_and_raw_images_int_actions_header_stamps(image_format: str, tmp_path: Path) -> None:
    stream = [(0.25 + 0.5 * m, a) for m, a in enumerate(ACTION_IDS)]
    bag = write_synthetic_turtlebot_bag(tmp_path / "run.mcap", actions=stream, image_format=image_format,
                                        image_latency=0.03, pose_latency=0.015)
    episode = read_episode(import_rosbag(bag, tmp_path / "out", RealTopics(), params(timestamps="header")))
    assert episode.n_frames == 41 and episode.images.shape == (41, 32, 32, 3)
    assert episode.header.params["sources"]["image_type"] == ("sensor_msgs/Image" if image_format == "raw"
                                                              else "sensor_msgs/CompressedImage")
    tolerance = 0 if image_format == "raw" else 4
    for k in range(41):
        centre = episode.images[k, 8:24, 8:24].astype(int)
        assert np.abs(centre - np.array(image_colour(3 * k))).max() <= tolerance, k
    assert_poses_match(episode)  # header stamps: the 15 ms and 30 ms transport delays do not show
    assert episode.actions.tolist() == expected_string_actions()
    assert (episode.held == -1).all()  # no held topic and no PICK near an object in view: nothing is held


def test_log_times_include_the_transport_delay(tmp_path: Path) -> None:
    bag = write_synthetic_turtlebot_bag(tmp_path / "run.mcap", actions=[(0.5, "MOVE")], pose_latency=0.05)
    episode = read_episode(import_rosbag(bag, tmp_path / "out", RealTopics(), params()), with_images=False)
    # The first pose is logged at 0.03 s, after the first image: the frames start there, at 10 fps. Frame t has
    # the pose logged at t, measured at t - 0.05 s.
    assert episode.n_frames == 40 and episode.header.params["quality"]["start_ns"] == BASE_NS + 30_000_000
    assert_poses_match(episode, lambda t: default_agent(t - 0.05), start=0.03)


def test_tracker_dropouts_are_interpolated_over(tmp_path: Path) -> None:
    def flaky(t: float) -> tuple[float, float, float]:  # the tracker loses the tag for 0.3 s: NaN poses
        return (math.nan, math.nan, math.nan) if 1.0 < t < 1.3 else default_agent(t)

    bag = write_synthetic_turtlebot_bag(tmp_path / "run.mcap", agent=flaky, actions=[(0.5, "MOVE")])
    episode = read_episode(import_rosbag(bag, tmp_path / "out", RealTopics(), params()), with_images=False)
    assert np.isfinite(episode.agent_poses).all()
    assert_poses_match(episode, tol=0.01)
    assert episode.header.params["quality"]["agent_pose_max_gap_s"] == pytest.approx(0.35, abs=1e-6)


def test_cmd_vel_only_with_held_topic(tmp_path: Path) -> None:
    def twist(t: float) -> tuple[float, float]:
        return [(0.2, 0.0), (0.0, 0.5), (0.0, 0.0), (0.0, -0.5)][min(int(t), 3)]

    twists = [(0.01 + 0.05 * j, *twist(0.01 + 0.05 * j)) for j in range(80)]
    held = [(0.02 + 0.1 * j, 0 if 2.4 <= 0.02 + 0.1 * j < 2.8 else -1) for j in range(40)]
    bag = write_synthetic_turtlebot_bag(tmp_path / "cmd_vel.mcap", twists=twists, held=held)
    episode = read_episode(import_rosbag(bag, tmp_path / "out", RealTopics(), params()), with_images=False)
    assert episode.header.params["sources"]["actions"] == "cmd_vel"
    move, left, right, pick, drop = (int(a) for a in Action)
    want = [move] * 10 + [left] * 10 + [NO_ACTION] * 10 + [right] * 10 + [NO_ACTION]  # frame 20: zero Twists
    want[24], want[28] = pick, drop  # the held topic's changes at 2.42 s and 2.82 s
    assert episode.actions.tolist() == want
    assert np.flatnonzero(episode.held == 0).tolist() == [25, 26, 27, 28]
    np.testing.assert_allclose(episode.object_positions[25:29, 0], episode.agent_poses[25:29, :2])


def test_a_robot_that_stops_and_starts_is_idle_when_it_stops_or_is_blocked(tmp_path: Path) -> None:
    """cmd_vel: MOVE on [0, 1) s, zero Twists on [1, 2), MOVE on [2, 4); the robot moves on [0, 1) and [2, 3) and
    is blocked on [3, 4). A frame is MOVE only where the robot was commanded to move and did."""
    def moving(t: float) -> float:  # seconds spent moving up to t
        return min(max(t, 0.0), 1.0) + min(max(t - 2.0, 0.0), 1.0)

    def agent(t: float) -> tuple[float, float, float]:
        return -1.0 + 0.2 * moving(t), 0.0, 0.0

    twists = [(0.01 + 0.05 * j, 0.0 if 1.0 <= 0.01 + 0.05 * j < 2.0 else 0.1, 0.0) for j in range(80)]
    bag = write_synthetic_turtlebot_bag(tmp_path / "stop_start.mcap", agent=agent, twists=twists)
    episode = read_episode(import_rosbag(bag, tmp_path / "out", RealTopics(), params()), with_images=False)
    move = int(Action.MOVE)
    assert episode.actions.tolist() == [move] * 10 + [NO_ACTION] * 10 + [move] * 10 + [NO_ACTION] * 11


def test_executed_actions_follow_the_tracked_pose() -> None:
    poses = np.array([[0, 0, 0], [0.1, 0, 0], [0.1, 0, 0], [0.1, 0, 0.17], [0.1, 0, 0.17], [0.1, 0, 0.17]], float)
    commands = np.array([Action.MOVE, Action.MOVE, Action.TURN_LEFT, Action.TURN_RIGHT, Action.PICK, Action.DROP])
    assert executed_actions(commands, poses).tolist() == [int(Action.MOVE), NO_ACTION, int(Action.TURN_LEFT),
                                                          NO_ACTION, int(Action.PICK), NO_ACTION]


def test_held_inferred_from_pick_and_drop(tmp_path: Path) -> None:
    def still(t: float) -> tuple[float, float, float]:
        return 0.0, 0.0, 0.0

    def layout(i: int, t: float) -> tuple[float, float]:
        return [(0.5, 0.0), (-2.0, 0.0), (0.0, 2.0)][i]

    bag = write_synthetic_turtlebot_bag(tmp_path / "pick.mcap", agent=still, objects=layout,
                                        actions=[(1.05, "PICK"), (2.05, "DROP")])
    episode = read_episode(import_rosbag(bag, tmp_path / "out", RealTopics(held=None), params()), with_images=False)
    assert episode.header.params["sources"]["held"] == "actions"
    assert np.flatnonzero(episode.held == 0).tolist() == list(range(11, 21))
    assert (episode.actions[10:20] == Action.PICK).all() and (episode.actions[20:31] == Action.DROP).all()
    assert (episode.actions[31:] == NO_ACTION).all()  # older than action_hold_s: the robot is idle
    np.testing.assert_allclose(episode.object_positions[15, 0], (0.0, 0.0))
    np.testing.assert_allclose(episode.object_positions[25, 0], (0.5, 0.0))


def test_import_is_deterministic_and_reads_rosbag2_directories(string_bag: Path, tmp_path: Path) -> None:
    folder = tmp_path / "rosbag2_2024_05_01-10_00_00"
    folder.mkdir()
    (folder / "run_string.mcap").write_bytes(string_bag.read_bytes())
    (folder / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    first = import_rosbag(string_bag, tmp_path / "a", RealTopics(), params())
    second = import_rosbag(folder, tmp_path / "b", RealTopics(), params())
    assert first.name == second.name == "real-run_string.mcap"
    assert first.read_bytes() == second.read_bytes()


# --- bad input: one line that names the bag, the topic and what to do --------------------------------------------


def _one_line_error(bag: Path, out: Path, topics: RealTopics | None = None, **overrides: object) -> str:
    with pytest.raises(MorError) as caught:
        import_rosbag(bag, out, topics or RealTopics(), params(**overrides))
    message = str(caught.value)
    assert isinstance(caught.value, RealBagError)
    assert "\n" not in message and str(bag) in message, message
    assert not list(out.glob("*.mcap*")) if out.exists() else True
    return message


@pytest.mark.parametrize(("omit", "empty", "needles"), [
    (["/tracker/robot_pose"], [], ["'/tracker/robot_pose'", "--agent-pose-topic"]),
    (["/tracker/object_2/pose"], [], ["'/tracker/object_2/pose'", "--object-pose-topic",
                                      "/tracker/object_0/pose"]),
    (["/camera/image_raw/compressed"], [], ["'/camera/image_raw/compressed'", "--image-topic", "no image topic"]),
    ([], ["/camera/image_raw/compressed"], ["'/camera/image_raw/compressed'", "no messages", "--image-topic"]),
    (["/mor/action"], [], ["'/mor/action'", "'/cmd_vel'", "--action-topic", "--cmd-vel-topic"]),
])
def test_missing_topics(omit: list[str], empty: list[str], needles: list[str], tmp_path: Path) -> None:
    bag = write_synthetic_turtlebot_bag(tmp_path / "bad.mcap", 1.0, actions=[(0.2, "MOVE")], omit=omit, empty=empty)
    message = _one_line_error(bag, tmp_path / "out")
    for needle in needles:
        assert needle in message, message


def test_wrong_topic_type_and_bad_action(tmp_path: Path) -> None:
    bag = write_synthetic_turtlebot_bag(tmp_path / "bad.mcap", 1.0, actions=[(0.2, "MOVE"), (0.6, "JUMP")])
    message = _one_line_error(bag, tmp_path / "out", RealTopics(image="/tracker/robot_pose"))
    assert "'/tracker/robot_pose'" in message and "--image-topic" in message and "PoseStamped" in message
    assert "/camera/image_raw/compressed" in message  # offered as the image topic to pass
    message = _one_line_error(bag, tmp_path / "out")
    assert "'/mor/action'" in message and "'JUMP'" in message and "MOVE" in message


@pytest.mark.parametrize("damage", ["garbage", "truncated", "missing"])
def test_unreadable_bag(damage: str, string_bag: Path, tmp_path: Path) -> None:
    bag = tmp_path / "broken.mcap"
    if damage == "garbage":
        bag.write_bytes(b"this is not an mcap file" * 100)
    elif damage == "truncated":
        data = string_bag.read_bytes()
        bag.write_bytes(data[: len(data) // 2])
    message = _one_line_error(bag, tmp_path / "out")
    assert ("no such file" in message) if damage == "missing" else ("mcap recover" in message)


def test_invalid_parameters_are_one_line_config_errors() -> None:
    cases = [
        (make_import_params, {"n_objects": 3, "object_classes": [1, 2], "target_positions": [(0, 0)] * 3},
         "object_classes"),
        (make_import_params, {"object_classes": [1, 2, 99], "target_positions": [(0, 0)] * 3}, "object_classes"),
        (make_import_params, {"object_classes": [1, 2, 3], "target_positions": [(0, 0)] * 2}, "target_positions"),
        (make_import_params, {"object_classes": [1, 2, 3], "target_positions": [(0, 0)] * 3, "fps": 0},
         "fps"),
        (make_real_topics, {"object_pose": "/tracker/object/pose"}, "object_pose"),
        (make_real_topics, {"camera": "/x"}, "unknown key"),
    ]
    for make, values, needle in cases:
        with pytest.raises(ConfigError) as caught:
            make("real", **values)
        assert "\n" not in str(caught.value) and needle in str(caught.value), str(caught.value)
        assert str(caught.value).startswith("real: ")


def test_cli_imports_a_bag_and_names_a_missing_topic(string_bag: Path, tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from pipelines.cli import app

    out = tmp_path / "real"
    args = ["import-real", str(string_bag), "--object-classes", "0,7,13", "--targets", "1,1;-1,2;0,-1.5",
            "--episode-id", "real-cli", "--out-dir", str(out)]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    episode = read_episode(out / "real-cli.mcap", with_images=False)
    assert episode.header.source == "real" and list(episode.header.object_classes) == [0, 7, 13]
    again = CliRunner().invoke(app, args)
    assert again.exit_code == 0 and f"replaced the existing episode {out / 'real-cli.mcap'}" in again.output
    bad = CliRunner().invoke(app, [*args, "--agent-pose-topic", "/nope"])
    assert bad.exit_code == 2
    lines = bad.output.strip().splitlines()
    assert len(lines) == 1 and "/nope" in lines[0] and "--agent-pose-topic" in lines[0]
