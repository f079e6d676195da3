"""The monolith end to end: whole episodes on real worlds, one process, no database.

Each episode takes about a second (the sim runs tens of times faster than real time)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from common.contract import records
from pnav.bench.nav.stack_episode import Combo, Episode, Outcome
from pnav.bench.nav.worldfile import read_benchmark
from pnav.monolith.monolith_episode import MonolithOutcome, run_monolith_episode
from pnav.monolith.monolith_stack import MonolithStack
from pnav.monolith.strategies import combo_strategy, shipped_strategies
from services.controller.avoid_left import AvoidLeft
from services.controller.avoid_right import AvoidRight
from services.controller.safety_stop import SafetyStop
from services.sim.sim import SimConfig
from services.sim.world_spec import load_world

ROOT = Path(__file__).resolve().parents[3]
EASY = ROOT / "worlds" / "barn" / "barn_easy_000.yaml"
AVOID = Combo("GOTO_AVOID", "turn_then_move")
DIRECT = Combo("GOTO_DIRECT", "turn_then_move")


def barn_episode(path: Path, combo: Combo) -> Episode:
    bench = read_benchmark(path)
    return Episode(path, bench.goal, combo, bench.time_limit_s)


@pytest.fixture(scope="module")
def easy() -> MonolithOutcome:
    return run_monolith_episode(barn_episode(EASY, AVOID))


@pytest.fixture
def box_ahead(tmp_path: Path) -> Path:
    """An empty room, and a crate the map does not show 0.35 m in front of the robot, on
    the straight line to the goal: the avoid scenarios must see it at the first scan."""
    world = tmp_path / "box_ahead.yaml"
    world.write_text(
        "name: box_ahead\n"
        f"map: {ROOT / 'worlds' / 'maps' / 'open_room.yaml'}\n"
        "robots:\n  - {id: r1, x: 1.0, y: 2.5, yaw: 0.0}\n"
        "obstacles:\n  - {name: crate, type: box, x: 1.45, y: 2.5, size: [0.2, 0.6, 0.4]}\n"
    )
    return world


def test_an_easy_barn_world_is_solved_with_goto_avoid(easy: MonolithOutcome) -> None:
    assert isinstance(easy, Outcome)  # what the navigation benchmark takes
    assert easy.end == "goal"
    assert easy.final_distance_m <= 0.3
    assert 0.0 < easy.time_s < read_benchmark(EASY).time_limit_s
    assert easy.collisions == []
    assert easy.trajectory[0][0] >= 0.0  # times from the first decision, as episode.py's
    start = read_benchmark(EASY).start
    assert math.dist(easy.trajectory[0][1:], start[:2]) < 0.05
    assert easy.watchdog_stops == 0 and easy.rule_errors == 0
    assert easy.decided_by.get("turn_then_move", 0) > 100  # the planner drove
    assert easy.cpu_s > 0.0 and easy.wall_s > 0.0


def test_the_same_episode_twice_drives_the_same_trajectory(easy: MonolithOutcome) -> None:
    again = run_monolith_episode(barn_episode(EASY, AVOID))
    assert again.trajectory == easy.trajectory
    assert (again.end, again.time_s, again.decided_by) == (easy.end, easy.time_s, easy.decided_by)


def test_sense_to_act_latency_samples_are_positive_and_small(easy: MonolithOutcome) -> None:
    lat = easy.latency_ms
    # at least one sample per planner recommendation period (0.1 s) of the run
    assert len(lat) >= easy.time_s / 0.1 * 0.8
    assert min(lat) > 0.0
    # no transport and no database: well under a millisecond typically; generous bounds
    # for a loaded test machine
    assert float(np.median(lat)) < 20.0
    assert max(lat) < 1000.0


def test_goto_direct_has_no_avoidance_where_goto_avoid_steers_away(box_ahead: Path) -> None:
    avoid = run_monolith_episode(Episode(box_ahead, (3.5, 2.5), AVOID, 40.0))
    direct = run_monolith_episode(Episode(box_ahead, (3.5, 2.5), DIRECT, 40.0))
    avoiders = {"avoid_left", "avoid_right"}
    # GOTO_AVOID names the avoid scenarios: they see the crate and win over the planner
    assert avoiders & set(avoid.decided_by)
    # GOTO_DIRECT does not: they never run, the planner alone goes round the crate
    assert not avoiders & set(direct.recommended_by)
    assert direct.trajectory != avoid.trajectory
    assert (avoid.end, direct.end) == ("goal", "goal")
    assert avoid.collisions == direct.collisions == []


def test_the_controller_scenarios_get_the_records_the_service_gives_them(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    seen: list[tuple[str, Any, Any, Any, Mapping[str, Any]]] = []
    for cls in (AvoidLeft, AvoidRight, SafetyStop):
        original = cls.decide

        def spy(
            klass: type[Any], scan: Any, odom: Any, robot: Any, params: Any, _o: Any = original
        ) -> Any:
            seen.append((klass.scenario, scan, odom, robot, params))
            return _o(scan, odom, robot, params)

        monkeypatch.setattr(cls, "decide", classmethod(spy))
    shipped = shipped_strategies()
    strategy = combo_strategy(AVOID, shipped)
    stack = MonolithStack(load_world(EASY), SimConfig(), [*shipped.values(), strategy])
    try:
        stack.set_strategy("r1", strategy.code)
        stack.set_goal("r1", *read_benchmark(EASY).goal)
        for _ in range(int(1.5 / stack.sim.dt)):
            stack.step()
    finally:
        stack.close()
    assert {name for name, *_ in seen} == {"avoid_left", "avoid_right", "safety_stop"}
    looked: set[tuple[str, int]] = set()
    for name, scan, odom, robot, params in seen:
        assert type(scan) is records.LaserScan
        assert scan.ranges.dtype == np.float32 and len(scan.ranges) == 360  # real[360]
        if name == "safety_stop":  # the one that asks for odometry (needs_odometry)
            assert type(odom) is records.Odometry
            # the newest odometry when the rule runs: a scenario that recommended nothing
            # looks at the same scan again, with newer odometry, while the scan is fresh
            assert 0.0 <= odom.stamp - scan.stamp <= 0.5
        else:
            assert odom is None
        assert type(robot) is records.Robot and robot.robot_id == "r1"
        assert robot.max_linear_mps == pytest.approx(0.22)
        assert dict(params) == strategy.params
        looked.add((name, scan.id))
    scans = {scan_id for _name, scan_id in looked}
    # every scenario looked at every scan of 1.5 s at 5 Hz
    assert len(scans) >= 7 and len(looked) == 3 * len(scans)
