"""Bad input fails early with one line that names the field (env keywords, params.yaml, the CLI)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import pytest
import typer
import yaml
from typer.testing import CliRunner

from pipelines.cli import app
from mor.config import load_profile
from mor.errors import ConfigError
from mor.sim.tasks import PickEnv

ENV_IDS = ["MOR/Pick-v0", "MOR/Drop-v0", "MOR/Rearrange-v0"]


def assert_one_line(error: BaseException, *names: str) -> str:
    message = str(error)
    assert message and "\n" not in message, f"not a single line: {message!r}"
    for name in names:
        assert name in message, f"{name!r} not named in {message!r}"
    return message


# ---- env keywords ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("env_id", ENV_IDS)
@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"n_objects": 0}, "n_objects"),
        ({"n_objects": 6}, "n_objects"),
        ({"n_objects": -3}, "n_objects"),
        ({"arena": "circle"}, "arena"),
        ({"texture_pool": "random"}, "texture_pool"),
        ({"image_size": 8}, "image_size"),
        ({"image_size": 15}, "image_size"),
        ({"image_size": 513}, "image_size"),
        ({"image_size": 4096}, "image_size"),
        ({"arena_size": 0.0}, "arena_size"),
        ({"arena_size": -6.0}, "arena_size"),
        ({"arena_size": 1000.0}, "arena_size"),
        ({"landmarks": True}, "landmarks"),  # unknown keyword (a typo of landmark)
        ({"colour": "red"}, "colour"),
        ({"rewards": {"success": -1.0}}, "rewards.success"),
        ({"rewards": {"bonus": 1.0}}, "rewards.bonus"),
    ],
)
def test_bad_env_keywords_fail_at_construction(env_id, kwargs, field) -> None:
    kwargs = {"image_size": 16, **kwargs}
    with pytest.raises(ConfigError) as error:
        gym.make(env_id, **kwargs)
    message = assert_one_line(error.value, field)
    assert isinstance(error.value, ValueError)  # ConfigError is also a ValueError
    if field in ("landmarks", "colour"):
        assert "unknown" in message


@pytest.mark.parametrize(
    ("shape", "size", "n_objects"),
    [("square", 2.0, 5), ("square", 1.5, 5), ("square", 1.0, 5), ("polygon", 2.5, 5), ("polygon", 1.0, 1)],
)
def test_arena_too_small_fails_at_construction(monkeypatch: pytest.MonkeyPatch, shape, size, n_objects) -> None:
    # Every case is geometrically impossible (a 2 m square leaves a 1 m x 1 m region 0.5 m from the walls, where no
    # target can lie 1.5 m from its object's start), so a smaller retry budget only makes giving up faster: with the
    # real budget (200 layout tries) each case takes 25-50 s to fail.
    monkeypatch.setattr("mor.sim.episode.MAX_LAYOUT_TRIES", 10)
    with pytest.raises(ConfigError) as error:
        gym.make("MOR/Rearrange-v0", n_objects=n_objects, arena=shape, arena_size=size, image_size=16)
    message = assert_one_line(error.value, "arena_size", f"n_objects={n_objects}", shape)
    assert "too small" in message


def test_small_arena_fits_one_object() -> None:
    env = gym.make("MOR/Pick-v0", n_objects=1, arena_size=3.0, image_size=16)
    env.reset(seed=0)
    env.close()


def test_valid_extremes_construct() -> None:
    for kwargs in ({"n_objects": 1, "image_size": 16}, {"n_objects": 5, "image_size": 16, "arena": "polygon"}):
        PickEnv(**kwargs).close()


def test_unsupported_render_mode() -> None:
    with pytest.raises(ValueError, match="render_mode"):
        PickEnv(render_mode="human", image_size=16)


# ---- params.yaml -----------------------------------------------------------------------------------------------
def write_params(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "params.yaml"
    path.write_text(text)
    return path


GOOD = {
    "profile": "tiny",
    "profiles": {
        "tiny": {
            "sim": {"n_objects": 3, "image_size": 32},
            "oracle": {"episodes": 4, "seeds": [0, 1]},
            "demo": {"task": "pick", "policy": "oracle", "seed": 0, "fps": 8},
        }
    },
}


def test_the_repository_profiles_load(repo_root: Path) -> None:
    for name in ("tiny", "default", "paper"):
        profile = load_profile(name, repo_root / "params.yaml")
        assert profile.sim.n_objects == 3
    tiny = load_profile("tiny", repo_root / "params.yaml")
    assert tiny.sim.image_size == 32 and tiny.oracle.seeds == [0, 1] and tiny.demo.task == "pick"


def test_a_good_temp_file_loads(tmp_path: Path) -> None:
    profile = load_profile("tiny", write_params(tmp_path, yaml.safe_dump(GOOD)))
    assert profile.oracle.episodes == 4


def test_an_integer_stands_for_a_float(tmp_path: Path) -> None:
    profile = load_profile("tiny", write_params(tmp_path, _with("sim", "arena_size", 6)))
    assert profile.sim.arena_size == 6.0 and isinstance(profile.sim.arena_size, float)


def _with(section: str, key: str, value) -> str:
    document = yaml.safe_load(yaml.safe_dump(GOOD))
    document["profiles"]["tiny"].setdefault(section, {})[key] = value
    return yaml.safe_dump(document)


@pytest.mark.parametrize(
    ("section", "key", "value", "field"),
    [
        ("sim", "n_object", 3, "sim.n_object"),  # unknown key (typo)
        ("sim", "n_objects", 9, "sim.n_objects"),
        ("sim", "n_objects", 0, "sim.n_objects"),
        ("sim", "image_size", 4, "sim.image_size"),
        ("sim", "arena", "round", "sim.arena"),
        ("sim", "texture_pool", "all", "sim.texture_pool"),
        ("oracle", "episodes", 0, "oracle.episodes"),
        ("oracle", "seeds", [], "oracle.seeds"),
        ("oracle", "seeds", [1, 1], "oracle.seeds"),
        ("evaluate", "seeds", [-1, 1], "evaluate.seeds.0"),
        ("evaluate", "seeds", [0, 0], "evaluate.seeds: seeds must be distinct"),
        ("evaluate", "episodes", True, "evaluate.episodes"),  # strict: a bool is not an int
        ("collect", "episodes", 2.0, "collect.episodes"),
        ("sim", "landmark", 1, "sim.landmark"),
        ("sim", "n_objects", "3", "sim.n_objects"),
        ("lnet", "train", {"max_steps": True}, "lnet.train.max_steps"),
        ("policy", "pick", {"n_envs": False}, "policy.pick.n_envs"),
        ("policy", "training_seeds", [0, 0], "policy.training_seeds: seeds must be distinct"),
        ("policy", "training_seeds", [-1], "policy.training_seeds.0"),
        ("oracle", "episode", 4, "oracle.episode"),  # typo of episodes
        ("demo", "task", "fly", "demo.task"),
        ("demo", "fps", 0, "demo.fps"),
        ("demo", "policy", "ppo", "demo.policy"),
        ("sim", "rewards", {"step": -0.01}, "sim.rewards.step"),
        ("lnet", "search_max_looks", 0, "lnet.search_max_looks"),
        ("lnet", "arena_grid_spacing", 0.0, "lnet.arena_grid_spacing"),
    ],
)
def test_bad_params_name_the_file_and_field(tmp_path: Path, section, key, value, field) -> None:
    path = write_params(tmp_path, _with(section, key, value))
    with pytest.raises(ConfigError) as error:
        load_profile("tiny", path)
    assert_one_line(error.value, str(path), f"profiles.tiny: {field}")


def test_the_lnets_detection_without_its_visibility_head_is_refused_naming_both_settings(tmp_path: Path) -> None:
    document = yaml.safe_load(_with("policy", "observation", {"pick_visibility": True}))
    document["profiles"]["tiny"]["lnet"] = {"model": {"visibility": False}}
    path = write_params(tmp_path, yaml.safe_dump(document))
    with pytest.raises(ConfigError) as error:
        load_profile("tiny", path)
    message = assert_one_line(error.value, str(path), "profiles.tiny: policy.observation.pick_visibility",
                              "lnet.model.visibility")
    assert "got" not in message  # a check across fields names them; it does not print the whole profile
    document["profiles"]["tiny"]["lnet"]["model"]["visibility"] = True
    assert load_profile("tiny", write_params(tmp_path, yaml.safe_dump(document))).policy.observation.pick_visibility


def test_unknown_section(tmp_path: Path) -> None:
    path = write_params(tmp_path, _with("simulator", "n_objects", 3))  # a misspelt section
    with pytest.raises(ConfigError) as error:
        load_profile("tiny", path)
    message = assert_one_line(error.value, str(path), "profiles.tiny: simulator")
    assert "unknown key" in message


def test_missing_profile(tmp_path: Path) -> None:
    path = write_params(tmp_path, yaml.safe_dump(GOOD))
    with pytest.raises(ConfigError) as error:
        load_profile("huge", path)
    message = assert_one_line(error.value, str(path), "profiles.huge")
    assert "tiny" in message  # says what exists


@pytest.mark.parametrize(
    "text",
    [
        "profiles:\n  tiny: {sim: {n_objects: 3\n",  # unclosed flow mapping
        "profiles:\n  tiny:\n    sim: [1, 2\n",
        "profiles:\n\ttiny: {}\n",  # a tab for indentation
        "a: b: c\n",
    ],
)
def test_bad_yaml(tmp_path: Path, text) -> None:
    path = write_params(tmp_path, text)
    with pytest.raises(ConfigError) as error:
        load_profile("tiny", path)
    message = assert_one_line(error.value, str(path))
    assert "YAML" in message


@pytest.mark.parametrize("text", ["", "just a string\n", "profiles: [tiny]\n", "profile: tiny\n"])
def test_no_profiles_mapping(tmp_path: Path, text) -> None:
    path = write_params(tmp_path, text)
    with pytest.raises(ConfigError) as error:
        load_profile("tiny", path)
    assert_one_line(error.value, str(path), "profiles")


def test_missing_params_file(tmp_path: Path) -> None:
    path = tmp_path / "nowhere.yaml"
    with pytest.raises(ConfigError) as error:
        load_profile("tiny", path)
    assert_one_line(error.value, str(path))


def test_a_profile_that_is_not_a_mapping(tmp_path: Path) -> None:
    path = write_params(tmp_path, "profiles:\n  tiny: [1, 2]\n")
    with pytest.raises(ConfigError) as error:
        load_profile("tiny", path)
    assert_one_line(error.value, str(path), "profiles.tiny")


# ---- the CLI ---------------------------------------------------------------------------------------------------
@pytest.fixture
def runner() -> CliRunner:
    return CliRunner()


def _error_lines(result) -> list[str]:
    return [line for line in result.stderr.splitlines() if line.strip()]


@pytest.mark.parametrize(
    "args",
    [
        ["sim", "oracle", "--profile", "nope"],
        ["sim", "render", "--profile", "nope"],
        ["sim", "video", "--profile", "nope"],
        ["sim", "demo", "--profile", "nope"],
    ],
)
def test_cli_bad_profile(runner: CliRunner, repo_root: Path, monkeypatch: pytest.MonkeyPatch, tmp_path: Path,
                         args) -> None:
    monkeypatch.chdir(repo_root)
    result = runner.invoke(app, [*args, *(["--out", str(tmp_path / "m.json")] if args[1] == "oracle" else [])])
    assert result.exit_code == 2, result.output
    lines = _error_lines(result)
    assert len(lines) == 1, lines
    assert lines[0].startswith("error: ")
    assert "profiles.nope" in lines[0] and "params.yaml" in lines[0]
    assert result.stdout == ""
    assert list(tmp_path.iterdir()) == []  # nothing written


def test_cli_bad_params_file(runner: CliRunner, tmp_path: Path) -> None:
    params = write_params(tmp_path, _with("sim", "n_objects", 9))
    result = runner.invoke(app, ["sim", "render", "--profile", "tiny", "--params", str(params),
                                 "--out-dir", str(tmp_path / "out")])
    assert result.exit_code == 2
    lines = _error_lines(result)
    assert len(lines) == 1 and lines[0].startswith("error: ")
    assert str(params) in lines[0] and "sim.n_objects" in lines[0]


def test_cli_missing_params_file(runner: CliRunner, tmp_path: Path) -> None:
    result = runner.invoke(app, ["sim", "oracle", "--profile", "tiny", "--params", str(tmp_path / "none.yaml"),
                                 "--out", str(tmp_path / "m.json")])
    assert result.exit_code == 2
    lines = _error_lines(result)
    assert len(lines) == 1 and lines[0].startswith("error: ") and "none.yaml" in lines[0]


@pytest.mark.parametrize("command", ["oracle", "render", "video"])
def test_cli_unknown_task(runner: CliRunner, repo_root: Path, monkeypatch: pytest.MonkeyPatch, tmp_path: Path,
                          command) -> None:
    monkeypatch.chdir(repo_root)
    out = {"oracle": ["--out", str(tmp_path / "m.json")], "render": ["--out-dir", str(tmp_path)],
           "video": ["--out", str(tmp_path / "v.gif")]}[command]
    result = runner.invoke(app, ["sim", command, "--profile", "tiny", "--task", "fly", *out])
    assert result.exit_code == 2
    lines = _error_lines(result)
    assert len(lines) == 1 and lines[0].startswith("error: ") and "--task" in lines[0] and "fly" in lines[0]


@pytest.mark.parametrize("horizon", [0, -3])
def test_a_horizon_below_one_step_is_refused(horizon: int) -> None:
    with pytest.raises(ConfigError, match="horizon: must be at least 1 step") as error:
        gym.make("MOR/Pick-v0", horizon=horizon, image_size=16)
    assert "\n" not in str(error.value)


# ---- every command, bad values ---------------------------------------------------------------------------------
def _commands() -> dict[str, Any]:
    """Every leaf command of ``mor``: ``"sim oracle"`` -> its click command."""
    found: dict[str, Any] = {}

    def walk(command: Any, path: tuple[str, ...]) -> None:
        for name, sub in (getattr(command, "commands", None) or {}).items():
            walk(sub, (*path, name))
        if not getattr(command, "commands", None):
            found[" ".join(path)] = command

    walk(typer.main.get_command(app), ())
    return found


COMMANDS = _commands()
#: What each command needs besides the option under test, so that the option's own check is what fails.
REQUIRED = {"import-real": ["x.mcap", "--object-classes", "0", "--targets", "1,2"]}
#: Numeric options without a typer bound (a model validates them in the command): a bad value for each.
UNBOUNDED_BAD = {("import-real", "--fps"): "0", ("import-real", "--image-size"): "8", ("bench sim", "--image-size"): "3"}


def _numeric_options() -> list[tuple[str, str, Any]]:
    """(command, option, its lower bound or None) for every int/float option of every command."""
    return [(name, param.opts[0], param.min) for name, command in COMMANDS.items() for param in command.params
            if param.opts[0].startswith("--") and param.type_descriptor.annotation in (int, float)]


def _bad_cases() -> list[tuple[list[str], str]]:
    """(arguments, what the error line must name): a hand-picked list, then for every numeric option a value
    that is not a number and one below its bound, and an unknown option for every command."""
    cases = [
        (["sim", "oracle", "--seeds", "a,b"], "--seeds"), (["sim", "oracle", "--seeds", "1,-1"], "--seeds"),
        (["sim", "oracle", "--seeds", "0,0"], "--seeds"),
        (["sim", "render", "--seed", "-1"], "--seed"), (["sim", "video", "--policy", "foo"], "--policy"),
        (["sim", "video", "--out", "v.avi"], "v.avi"), (["collect", "--episodes", "-5"], "--episodes"),
        (["collect", "--episodes", "0"], "--episodes"), (["collect", "--workers", "0"], "--workers"),
        (["bench", "sim", "--steps", "-1"], "--steps"), (["collect", "--backend", "threads"], "--backend"),
    ]
    for name, option, low in _numeric_options():
        cases.append(([*name.split(), option, "x", *REQUIRED.get(name, [])], option))
        bad = str(low - 1) if low is not None else UNBOUNDED_BAD.get((name, option))
        if bad is not None:
            cases.append(([*name.split(), option, bad, *REQUIRED.get(name, [])], option.lstrip("-").replace("-", "_")
                          if low is None else option))
    cases += [([*name.split(), "--no-such-option"], "--no-such-option") for name in COMMANDS]
    return cases


def test_every_numeric_option_has_a_bound_or_a_bad_case() -> None:
    missing = [(name, option) for name, option, low in _numeric_options()
               if low is None and (name, option) not in UNBOUNDED_BAD]
    assert not missing, f"give these options a typer min= or a bad value in UNBOUNDED_BAD: {missing}"


@pytest.mark.parametrize(("args", "named"), _bad_cases(), ids=lambda v: " ".join(v) if isinstance(v, list) else v)
def test_every_command_refuses_bad_values_in_one_line(runner: CliRunner, repo_root: Path,
                                                      monkeypatch: pytest.MonkeyPatch, args, named: str) -> None:
    monkeypatch.chdir(repo_root)
    result = runner.invoke(app, args)
    assert result.exit_code == 2, result.output
    assert isinstance(result.exception, SystemExit) and "Traceback" not in result.output
    lines = _error_lines(result)
    assert len(lines) == 1 and lines[0].startswith("error: "), lines
    assert named in lines[0], lines[0]
    assert result.stdout == ""


@pytest.mark.parametrize("active", [None, ["tiny"], "huge"])
def test_the_active_profile_must_be_named_in_params_yaml(runner: CliRunner, tmp_path: Path, active) -> None:
    document = {key: value for key, value in GOOD.items() if key != "profile"}
    params = write_params(tmp_path, yaml.safe_dump(document if active is None else {**document, "profile": active}))
    result = runner.invoke(app, ["profile", "--params", str(params)])
    assert result.exit_code == 2
    lines = _error_lines(result)
    assert len(lines) == 1 and str(params) in lines[0] and "profile" in lines[0], lines


@pytest.mark.parametrize(("args", "words"), [
    (["policy", "train", "--variant", "gt_pose", "--seed", "-1"], "--seed"),
    (["policy", "train", "--variant", "gt_pose", "--seed", "0,0"], "--seed"),
    (["policy", "train", "--variant", "gt_pose", "--seed", "1", "--backend", "slurm"], "--backend"),
    (["eval", "run", "--method", "gt_pose", "--seeds", "0,9"], "--seeds: [0] are the protocol's own"),
    (["eval", "run", "--method", "gt_pose", "--seeds", "5,5"], "--seeds"),
])
def test_bad_training_and_evaluation_seeds_are_one_line(runner: CliRunner, repo_root: Path,
                                                        monkeypatch: pytest.MonkeyPatch, args, words) -> None:
    monkeypatch.chdir(repo_root)
    result = runner.invoke(app, [*args, "--profile", "tiny"])
    assert result.exit_code == 2, result.output
    lines = _error_lines(result)
    assert len(lines) == 1 and lines[0].startswith("error: ") and words in lines[0], lines
