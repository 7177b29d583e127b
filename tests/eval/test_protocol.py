"""The evaluation protocol: same episodes for every method, resumable records, statistics, results rows."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from mor.errors import ConfigError
from mor.eval.methods import LoadedMethod, method_spec
from mor.eval.protocol import metric_summaries, read_records, run_protocol
from mor.eval.results import gather_rows
from mor.eval.stats import summarize
from mor.sim.config import SimConfig

SIM = SimConfig(n_objects=2, image_size=16)


def test_summary_is_mean_and_std_of_seed_means_with_an_interval_around_the_mean() -> None:
    values = {0: [1, 0, 1, 1], 1: [0, 0, 1, 0], 2: [1, 1, 1, 0]}
    summary = summarize(values, resamples=500)
    means = [0.75, 0.25, 0.75]
    assert summary["mean"] == pytest.approx(np.mean(means))
    assert summary["std"] == pytest.approx(np.std(means))
    low, high = summary["ci95"]
    assert low < summary["mean"] < high and 0.0 <= low and high <= 1.0
    assert summarize({0: [1.0, 1.0]}, resamples=500)["ci95"] == [1.0, 1.0]


def test_an_unknown_method_lists_the_known_ones() -> None:
    with pytest.raises(ConfigError, match=r"unknown method 'foo'; choose one of gt_pose, lnet, .*oracle, random"):
        method_spec("foo")


class _Stamped(LoadedMethod):
    """The oracle, as if played through the L-Net ``version`` (what ``played_by`` records)."""

    def played_by(self) -> dict:
        return {"lnet_version": self.version}


def _stamped(version: str) -> LoadedMethod:
    loaded = _Stamped(method_spec("oracle"))
    loaded.version = version
    return loaded


def test_every_method_plays_the_same_episodes_and_a_rerun_resumes(tmp_path) -> None:
    oracle = run_protocol(LoadedMethod(method_spec("oracle")), SIM, [0, 1], 2, tmp_path / "oracle.jsonl", progress=False)
    random = run_protocol(LoadedMethod(method_spec("random")), SIM, [0, 1], 2, tmp_path / "random.jsonl", progress=False)
    assert [(r["task"], r["reset_seed"]) for r in oracle] == [(r["task"], r["reset_seed"]) for r in random]
    assert len(oracle) == 3 * 2 * 2
    lines = (tmp_path / "oracle.jsonl").read_text().splitlines()
    (tmp_path / "oracle.jsonl").write_text("\n".join(lines[:-1]) + "\n" + lines[-1][:10])  # a kill mid-line
    again = run_protocol(LoadedMethod(method_spec("oracle")), SIM, [0, 1], 2, tmp_path / "oracle.jsonl", progress=False)
    assert [r["metrics"] for r in again] == [r["metrics"] for r in oracle]
    assert len(read_records(tmp_path / "oracle.jsonl")) == len(oracle)
    with pytest.raises(ConfigError, match=r"oracle.jsonl: its records were played by \{\} but this run plays "
                                          r"\{'lnet_version': 'b'\}; remove it and oracle.played_by.json"):
        run_protocol(_stamped("b"), SIM, [0, 1], 2, tmp_path / "oracle.jsonl", progress=False)  # e.g. a new L-Net
    summaries = metric_summaries(oracle, resamples=200)
    assert set(summaries) == {"pick_success", "drop_success", "rearrange_success", "fixed_strict", "energy_remaining"}
    assert summaries["pick_success"]["mean"] == 1.0


def _edit(line: str, change: dict) -> str:
    return json.dumps({**json.loads(line), **change})


@pytest.mark.parametrize(("replace", "problem"), [
    (lambda line: "42", "not an episode record (Input should be a valid dictionary"),
    (lambda line: "{}", "not an episode record (method: Field required)"),
    (lambda line: line[:20], "not JSON"),
    (lambda line: _edit(line, {"metrics": {"success": 0.0}}), "the record does not match its digest (edited"),
    (lambda line: _edit(line, {"steps": True}), "not an episode record (steps: Input should be a valid integer"),
    (lambda line: _edit(line, {"metrics": {}}), "not an episode record (metrics: a pick record needs success"),
    (lambda line: _edit(line, {"reset_seed": 7}), "not an episode record (reset_seed: 7 is not the reset seed of seed 0, episode 0"),
    (lambda line: json.dumps({k: v for k, v in json.loads(line).items() if k != "digest"}),
     "a record without its digest (written before records were sealed)"),
])
def test_a_line_that_is_not_a_sealed_record_is_one_line_naming_file_and_line(tmp_path: Path, replace, problem
                                                                              ) -> None:
    path = tmp_path / "oracle.jsonl"
    run_protocol(_stamped("a"), SIM, [0], 1, path, progress=False)
    lines = path.read_text().splitlines()
    path.write_text("\n".join([replace(lines[0]), *lines[1:]]) + "\n")
    with pytest.raises(ConfigError) as error:
        run_protocol(_stamped("a"), SIM, [0], 1, path, progress=False)
    message = str(error.value)
    assert "\n" not in message and message.startswith(f"{path}:1: {problem}"), message
    assert message.endswith("delete that line to play its episode again, or delete the file and "
                            "oracle.played_by.json to play every episode again")


def test_records_are_sealed_with_what_played_them(tmp_path: Path) -> None:
    path = tmp_path / "oracle.jsonl"
    run_protocol(_stamped("a"), SIM, [0], 1, path, progress=False)
    assert len(read_records(path)) == 3
    (tmp_path / "oracle.played_by.json").write_text(json.dumps({"lnet_version": "b"}))  # a sidecar edited by hand
    with pytest.raises(ConfigError, match=r"oracle.jsonl:1: the record does not match its digest"):
        read_records(path)
    (tmp_path / "oracle.played_by.json").write_text("{not json")
    with pytest.raises(ConfigError, match=r"oracle.played_by.json: not JSON; delete it and oracle.jsonl to play"):
        read_records(path)


def test_the_results_are_the_row_files_alone_in_order(tmp_path: Path) -> None:
    row = {"encoder": None, "arena": "square", "policy_arena": "square", "n_objects": 3, "profile": "tiny"}
    folder = tmp_path / "rows"
    folder.mkdir()
    for method in ("lnet", "gt_pose"):
        (folder / f"{method}.json").write_text(json.dumps({**row, "method": method}))
    (folder / "oracle.json").write_text(json.dumps({**row, "method": "oracle", "profile": "default"}))
    assert [r["method"] for r in gather_rows({".": folder}, "tiny")] == ["gt_pose", "lnet"]  # the profile's, sorted
    (folder / "lnet.json").unlink()
    assert [r["method"] for r in gather_rows({".": folder}, "tiny")] == ["gt_pose"]  # a row whose file is gone
