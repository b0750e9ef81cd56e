"""nuturtle_eval.run_folder: a run writes into a staging folder; the previous result is replaced only when
the run completes, an early stop leaves a marked OUT.incomplete, a foreign folder is never replaced."""

import subprocess
import sys
from pathlib import Path

import pytest

from nuturtle_eval.datasets.__main__ import main
from nuturtle_eval.run_folder import (
    INCOMPLETE,
    RunFolder,
    check_no_other_run,
    check_replaceable,
    incomplete_folder,
    outputs_line,
    say_previous_result,
    unfinished_runs,
)

OUTPUTS = ("metrics.json", "run")
# A run in another process: its RunFolder for argv[1], the staging folder's path printed, then on a line
# "complete" on stdin it writes metrics.json and completes (else it waits to be killed)
OTHER_RUN = """
import sys
from pathlib import Path
from nuturtle_eval.run_folder import RunFolder
folder = RunFolder(Path(sys.argv[1]), ["metrics.json", "run"])
print(folder.path, flush=True)
if sys.stdin.readline().strip() == "complete":
    (folder.path / "metrics.json").write_text("other")
    folder.complete()
"""


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


def _other_run(out):
    """A run into ``out`` in another process, and the staging folder it writes (once it holds it)."""
    run = subprocess.Popen(
        [sys.executable, "-P", "-c", OTHER_RUN, str(out)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    return run, run.stdout.readline().strip()


def test_the_staging_folder_of_a_killed_run_is_found_and_a_running_one_is_not(tmp_path):
    out = tmp_path / "latest"
    killed, killed_path = _other_run(out)
    assert unfinished_runs(out) == []
    killed.kill()  # SIGKILL: the system lets go of its lock
    killed.wait(10)
    (tmp_path / "other.partial-1").mkdir()
    running = RunFolder(out, OUTPUTS)
    assert unfinished_runs(out) == [Path(killed_path)] and running.path.is_dir()
    running.discard()


def test_a_run_into_an_output_folder_another_run_is_writing_is_refused_until_it_completes(tmp_path):
    out = tmp_path / "latest"
    _previous_result(out)
    other, staging = _other_run(out)
    try:
        with pytest.raises(ValueError, match=rf"another run \(process {other.pid}\) is writing {out}"):
            RunFolder(out, OUTPUTS)
        with pytest.raises(ValueError, match="wait for it to finish or choose another --out"):
            check_no_other_run(out)
        # nothing of the refused run is left, the other's staging folder and the previous result untouched
        assert sorted(p.name for p in tmp_path.iterdir()) == ["latest", f"latest.partial-{other.pid}"]
        assert str(tmp_path / f"latest.partial-{other.pid}") == staging
        assert (out / "metrics.json").read_text() == "old" and unfinished_runs(out) == []
    finally:
        other.communicate("complete\n", timeout=10)
    assert other.returncode == 0 and (out / "metrics.json").read_text() == "other"
    folder = RunFolder(out, OUTPUTS)
    assert folder.complete() == out


def test_the_dataset_command_refuses_an_output_folder_another_run_is_writing_before_reading(tmp_path, capsys):
    out = tmp_path / "results"
    other, _ = _other_run(out)
    try:
        code = main(["mrclam", "--data", str(tmp_path / "nowhere"), "--robot", "1", "--out", str(out)])
    finally:
        other.communicate("complete\n", timeout=10)
    (line,) = capsys.readouterr().err.splitlines()
    assert code == 2 and line.startswith(f"error: another run (process {other.pid}) is writing {out}: ")


def test_the_previous_result_a_run_replaces_is_named_as_it_starts(tmp_path, capsys):
    out = tmp_path / "latest"
    say_previous_result(out)
    out.mkdir()
    say_previous_result(out)
    assert capsys.readouterr().err == ""
    _previous_result(out)
    say_previous_result(out)
    (note,) = capsys.readouterr().err.splitlines()
    assert note.startswith(f"note: {out}/ holds a previous result (written ")
    assert note.endswith("this run replaces it when it completes (choose another --out to keep it)")


def test_the_outputs_line_names_every_entry_of_the_folder_and_marks_folders(tmp_path):
    for name in ("metrics.json", "map.yaml", "grid.png"):
        (tmp_path / name).write_text("x")
    (tmp_path / "run").mkdir()
    assert outputs_line(tmp_path) == f"outputs in {tmp_path}/: grid.png map.yaml metrics.json run/"
