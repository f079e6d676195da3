"""The sim's command timeout: like robot firmware, a robot whose commands stop coming stops
its wheels after cmd_timeout_s of sim time; commands that keep coming keep it going."""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path

import pytest

from common.errors import ConfigError
from services.sim.__main__ import build, parse_args
from services.sim.robot import BURGER
from services.sim.sim import CMD_TIMEOUT_S, SimConfig, Simulation
from services.sim.world_spec import load_world
from tests.unit.sim.conftest import MakeWorld

pytestmark = pytest.mark.timeout(30)

# the Burger's acceleration limits (models/turtlebot3_burger.yaml): the motors reach a command
# at these, and brake at them when the timeout zeroes it
ACCEL, ANGULAR_ACCEL = BURGER.max_linear_accel_mps2, BURGER.max_angular_accel_rps2


def ramp_loss(speed: float, accel: float, dt: float) -> float:
    """How much less than ``speed x time`` a robot starting from rest covers, ramping up by
    ``accel x dt`` per step; braking to rest at the same rate covers exactly this much more
    than stopping dead, so a run that ends standing covers ``speed x time`` in all."""
    k, loss = 1, 0.0
    while k * accel * dt < speed:
        loss += (speed - k * accel * dt) * dt
        k += 1
    return loss


@pytest.fixture
def open_floor(make_world: MakeWorld) -> Path:
    return make_world(8.0, 4.0)  # r1 at (1, 1) facing +x, nothing within 6 m ahead


@pytest.fixture
def sim(open_floor: Path) -> Iterator[Simulation]:
    simulation = Simulation(load_world(open_floor), SimConfig(), lambda *_: None)
    try:
        yield simulation
    finally:
        simulation.close()


def test_the_default_is_the_firmwares_half_second() -> None:
    assert CMD_TIMEOUT_S == 0.5 and SimConfig().cmd_timeout_s == 0.5


def test_a_robot_whose_commands_stop_coming_stops_after_the_timeout(sim: Simulation) -> None:
    robot = sim.robots[0]
    sim.set_command("r1", 0.2, 0.0)
    sim.run_for(0.5 - sim.dt)
    assert robot.linear == pytest.approx(0.2)  # still obeying, one step before the timeout
    sim.step()  # the command has been obeyed for 0.5 s now
    sim.step()
    assert (robot.cmd_linear, robot.cmd_angular) == (0.0, 0.0)
    assert robot.linear == pytest.approx(0.2 - ACCEL * sim.dt)  # braking at the limit
    # it drove on its last command for exactly 0.5 s, then braked to a standstill
    sim.run_for(2.0)
    assert robot.x == pytest.approx(1.0 + 0.2 * 0.5, abs=1e-9)
    assert sim.cmd_timeout_stops == 1


def test_commands_every_tenth_of_a_second_keep_it_going(sim: Simulation) -> None:
    for _ in range(30):
        sim.set_command("r1", 0.2, 0.0)
        sim.run_for(0.1)
    still = ramp_loss(0.2, ACCEL, sim.dt)  # driving yet: the ramp up is not made good
    assert sim.robots[0].x == pytest.approx(1.0 + 0.2 * 3.0 - still, abs=1e-9)
    assert sim.robots[0].linear == pytest.approx(0.2)
    assert sim.cmd_timeout_stops == 0


def test_the_next_command_after_a_stop_moves_it_again(sim: Simulation) -> None:
    sim.set_command("r1", 0.0, 1.0)
    sim.run_for(1.0)
    assert sim.robots[0].yaw == pytest.approx(0.5, abs=1e-9)  # turned for 0.5 s only
    sim.set_command("r1", 0.0, 1.0)
    sim.run_for(0.45)
    turned = 1.0 * 0.45 - ramp_loss(1.0, ANGULAR_ACCEL, sim.dt)
    assert sim.robots[0].yaw == pytest.approx(0.5 + turned, abs=1e-9)
    assert sim.robots[0].angular == pytest.approx(1.0)
    assert sim.cmd_timeout_stops == 1


def test_a_standing_robot_is_not_counted_as_stopped(sim: Simulation) -> None:
    sim.set_command("r1", 0.0, 0.0)
    sim.run_for(2.0)
    assert sim.cmd_timeout_stops == 0


def test_each_robot_times_out_on_its_own_commands(make_world: MakeWorld) -> None:
    robots = [{"id": "a", "x": 1.0, "y": 1.0}, {"id": "b", "x": 1.0, "y": 3.0}]
    sim = Simulation(load_world(make_world(8.0, 4.0, robots=robots)), SimConfig(), lambda *_: None)
    try:
        sim.set_command("a", 0.2, 0.0)
        for _ in range(20):
            sim.set_command("b", 0.1, 0.0)  # b's commands say nothing about a's
            sim.run_for(0.1)
        a, b = sim.robots
        b_still = ramp_loss(0.1, ACCEL, sim.dt)  # b drives yet
        assert a.x == pytest.approx(1.1, abs=1e-9)
        assert b.x == pytest.approx(1.2 - b_still, abs=1e-9)
        assert sim.cmd_timeout_stops == 1
    finally:
        sim.close()


def test_the_timeout_is_counted_in_sim_steps_at_any_physics_rate(open_floor: Path) -> None:
    config = SimConfig(physics_hz=120.0, cmd_timeout_s=0.25)
    sim = Simulation(load_world(open_floor), config, lambda *_: None)
    try:
        sim.set_command("r1", 0.2, 0.0)
        sim.run_for(1.0)
        assert sim.robots[0].x == pytest.approx(1.0 + 0.2 * 0.25, abs=1e-9)
    finally:
        sim.close()


def test_zero_disables_it(open_floor: Path) -> None:
    sim = Simulation(load_world(open_floor), SimConfig(cmd_timeout_s=0.0), lambda *_: None)
    try:
        sim.set_command("r1", 0.2, 0.0)
        sim.run_for(2.0)
        still = ramp_loss(0.2, ACCEL, sim.dt)
        assert sim.robots[0].x == pytest.approx(1.4 - still, abs=1e-9)
        assert sim.cmd_timeout_stops == 0
    finally:
        sim.close()


@pytest.mark.parametrize("bad", [-0.1, math.nan, math.inf])
def test_a_bad_timeout_is_refused(bad: float) -> None:
    with pytest.raises(ConfigError, match="--cmd-timeout"):
        SimConfig(cmd_timeout_s=bad)


def test_the_option_and_its_variable(open_floor: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("PNAV_SIM_CMD_TIMEOUT", raising=False)
    world = ["--world", str(open_floor)]
    assert build(parse_args(world))[1].cmd_timeout_s == 0.5
    assert build(parse_args([*world, "--cmd-timeout", "0"]))[1].cmd_timeout_s == 0.0
    monkeypatch.setenv("PNAV_SIM_CMD_TIMEOUT", "0.3")
    assert build(parse_args(world))[1].cmd_timeout_s == 0.3
    assert build(parse_args([*world, "--cmd-timeout", "1"]))[1].cmd_timeout_s == 1.0
    monkeypatch.setenv("PNAV_SIM_CMD_TIMEOUT", "0")
    assert build(parse_args(world))[1].cmd_timeout_s == 0.0  # 0 is "never", not "unset"
    monkeypatch.setenv("PNAV_SIM_CMD_TIMEOUT", "-1")
    with pytest.raises(ConfigError, match="PNAV_SIM_CMD_TIMEOUT"):
        build(parse_args(world))


def test_the_most_a_robot_drove_after_its_last_command_is_measured(sim: Simulation) -> None:
    for _ in range(10):  # commands every 0.1 s: at most 0.02 m on any one of them
        sim.set_command("r1", 0.2, 0.0)
        sim.run_for(0.1)
    assert sim.max_after_command_m == pytest.approx(0.2 * 0.1, abs=1e-9)
    # the stream stops: the timeout zeroes the command after 0.1 m, and the motors brake at
    # their deceleration, covering the ramp's worth more
    sim.run_for(2.0)
    braking = ramp_loss(0.2, ACCEL, sim.dt)
    assert sim.max_after_command_m == pytest.approx(0.2 * 0.5 + braking, abs=1e-9)
