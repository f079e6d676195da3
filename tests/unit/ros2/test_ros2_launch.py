"""`pnav up --robot-link ros2`: the processes it adds, and the link files it refuses."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from common.config import ZenohSettings
from common.errors import UsageError
from pnav.cli.options import robot_link_env
from pnav.cli.parser import build_parser
from pnav.run.launcher import service_specs
from pnav.run.local_stack import LocalStack
from pnav.run.stack_options import StackOptions


def _local() -> LocalStack:
    router: Any = None  # not used to build the specs
    return LocalStack(
        "postgresql://x/y", ZenohSettings(connect=("tcp/127.0.0.1:7447",)), router, None
    )


def test_the_ros2_link_adds_the_rviz_process_acting_for_people() -> None:
    world = Path("worlds/open_room.yaml")
    native = [s.name for s in service_specs(_local(), StackOptions(), world)]
    assert "rviz" not in native
    options = StackOptions(extra_env={"PNAV_ROBOT_LINK": "ros2"})
    specs = {s.name: s for s in service_specs(_local(), options, world)}
    rviz = specs["rviz"]
    assert rviz.argv[1:] == ["-m", "pnav.ros2"]
    assert rviz.env["PNAV_ROBOT_LINK"] == "ros2"


def test_pnav_up_refuses_a_ros_clock_on_wall_time_since_it_runs_the_sim(tmp_path: Path) -> None:
    link = tmp_path / "link.yaml"
    link.write_text("clock: ros\n")
    args = build_parser().parse_args(["up", "--robot-link", "ros2", "--ros-link-file", str(link)])
    with pytest.raises(UsageError, match="use_sim_time: true"):
        robot_link_env(args)
    link.write_text("clock: ros\nuse_sim_time: true\n")
    assert robot_link_env(args)["PNAV_ROS2_LINK_FILE"] == str(link.resolve())


def test_no_sim_takes_real_robots_on_ros2_with_their_clock_and_refuses_the_rest(
    tmp_path: Path,
) -> None:
    link = tmp_path / "tb3.yaml"
    link.write_text("clock: ros\nuse_sim_time: false\n")  # a real robot: wall time is right

    def env(*extra: str) -> dict[str, str]:
        return robot_link_env(build_parser().parse_args(["up", "--no-sim", *extra]))

    assert env("--robot-link", "ros2", "--ros-link-file", str(link))["PNAV_ROBOT_LINK"] == "ros2"
    with pytest.raises(UsageError, match="needs --robot-link ros2"):
        env()
    with pytest.raises(UsageError, match="needs a --ros-link-file with clock: ros"):
        env("--robot-link", "ros2")
    link.write_text("clock: sim\n")
    with pytest.raises(UsageError, match="say clock: ros"):
        env("--robot-link", "ros2", "--ros-link-file", str(link))
