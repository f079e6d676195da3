"""The dodge scenario tick by tick: a Jackal's 720-beam scan cast exactly into small worlds
(tests/unit/local/scene.py), one scan every 0.02 s of sim time as its lidar sends them, the
robot moved by its odometry between scans. The tracker follows a mover and not a wall or a
box; the decision yields before a mover's line, steps a standing robot out of a mover's way,
and stays silent among static clutter."""

from __future__ import annotations

import math
from typing import cast

import pytest

from common.contract.records import Odometry
from common.controller_core.scenario import Command, Host, ScenarioSpec, installed_scenarios
from pnav_local.dodge import Dodge, decide_for
from pnav_local.tracks import MAX_TRACKS, Tracker
from tests.unit.local.scene import JACKAL, Disc, Segment, box, scan_at

PERIOD = 0.02  # the Jackal's lidar: 50 Hz
CORRIDOR: list[Segment] = [(0.0, 0.0, 0.0, 12.0), (4.8, 0.0, 4.8, 12.0)]
NORTH = math.pi / 2  # the robot drives up the corridor (+y), as in the BARN worlds


def drive(
    tracker: Tracker,
    discs: list[Disc],
    walls: list[Segment],
    *,
    start: tuple[float, float],
    speed: float,
    ticks: int,
    obey: bool = False,
    period: float = PERIOD,
) -> list[tuple[float, Command | None, float]]:
    """``ticks`` scans of a robot heading north from ``start``: at ``speed`` throughout, or,
    with ``obey``, at dodge's command whenever it gives one (reached at once: the Jackal's
    10 m/s^2 covers 2 m/s in 0.2 s, 10 scans). Returns (t, command, speed) per scan."""
    x, y = start
    v = speed
    out = []
    for i in range(ticks):
        t = i * period
        pose = (x, y, NORTH)
        scan = scan_at(pose, discs, walls, t, i + 1)
        odom = Odometry(i + 1, "r1", t, x, y, NORTH, v, 0.0)
        command = decide_for(tracker, scan, odom, JACKAL)
        out.append((t, command, v))
        if obey and command is not None:
            v = command.linear
        y += v * period
    return out


def test_a_mover_is_followed_at_its_velocity_and_the_walls_are_not() -> None:
    tracker = Tracker()
    mover = Disc(4.0, 5.0, 0.19, vx=-0.8)  # crossing the corridor 4.3 m ahead, right to left
    drive(tracker, [mover], CORRIDOR, start=(2.4, 0.7), speed=1.0, ticks=25)
    moving = tracker.moving()
    assert len(moving) == 1, "the mover, and neither wall"
    (track,) = moving
    assert (track.vx, track.vy) == pytest.approx((-0.8, 0.0), abs=0.08)
    assert track.radius == pytest.approx(0.19, abs=0.06)
    # where it is now, within the centre estimate's error (the face seen, pushed back)
    assert (track.last_x, track.last_y) == pytest.approx(mover.at(24 * PERIOD), abs=0.08)


def test_a_track_needs_time_before_it_counts_as_moving() -> None:
    tracker = Tracker()
    mover = Disc(4.0, 3.0, 0.19, vx=-0.8)
    ticks = drive(tracker, [mover], CORRIDOR, start=(2.4, 0.7), speed=0.0, ticks=8)
    # 0.14 s of scans: too short a history to fit a velocity, so nothing is said yet
    assert tracker.moving() == []
    assert all(command is None for _, command, _ in ticks)


def test_static_clutter_never_moves_and_dodge_stays_silent() -> None:
    # BARN-like clutter on both sides of the robot's way: boxes of 0.15 to 0.45 m and posts,
    # passed at the Jackal's top speed, faces turning into view as it goes
    walls = list(CORRIDOR)
    for i, (x, y) in enumerate([(1.2, 2.5), (3.6, 3.0), (1.0, 4.2), (3.5, 5.1), (1.4, 6.3)]):
        walls += box(x, y, (0.075, 0.15, 0.225)[i % 3])
    posts = [Disc(3.3, 2.0, 0.1), Disc(1.5, 3.4, 0.2), Disc(3.4, 6.8, 0.15)]
    tracker = Tracker()
    ticks = drive(tracker, posts, walls, start=(2.4, 0.7), speed=2.0, ticks=150)
    said = [(t, c.reason) for t, c, _ in ticks if c is not None]
    assert said == []
    assert tracker.tracks, "it did follow the clutter's objects"
    assert tracker.moving() == []


def test_a_mover_crossing_ahead_makes_the_robot_yield_before_its_line() -> None:
    # at 2 m/s the robot would reach y = 3 as the mover (0.8 m/s from the right) does
    mover = Disc(3.4, 3.0, 0.19, vx=-0.8)
    ticks = drive(Tracker(), [mover], CORRIDOR, start=(2.4, 0.7), speed=2.0, ticks=16)
    first = next((t, c) for t, c, _ in ticks if c is not None)
    t, command = first
    assert command is not None
    assert t <= 0.3, "as soon as the track has a velocity"
    assert command.linear < 2.0 and command.angular == 0.0, "slower, on its way: a yield"
    assert "mover track 1" in command.reason
    assert "moving 0.8" in command.reason
    # told before the contact itself: the mover is about to cross safety_stop's reach
    assert "contact in" in command.reason or "in safety_stop's reach in" in command.reason
    assert "yield" in command.reason


def test_obeying_it_the_robot_lets_the_mover_pass_and_never_touches_it() -> None:
    for start_x, speed in ((3.4, -0.8), (3.0, -0.5), (1.0, 0.6), (4.0, -1.0)):
        mover = Disc(start_x, 3.0, 0.19, vx=speed)
        ticks = drive(
            Tracker(), [mover], CORRIDOR, start=(2.4, 0.7), speed=2.0, ticks=200, obey=True
        )
        y = 0.7
        closest = math.inf
        for i, (t, _, v) in enumerate(ticks):
            mx, my = mover.at(t)
            closest = min(closest, math.hypot(mx - 2.4, my - y) - 0.19 - JACKAL.footprint_radius_m)
            y += v * PERIOD if i + 1 < len(ticks) else 0.0
        assert closest > 0.05, (start_x, speed, closest)
        assert y > 5.0, "and went on once it had"


def test_a_mover_heading_at_a_standing_robot_makes_it_step_out_of_the_way() -> None:
    # standing on the mover's line (dwa turned in place, or safety_stop stopped it there)
    mover = Disc(4.2, 3.0, 0.19, vx=-0.8)
    ticks = drive(Tracker(), [mover], CORRIDOR, start=(2.4, 3.0), speed=0.0, ticks=20)
    said = [c for _, c, _ in ticks if c is not None]
    assert said, "it saw the threat"
    command = said[0]
    assert command.linear > 0.0, "it drives off the line (its lidar sees nothing behind)"
    assert "step out of its way" in command.reason and "mover track 1" in command.reason


def test_a_mover_going_away_is_no_threat() -> None:
    mover = Disc(2.9, 3.0, 0.19, vx=0.8)  # already past the robot's way, leaving it
    ticks = drive(Tracker(), [mover], CORRIDOR, start=(2.4, 0.7), speed=1.0, ticks=30)
    assert all(c is None for _, c, _ in ticks)


def test_the_same_scans_give_the_same_commands() -> None:
    mover = Disc(3.4, 3.0, 0.19, vx=-0.8)

    def run() -> list[tuple[float, Command | None]]:
        ticks = drive(
            Tracker(), [mover], CORRIDOR, start=(2.4, 0.7), speed=2.0, ticks=60, obey=True
        )
        return [(t, c) for t, c, _ in ticks]

    assert run() == run()


def test_the_tracks_are_bounded_whatever_the_scan_holds() -> None:
    posts = [Disc(0.5 + 0.45 * i, 2.0 + 0.45 * j, 0.1) for i in range(10) for j in range(12)]
    tracker = Tracker()
    drive(tracker, posts, [], start=(2.4, 0.7), speed=1.0, ticks=5)
    assert len(tracker.tracks) <= MAX_TRACKS


def test_a_recommendation_lives_a_few_scan_periods() -> None:
    spec = ScenarioSpec(JACKAL, "GOTO_DODGE", {})
    rule = Dodge(cast(Host, None), ("r1", "dodge"), spec)  # the host: only to run as a rule
    rule.start()  # as its supervisor does: initialise() sets up its tracks
    assert rule.ttl_s() == pytest.approx(0.1), "before a second scan: the floor"
    tracker = rule.tracker
    assert isinstance(tracker, Tracker)
    drive(tracker, [], CORRIDOR, start=(2.4, 0.7), speed=1.0, ticks=3)
    # the Jackal's 50 Hz: 3 periods are 0.06 s, under the floor of 0.1 s
    assert rule.ttl_s() == pytest.approx(0.1)
    # a 10 Hz lidar: 3 periods, 0.3 s; a 5 Hz one (the Burger's): the usual 0.5 s at most
    for period, ttl in ((0.1, 0.3), (0.2, 0.5)):
        slow = Tracker()
        drive(slow, [], CORRIDOR, start=(2.4, 0.7), speed=1.0, ticks=3, period=period)
        rule.tracker = slow
        assert rule.ttl_s() == pytest.approx(ttl)


def test_dodge_is_found_by_its_entry_point() -> None:
    assert installed_scenarios()["dodge"] is Dodge
    assert Dodge.priority == 90  # above recovery (70), below the safety band (100)
