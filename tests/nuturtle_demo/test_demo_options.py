"""nuturtle_demo.run.DemoOptions: what a demo run accepts (checked before anything starts), and the
robot model it runs."""

from __future__ import annotations

import math
import socket

import numpy as np
import pytest

from nuturtle_demo.cli import main, parse_args
from nuturtle_demo.run import DemoOptions, DemoSystem
from nuturtle_description.robot_params import MODEL_ENV, model_params
from nuturtle_tools.recorder import BagWriter


def test_defaults_and_converted_values():
    options = DemoOptions(seed=np.int64(7), duration_s=30, max_realtime_factor=np.float64(5.0))
    assert options.association == "unknown" and options.world.is_file()
    assert type(options.seed) is int and options.seed == 7
    assert type(options.duration_s) is float and options.duration_s == 30.0
    assert options.realtime_factor == 5.0 and DemoOptions(realtime=True).realtime_factor == 1.0


@pytest.mark.parametrize(
    "fields, message",
    [
        (dict(association="maybe"), r"association must be one of \('known', 'unknown'\), got 'maybe'"),
        (dict(seed=-1), "seed must be >= 0, got -1"),
        (dict(seed=1.5), "seed must be an integer, got 1.5"),
        (dict(seed=True), "seed must be an integer, got True"),
        (dict(duration_s=0.0), "duration_s must be finite and > 0, got 0.0"),
        (dict(duration_s=math.inf), "duration_s must be a finite number, got inf"),
        (dict(duration_s="60"), "duration_s must be a finite number, got '60'"),
        (dict(max_realtime_factor=-2.0), "max_realtime_factor must be finite and > 0, got -2.0"),
        (dict(world="no/such/world.yaml"), "world file no/such/world.yaml does not exist"),
        (dict(robots=0), "robots must be >= 1, got 0"),
        (dict(robots=7), "robots must be at most 6, got 7"),
        (
            dict(robots=2, save_map=True, map_file="m.json"),
            "map_file, save_map take one robot, not robots = 2",
        ),
        (dict(robots=3, start=(0.0, 0.0, 0.0)), "start take one robot, not robots = 3"),
        (dict(robots=2, foxglove=("127.0.0.1", 8765)), "foxglove take one robot"),
    ],
)
def test_invalid_options_raise_with_their_reason(fields, message):
    with pytest.raises(ValueError, match=message):
        DemoOptions(**fields)


def test_the_model_is_the_option_else_turtlebot3_model_else_burger(monkeypatch):
    monkeypatch.delenv(MODEL_ENV, raising=False)
    assert DemoOptions().model == "burger"
    monkeypatch.setenv(MODEL_ENV, "waffle_pi")
    assert DemoOptions().model == "waffle_pi"
    assert DemoOptions(model="waffle").model == "waffle"


def test_an_unknown_model_is_one_error_line_and_exit_code_2(monkeypatch, capsys, tmp_path):
    with pytest.raises(SystemExit) as exit_info:
        main(["--model", "wafle"])
    assert exit_info.value.code == 2
    errors = [line for line in capsys.readouterr().err.splitlines() if "error:" in line]
    assert errors == [
        "python -m nuturtle_demo: error: argument --model: invalid choice: 'wafle' "
        "(choose from 'burger', 'waffle', 'waffle_pi')"
    ]
    # from the environment: refused before anything runs
    monkeypatch.setenv(MODEL_ENV, "burger3")
    assert main(["--out", str(tmp_path / "out")]) == 2
    assert capsys.readouterr().err.splitlines() == [
        "error: TURTLEBOT3_MODEL (the environment variable) must be one of "
        "('burger', 'waffle', 'waffle_pi'), got 'burger3'"
    ]
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("bad", ["world", "map", "foxglove port"])
def test_a_bad_input_is_one_error_line_exit_2_and_the_output_folder_untouched(tmp_path, capsys, bad):
    out = tmp_path / "out"
    out.mkdir()
    (out / "metrics.json").write_text("previous")
    broken = tmp_path / "broken.yaml"
    broken.write_text("nusim: {ros__parameters: {rate: [}\n")
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen(1)
        port = busy.getsockname()[1]
        args, message = {
            "world": (["--world", str(broken)], f"error: world file {broken} is not a ROS params file: "),
            "map": (["--map-file", str(broken)], f"error: {broken}: not a JSON document (truncated?): "),
            "foxglove port": (
                ["--foxglove", f"127.0.0.1:{port}"],
                f"error: cannot serve Foxglove on 127.0.0.1:{port}: Address already in use",
            ),
        }[bad]
        assert main(["--out", str(out), "--no-progress", *args]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith(message)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["broken.yaml", "out"]
    assert [p.name for p in out.iterdir()] == ["metrics.json"] and (
        out / "metrics.json"
    ).read_text() == "previous"


@pytest.mark.ros
def test_every_node_of_a_waffle_demo_runs_the_waffle(ros, tmp_path):
    """--model waffle: nusim, turtle_control, odometry, slam and the driver all take the Waffle's constants
    (built as a run builds them, not run)."""
    args = parse_args(["--model", "waffle", "--out", str(tmp_path)])
    options = DemoOptions(model=args.model, out_dir=args.out, progress=False)
    writer = BagWriter(tmp_path / "run")
    system = DemoSystem(options, ros.context, writer)
    try:
        waffle = model_params("waffle")
        for node in (system.nusim, system.turtle_control, system.odometry, system.slam, system.driver):
            assert node.get_parameter("model").value == "waffle", node.get_name()
            values = {name: node.get_parameter(name).value for name in vars(waffle)}
            assert values == pytest.approx(vars(waffle), rel=1e-12), node.get_name()
        assert system.nusim.simulation.config.robot == waffle
        assert system.slam.config.T_body_sensor == waffle.T_body_scan
    finally:
        writer.close()
        for node in system.nodes:
            node.destroy_node()
