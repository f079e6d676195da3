"""The battery model: drains with motion, charges at a station, stays within [0, capacity]."""

from __future__ import annotations

from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from services.sim.battery import Battery, BatteryModel
from services.sim.sim import SimConfig, Simulation
from services.sim.world_spec import load_world
from tests.unit.sim.conftest import MakeWorld

pytestmark = pytest.mark.timeout(30)

MODEL = BatteryModel()

steps = st.lists(
    st.tuples(
        st.floats(0.0, 600.0),  # dt, s: long steps push against the bounds
        st.floats(-0.22, 0.22),
        st.floats(-2.84, 2.84),
        st.one_of(st.none(), st.floats(0.0, 200.0)),
    ),
    max_size=40,
)


@settings(max_examples=200, deadline=None)
@given(start=st.floats(0.0, 100.0), sequence=steps)
def test_energy_never_leaves_zero_to_capacity(start: float, sequence: list[Any]) -> None:
    bat = Battery.at_percent(MODEL, start)
    for dt, v, w, charge in sequence:
        bat.step(dt, v, w, charge)
        assert 0.0 <= bat.energy_wh <= MODEL.capacity_wh
        assert 0.0 <= bat.percentage <= 100.0
        assert bat.charging == (charge is not None)


@settings(max_examples=100, deadline=None)
@given(v=st.floats(-0.22, 0.22), w=st.floats(-2.84, 2.84))
def test_moving_drains_at_least_as_fast_as_idling(v: float, w: float) -> None:
    idle, moving = Battery.at_percent(MODEL, 50), Battery.at_percent(MODEL, 50)
    idle.step(10.0, 0.0, 0.0, None)
    moving.step(10.0, v, w, None)
    assert moving.energy_wh <= idle.energy_wh < 0.5 * MODEL.capacity_wh
    assert moving.power_w == pytest.approx(MODEL.idle_w + 10.0 * abs(v) + 0.5 * abs(w))


def test_documented_figures() -> None:
    # idle 1.5 W; flat out 1.5 + 10 * 0.22 + 0.5 * 2.84 = 5.12 W
    assert MODEL.load_w(0.0, 0.0) == 1.5
    assert MODEL.load_w(0.22, 2.84) == pytest.approx(5.12)
    bat = Battery.at_percent(MODEL, 100)
    bat.step(3600.0, 0.0, 0.0, None)
    assert bat.energy_wh == pytest.approx(19.98 - 1.5)


def test_charging_is_negative_power_and_stops_at_full() -> None:
    bat = Battery.at_percent(MODEL, 50)
    bat.step(60.0, 0.0, 0.0, 20.0)
    assert bat.charging and bat.power_w == pytest.approx(1.5 - 20.0)
    assert bat.energy_wh > 0.5 * MODEL.capacity_wh
    bat.step(10 * 3600.0, 0.0, 0.0, 20.0)
    assert bat.energy_wh == MODEL.capacity_wh and bat.power_w == 0.0


def test_in_the_sim_a_robot_drains_when_moving_and_charges_at_a_station(
    make_world: MakeWorld,
) -> None:
    path = make_world(
        6.0,
        6.0,
        robots=[
            {"id": "mover", "x": 1.0, "y": 1.0, "battery": 50},
            {"id": "idler", "x": 1.0, "y": 3.0, "battery": 50},
            {"id": "docked", "x": 4.0, "y": 4.0, "battery": 50},
        ],
        charging_stations=[{"id": "dock", "x": 4.05, "y": 4.0, "radius": 0.3, "power": 30.0}],
    )
    last: dict[str, dict[str, Any]] = {}

    def sink(robot: str, topic: str, msg: dict[str, Any]) -> None:
        if topic == "battery":
            last[robot] = msg

    # the mover's command is held all along, as the stack's re-issues would hold it
    sim = Simulation(load_world(path), SimConfig(cmd_timeout_s=0.0), sink)
    try:
        sim.set_command("mover", 0.2, 0.5)
        sim.run_for(30.0)
    finally:
        sim.close()
    start = 0.5 * 19.98
    mover, idler, docked = last["mover"], last["idler"], last["docked"]
    assert mover["energy_wh"] < idler["energy_wh"] < start
    assert mover["power_w"] > idler["power_w"] == pytest.approx(1.5)
    assert not mover["charging"] and not idler["charging"]
    assert docked["charging"] and docked["power_w"] == pytest.approx(1.5 - 30.0)
    assert docked["energy_wh"] > start
    assert docked["percentage"] == pytest.approx(100 * docked["energy_wh"] / 19.98)


def test_a_flat_battery_does_not_move(make_world: MakeWorld) -> None:
    world = load_world(make_world(4.0, 4.0))
    sim = Simulation(world, SimConfig(battery_percent=0.0), lambda *_: None)
    try:
        sim.set_command("r1", 0.2, 0.0)
        sim.run_for(1.0)
        assert (sim.robots[0].x, sim.batteries[0].energy_wh) == (1.0, 0.0)
    finally:
        sim.close()
