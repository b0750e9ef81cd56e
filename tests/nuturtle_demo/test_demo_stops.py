"""The demo as a user's process stopped from outside (real child processes, real signals): SIGTERM ends it
like Ctrl-C (a closed, readable bag and the metrics of what ran, marked incomplete), kill -9 leaves a bag
the replay's reader recovers, a file size limit (a full disk) stops it with one error line; the previous
complete result is never touched. The staging folder logic itself is tested in
tests/nuturtle_eval/test_run_folder.py, the SIGHUP/SIGINT handling in
tests/nuturtle_ros_common/test_stop_signals.py."""

from __future__ import annotations

import json
import os
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from bag_reading import read_bag
from nuturtle_tools.bag_source import BagSource

# a 60 s run, stopped from outside long before its end
LONG_S = "60"
PREVIOUS = '{"previous": true}\n'
# the bag's size once it has a flushed chunk of messages beyond the header and the first schemas (bytes)
STARTED_BYTES = 20_000


def _previous_result(tmp_path: Path) -> Path:
    out = tmp_path / "out"
    out.mkdir()
    (out / "metrics.json").write_text(PREVIOUS)
    return out


def _start_demo(tmp_path: Path, out: Path, *options: str, **kwargs) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "nuturtle_demo", "--duration", LONG_S, "--out", str(out), "--no-progress",
         *options],
        cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kwargs,
    )  # fmt: skip


def _wait_for_bag(process: subprocess.Popen, out: Path, timeout_s: float = 60.0) -> Path:
    """The staging folder's bag file once it holds flushed messages (the simulation is running)."""
    mcap = out.with_name(f"{out.name}.partial-{process.pid}") / "run" / "run.mcap"
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        assert process.poll() is None, process.communicate()
        if mcap.is_file() and mcap.stat().st_size > STARTED_BYTES:
            return mcap
        time.sleep(0.1)
    process.kill()
    pytest.fail(f"no bag grew at {mcap} within {timeout_s} s: {process.communicate()}")


def _stderr_lines(stderr: str) -> list[str]:
    """stderr without the nodes' log lines (``[INFO] [...]``)."""
    return [line for line in stderr.splitlines() if line and not line.startswith("[")]


@pytest.mark.ros
def test_sigterm_ends_the_demo_like_ctrl_c_and_keeps_the_previous_result(tmp_path):
    out = _previous_result(tmp_path)
    process = _start_demo(tmp_path, out, "--check")
    _wait_for_bag(process, out)
    process.send_signal(signal.SIGTERM)
    stdout, stderr = process.communicate(timeout=60)
    # without --check the exit status is 0, as after Ctrl-C; --check fails an incomplete run
    assert process.returncode == 1, stderr
    assert _stderr_lines(stderr)[-1].startswith("check failed: the run is incomplete (SIGTERM)")
    incomplete = tmp_path / "out.incomplete"
    assert (out / "metrics.json").read_text() == PREVIOUS
    assert "interrupted by SIGTERM" in (incomplete / "INCOMPLETE").read_text()
    metrics = json.loads((incomplete / "metrics.json").read_text())
    assert metrics["complete"] is False and metrics["stopped_by"] == "SIGTERM"
    assert 0.0 < metrics["sim_seconds"] < float(LONG_S)
    assert "INCOMPLETE: interrupted by SIGTERM" in stdout and f"outputs in {incomplete}/" in stdout
    # closed like after Ctrl-C: metadata.yaml and an MCAP summary and footer
    bag = read_bag(incomplete / "run")
    assert bag.metadata["message_count"] == len(bag.records) > 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "out.incomplete"]


@pytest.mark.ros
def test_kill_9_leaves_a_bag_the_replay_s_reader_recovers(tmp_path):
    out = _previous_result(tmp_path)
    process = _start_demo(tmp_path, out)
    mcap = _wait_for_bag(process, out)
    time.sleep(1.5)  # at least one more flush
    process.kill()
    process.communicate(timeout=30)
    assert process.returncode == -signal.SIGKILL
    assert (out / "metrics.json").read_text() == PREVIOUS
    bag_dir = mcap.parent
    assert not (bag_dir / "metadata.yaml").exists()
    assert "has not finished" in (bag_dir.parent / "INCOMPLETE").read_text()
    with BagSource(bag_dir) as source:
        assert source.recovery is not None and "unfinished recording" in source.recovery.note()
        counts = {name: topic.message_count for name, topic in source.topics.items()}
        messages = list(source.messages(["/scan", "/joint_states"]))
    assert counts["/joint_states"] > 20 and counts["/scan"] > 5
    assert (
        len(messages)
        == counts["/scan"] + counts["/joint_states"]
        == source.recovery.messages
        - sum(count for name, count in counts.items() if name not in ("/scan", "/joint_states"))
    )
    # a chunk cut off in the middle is dropped, the ones before it read
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(mcap.read_bytes()[: mcap.stat().st_size * 2 // 3])
    with BagSource(cut) as source:
        assert 0 < source.recovery.messages < sum(counts.values()) and source.recovery.dropped_bytes > 0


def _file_size_limit(limit_bytes: int):
    def limit() -> None:
        # EFBIG from write() instead of the default SIGXFSZ, which would kill the process
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit_bytes, limit_bytes))

    return limit


@pytest.mark.ros
def test_a_full_disk_stops_the_demo_with_one_error_line(tmp_path):
    out = _previous_result(tmp_path)
    process = _start_demo(tmp_path, out, preexec_fn=_file_size_limit(300_000))
    _, stderr = process.communicate(timeout=120)
    assert process.returncode == 1, stderr
    # the note the run gave as it started, then the one error line
    replaced, *errors = _stderr_lines(stderr)
    assert replaced.startswith(f"note: {out}/ holds a previous result (written ")
    assert errors == [
        "error: cannot write the bag run/: File too large (EFBIG); the outputs written so far are in "
        f"{tmp_path / 'out.incomplete'}/"
    ]
    assert "Traceback" not in stderr
    assert (out / "metrics.json").read_text() == PREVIOUS
    assert (
        "the run failed: cannot write the bag run/"
        in (tmp_path / "out.incomplete" / "INCOMPLETE").read_text()
    )
    assert os.path.getsize(tmp_path / "out.incomplete" / "run" / "run.mcap") <= 300_000
