"""Writers of outputs: one at a time per output (``mor.locking``), and every file or folder published whole
(``mor.atomic``), even with two writers at once or a writer killed mid-write."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from typer.testing import CliRunner

from mor.atomic import atomic_folder, atomic_output
from mor.errors import MorError
from mor.locking import lock_path, writer_lock
from pipelines.cli import app

ROUNDS = 200
WRITER = """
import json, sys
from pathlib import Path
from mor.atomic import atomic_output
path, name, rounds, go = Path(sys.argv[1]), sys.argv[2], int(sys.argv[3]), Path(sys.argv[4])
while not go.exists():
    pass
for i in range(rounds):
    with atomic_output(path) as partial:
        partial.write_text(json.dumps({"writer": name, "round": i, "pad": "x" * 4096}))
"""


def test_two_writers_of_one_file_at_once_each_publish_whole_files(tmp_path: Path) -> None:
    path, go = tmp_path / "out" / "row.json", tmp_path / "go"
    writers = [subprocess.Popen([sys.executable, "-c", WRITER, str(path), name, str(ROUNDS), str(go)])
               for name in ("a", "b")]
    go.touch()
    while any(writer.poll() is None for writer in writers):
        if path.is_file():
            assert json.loads(path.read_text())["writer"] in {"a", "b"}  # a reader never sees a partial file
    assert [writer.wait() for writer in writers] == [0, 0]
    final = json.loads(path.read_text())
    assert final["writer"] in {"a", "b"} and final["round"] == ROUNDS - 1
    assert os.listdir(path.parent) == ["row.json"]


def _fill(folder: Path, files: dict[str, str]) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    for name, text in files.items():
        (folder / name).write_text(text)


def _contents(folder: Path) -> dict[str, str]:
    return {path.name: path.read_text() for path in folder.iterdir()}


OLD = {"policy.pth": "old", "meta.json": "old"}
NEW = {"policy.pth": "new", "meta.json": "new"}


def test_a_folder_is_replaced_whole_or_not_at_all(tmp_path: Path) -> None:
    card = tmp_path / "card"
    _fill(card, OLD)
    with pytest.raises(RuntimeError), atomic_folder(card) as folder:
        (folder / "policy.pth").write_text("new")
        raise RuntimeError("failed mid-write")
    assert _contents(card) == OLD
    with atomic_folder(card) as folder:
        _fill(folder, NEW)
    assert _contents(card) == NEW
    with atomic_folder(card, keep_existing=True) as folder:  # the files not written again stay
        (folder / "policy.pth").write_text("newer")
    assert _contents(card) == {**NEW, "policy.pth": "newer"}
    with atomic_folder(tmp_path / "fresh") as folder:
        _fill(folder, NEW)
    assert _contents(tmp_path / "fresh") == NEW
    assert sorted(os.listdir(tmp_path)) == ["card", "fresh"]


def test_a_swap_cut_between_its_two_renames_is_undone_by_the_next_writer(tmp_path: Path,
                                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    import mor.atomic

    card = tmp_path / "card"
    _fill(card, OLD)
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    monkeypatch.setattr(mor.atomic.os, "getpid", lambda: int(dead.stdout))  # the aside names a writer now gone
    card.rename(mor.atomic._aside_path(card))  # a kill after the first rename: card is missing, the old one aside
    monkeypatch.undo()
    with pytest.raises(RuntimeError), atomic_folder(card, keep_existing=True):
        raise RuntimeError("the next writer fails too")
    assert _contents(card) == OLD
    assert sorted(os.listdir(tmp_path)) == ["card"]


def test_a_policy_is_published_whole_with_whatever_published_lists(tmp_path: Path,
                                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    from pipelines import train_policy  # noqa: PLC0415

    run_dir, card = tmp_path / "run", tmp_path / "card"
    _fill(card, {**OLD, "README.md": "kept"})
    _fill(run_dir, {**NEW, "extra.json": "new"})
    monkeypatch.setattr(train_policy, "PUBLISHED", ("policy.pth", "extra.json", "meta.json", "log.csv"))
    copy = shutil.copyfile

    def fail_on_the_new_meta(src: Path, dst: Path, **kwargs: bool) -> Path:
        if Path(src) == run_dir / "meta.json":
            raise OSError("no space left on device")
        return copy(src, dst, **kwargs)

    monkeypatch.setattr(shutil, "copyfile", fail_on_the_new_meta)
    with pytest.raises(OSError, match="no space"):
        train_policy.publish(run_dir, card)
    assert _contents(card) == {**OLD, "README.md": "kept"}  # not the new policy beside the old meta.json
    monkeypatch.setattr(shutil, "copyfile", copy)
    train_policy.publish(run_dir, card)
    assert _contents(card) == {**NEW, "extra.json": "new", "README.md": "kept"}
    assert sorted(os.listdir(tmp_path)) == ["card", "run"]


KILLED = """
import os, signal, sys
from pathlib import Path
from mor.atomic import atomic_folder, atomic_output
with atomic_folder(Path(sys.argv[1])) as folder, atomic_output(Path(sys.argv[2])) as partial:
    (folder / "policy.pth").write_text("new")
    partial.write_text("new")
    os.kill(os.getpid(), signal.SIGKILL)
"""


def test_a_writer_killed_mid_write_leaves_the_old_outputs_whole_and_the_next_removes_its_scratch(tmp_path: Path
                                                                                                  ) -> None:
    card, row = tmp_path / "card", tmp_path / "row.json"
    _fill(card, OLD)
    row.write_text("old")
    killed = subprocess.run([sys.executable, "-c", KILLED, str(card), str(row)], check=False)
    assert killed.returncode == -signal.SIGKILL
    assert _contents(card) == OLD and row.read_text() == "old"
    assert len(os.listdir(tmp_path)) == 4  # the killed writer's partial folder and file
    with atomic_folder(card, keep_existing=True), atomic_output(row) as partial:
        partial.write_text("new")
    assert sorted(os.listdir(tmp_path)) == ["card", "row.json"]
    assert _contents(card) == OLD and row.read_text() == "new"


EVAL_RUN = "mor eval run --method oracle"
RECORDS = Path("datasets/eval/oracle.jsonl")
HOLDER = """
import sys, time
from pathlib import Path
from mor.locking import writer_lock
output = Path(sys.argv[1])
with writer_lock(output, sys.argv[2]):
    output.write_text("first writer\\n")
    print("holding", flush=True)
    time.sleep(120)
"""


@pytest.fixture
def holder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[subprocess.Popen]:
    """A process holding the lock of ``datasets/eval/oracle.jsonl`` as ``mor eval run --method oracle`` (in
    ``tmp_path``, the current directory), having written that file; killed at the end."""
    monkeypatch.chdir(tmp_path)
    RECORDS.parent.mkdir(parents=True)
    process = subprocess.Popen([sys.executable, "-c", HOLDER, str(RECORDS), EVAL_RUN], stdout=subprocess.PIPE,
                               text=True)
    try:
        assert process.stdout.readline() == "holding\n"
        yield process
    finally:
        process.kill()
        process.wait()
        process.stdout.close()


def _refusal(pid: int) -> str:
    return f"another `{EVAL_RUN}` is writing {RECORDS} (pid {pid}); wait for it or stop it"


def test_a_second_writer_is_refused_in_one_line_naming_the_first(holder: subprocess.Popen) -> None:
    with pytest.raises(MorError) as error, writer_lock(RECORDS, EVAL_RUN):
        pytest.fail("two writers held one lock")
    assert str(error.value) == _refusal(holder.pid)
    assert RECORDS.read_text() == "first writer\n"


def test_mor_eval_run_beside_a_running_one_is_one_error_line_and_exit_2(holder: subprocess.Popen, repo_root: Path
                                                                         ) -> None:
    shutil.copy(repo_root / "params.yaml", "params.yaml")
    result = CliRunner().invoke(app, ["eval", "run", "--method", "oracle", "--profile", "tiny"])
    assert result.exit_code == 2
    assert result.output.strip().splitlines() == [f"error: {_refusal(holder.pid)}"]
    assert RECORDS.read_text() == "first writer\n" and not Path("cards/results/rows/oracle.json").exists()


def test_a_lock_left_by_a_killed_writer_blocks_no_one(holder: subprocess.Popen) -> None:
    holder.kill()
    holder.wait()
    assert lock_path(RECORDS).is_file()  # the file stays; the kernel's lock ended with its holder
    with writer_lock(RECORDS, EVAL_RUN):
        assert json.loads(lock_path(RECORDS).read_text()) == {"pid": os.getpid(), "command": EVAL_RUN}
    assert not lock_path(RECORDS).exists()
