"""Sim-time schedules, --rate parsing and wall-clock pacing."""

from __future__ import annotations

import pytest

from common.errors import ConfigError
from services.sim.pacing import MAX, Every, Pacer, parse_rate

pytestmark = pytest.mark.timeout(10)


@pytest.mark.parametrize("hz, physics_hz", [(5, 240), (30, 240), (1, 240), (7, 240), (30, 100)])
def test_every_fires_at_the_exact_long_run_rate(hz: float, physics_hz: float) -> None:
    every = Every(1.0 / hz, 1.0 / physics_hz)
    fired = [step for step in range(int(10 * physics_hz)) if every.due(step)]
    assert len(fired) == pytest.approx(10 * hz, abs=1)
    assert fired[0] == 0


def test_scans_land_on_exact_multiples_of_the_period() -> None:
    every = Every(0.2, 1 / 240)
    assert [s for s in range(500) if every.due(s)] == list(range(0, 500, 48))


def test_parse_rate() -> None:
    assert parse_rate("max") == MAX and parse_rate("MAX") == MAX
    assert parse_rate("10") == 10.0 and parse_rate(0.5) == 0.5
    for bad in ("fast-ish", "-1", "nan"):
        with pytest.raises(ConfigError):
            parse_rate(bad)


class FakeWall:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_pacer_follows_the_rate_in_sim_time() -> None:
    wall = FakeWall()
    pacer = Pacer(10.0, 1 / 240, wall=wall)
    assert pacer.steps_due(0) == 0
    wall.now += 0.1  # 0.1 wall s at 10x = 1 sim s = 240 steps
    assert pacer.steps_due(0) == 240
    assert pacer.steps_due(240) == 0
    assert pacer.wall_until_next(240) == pytest.approx(1 / 2400)


def test_pacer_drops_debt_when_it_cannot_keep_up() -> None:
    wall = FakeWall()
    pacer = Pacer(1.0, 1 / 240, wall=wall, max_lag_s=0.25)
    wall.now += 5.0
    assert pacer.steps_due(0) == 1 and pacer.slips == 1
    assert pacer.steps_due(1) == 0  # re-anchored: no burst


def test_max_rate_always_owes_steps() -> None:
    pacer = Pacer(MAX, 1 / 240)
    assert pacer.steps_due(10**6) > 10**6
    assert pacer.wall_until_next(0) == 0.0


def test_time_the_sim_stood_held_is_owed_no_steps_and_is_no_slip() -> None:
    wall = FakeWall()
    pacer = Pacer(5.0, 1 / 240, wall=wall)
    wall.now += 30.0  # held 30 wall seconds (services/sim/hold.py)
    pacer.restart(0)
    assert pacer.steps_due(0) == 0 and pacer.slips == 0
    wall.now += 0.1  # then paced at the rate again: 0.5 sim s
    assert pacer.steps_due(0) == 120


def test_a_run_message_says_until_when_or_on() -> None:
    from services.sim.hold import parse_until

    assert parse_until({"until": 3}) == 3.0 and parse_until({"until": None}) is None
    for bad in ({"until": -0.1}, {"until": float("inf")}, {"until": True}, {"until": "3"}, {}, []):
        with pytest.raises((ValueError, KeyError, TypeError)):
            parse_until(bad)
