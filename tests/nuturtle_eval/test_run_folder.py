"""nuturtle_eval.run_folder: a run writes into a staging folder; the previous result is replaced only when
the run completes, an early stop leaves a marked OUT.incomplete, a foreign folder is never replaced."""

import os
import subprocess
import sys

import pytest

from nuturtle_eval.run_folder import (
    INCOMPLETE,
    RunFolder,
    check_replaceable,
    incomplete_folder,
    outputs_line,
    unfinished_runs,
)

OUTPUTS = ("metrics.json", "run")


def _previous_result(out):
    (out / "run").mkdir(parents=True)
    (out / "run" / "run.mcap").write_bytes(b"old bag")
    (out / "metrics.json").write_text("old")


def _write(folder, text):
    (folder / "run").mkdir()
    (folder / "metrics.json").write_text(text)


def test_a_complete_run_replaces_the_previous_result_and_only_then(tmp_path):
    out = tmp_path / "latest"
    _previous_result(out)
    folder = RunFolder(out, OUTPUTS)
    assert folder.path.parent == tmp_path and (folder.path / INCOMPLETE).is_file()
    _write(folder.path, "new")
    assert (out / "metrics.json").read_text() == "old"
    assert folder.complete() == out
    assert sorted(p.name for p in out.iterdir()) == ["metrics.json", "run"]
    assert (out / "metrics.json").read_text() == "new"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["latest"]


def test_a_run_stopped_early_is_marked_and_leaves_the_previous_result(tmp_path):
    out = tmp_path / "latest"
    _previous_result(out)
    (incomplete_folder(out)).mkdir()
    (incomplete_folder(out) / INCOMPLETE).write_text("an older stopped run")
    folder = RunFolder(out, OUTPUTS)
    _write(folder.path, "partial")
    where = folder.keep_incomplete("interrupted by SIGTERM after 2.0 of 60.0 s")
    assert where == tmp_path / "latest.incomplete"
    assert "SIGTERM" in (where / INCOMPLETE).read_text()
    assert (where / "metrics.json").read_text() == "partial"
    assert (out / "metrics.json").read_text() == "old" and (
        out / "run" / "run.mcap"
    ).read_bytes() == b"old bag"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["latest", "latest.incomplete"]


def test_a_discarded_run_leaves_nothing(tmp_path):
    folder = RunFolder(tmp_path / "new" / "latest", OUTPUTS)
    folder.discard()
    assert list((tmp_path / "new").iterdir()) == []


def test_the_kept_file_inside_the_output_folder_moves_into_the_new_result(tmp_path):
    out = tmp_path / "loc_run"
    out.mkdir()
    map_file = out / "map.json"
    map_file.write_text("map")
    folder = RunFolder(out, OUTPUTS, keep=[map_file])
    _write(folder.path, "new")
    folder.complete()
    assert map_file.read_text() == "map" and (out / "metrics.json").read_text() == "new"


def test_a_folder_with_other_files_is_refused_before_anything_is_written(tmp_path):
    (tmp_path / "notes.txt").write_text("mine")
    with pytest.raises(ValueError, match=r"holds files a run does not write \(notes.txt\)"):
        RunFolder(tmp_path, OUTPUTS)
    assert [p.name for p in tmp_path.iterdir()] == ["notes.txt"]
    (tmp_path / "file").write_text("")
    with pytest.raises(ValueError, match="is a file"):
        check_replaceable(tmp_path / "file", OUTPUTS)


def test_the_staging_folder_of_a_killed_run_is_found_and_a_running_one_is_not(tmp_path):
    gone = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True
    )
    killed = tmp_path / f"latest.partial-{int(gone.stdout)}"
    killed.mkdir()
    (tmp_path / f"latest.partial-{os.getpid()}").mkdir()
    (tmp_path / "other.partial-1").mkdir()
    assert unfinished_runs(tmp_path / "latest") == [killed]


def test_the_outputs_line_names_every_entry_of_the_folder_and_marks_folders(tmp_path):
    for name in ("metrics.json", "map.yaml", "grid.png"):
        (tmp_path / name).write_text("x")
    (tmp_path / "run").mkdir()
    assert outputs_line(tmp_path) == f"outputs in {tmp_path}/: grid.png map.yaml metrics.json run/"
