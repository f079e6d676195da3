"""The robot-link settings both sides of the link read (common/robotlink.py)."""

from __future__ import annotations

from pathlib import Path

import pytest

from common.errors import ConfigError
from common.robotlink import RobotLinkSettings


def test_native_is_the_default_and_robots_are_namespaced_by_id() -> None:
    settings = RobotLinkSettings.from_env({})
    assert settings.link == "native" and settings.domain_id == 0
    assert settings.topics("r7").resolved_namespace("r7") == "/r7"


def test_a_link_file_sets_namespace_and_cmd_vel_type_per_robot(tmp_path: Path) -> None:
    path = tmp_path / "link.yaml"
    path.write_text(
        "robots:\n  r1: {namespace: '', cmd_vel_type: twist_stamped}\ndefault: {scan: base_scan}\n"
    )
    env = {"PNAV_ROBOT_LINK": "ros2", "PNAV_ROS_DOMAIN_ID": "3", "PNAV_ROS2_LINK_FILE": str(path)}
    settings = RobotLinkSettings.from_env(env)
    r1, r2 = settings.topics("r1"), settings.topics("r2")
    assert (settings.link, settings.domain_id) == ("ros2", 3)
    assert (r1.resolved_namespace("r1"), r1.cmd_vel_type, r1.scan) == (
        "/",
        "twist_stamped",
        "base_scan",
    )
    assert (r2.resolved_namespace("r2"), r2.cmd_vel_type, r2.scan) == ("/r2", "twist", "base_scan")


@pytest.mark.parametrize(
    "env",
    [
        {"PNAV_ROBOT_LINK": "dds"},
        {"PNAV_ROS_DOMAIN_ID": "233"},
        {"PNAV_ROS_DOMAIN_ID": "x"},
    ],
)
def test_bad_settings_are_refused(env: dict[str, str]) -> None:
    with pytest.raises(ConfigError):
        RobotLinkSettings.from_env(env)


@pytest.mark.parametrize(
    "body",
    [
        "robots: {r1: {cmd_vel_type: twist3}}",
        "robots: {r1: {scan: 'a b'}}",
        "robots: {r1: {nope: 1}}",
    ],
)
def test_bad_link_files_are_refused(tmp_path: Path, body: str) -> None:
    path = tmp_path / "link.yaml"
    path.write_text(body)
    with pytest.raises(ConfigError):
        RobotLinkSettings.from_env({"PNAV_ROS2_LINK_FILE": str(path)})


def test_the_clock_is_the_sims_unless_the_link_file_says_ros(tmp_path: Path) -> None:
    path = tmp_path / "link.yaml"
    env = {"PNAV_ROBOT_LINK": "ros2", "PNAV_ROS2_LINK_FILE": str(path)}
    path.write_text("robots: {r1: {namespace: ''}}\n")
    settings = RobotLinkSettings.from_env(env)
    assert (settings.clock, settings.use_sim_time, settings.bridge_clock) == ("sim", False, False)
    path.write_text("clock: ros\nuse_sim_time: true\n")
    settings = RobotLinkSettings.from_env(env)
    assert (settings.clock, settings.use_sim_time, settings.bridge_clock) == ("ros", True, True)
    # the native link has no ROS time to publish
    assert not RobotLinkSettings.from_env({**env, "PNAV_ROBOT_LINK": "native"}).bridge_clock


@pytest.mark.parametrize("body", ["clock: wall", "use_sim_time: 'yes'", "clocks: ros"])
def test_bad_clock_settings_are_refused(tmp_path: Path, body: str) -> None:
    path = tmp_path / "link.yaml"
    path.write_text(body)
    with pytest.raises(ConfigError):
        RobotLinkSettings.from_env({"PNAV_ROS2_LINK_FILE": str(path)})
