"""dodge and safety_stop's reach, tick by tick: an evasion dodge picks is never one the
controller's safety_stop stops in its first steps (the dynamic suite's hard worlds: a swerve
at top speed past one mover put another inside safety_stop's reach, and the robot stood
there, held by the stop, until a third hit it); what the robot is about to do counts as a
threat when safety_stop would stop it for a mover; and a mover turning back at the end of
its line stays a mover through the turn. The same Jackal scan as test_dodge.py, cast
exactly, and the real safety_stop judging it."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from common.contract.records import Odometry
from pnav_local import threats
from pnav_local.dodge import decide_for, static_hits
from pnav_local.tracks import STICKY_S, Cluster, Track, Tracker
from services.controller.safety_stop import SafetyStop
from tests.unit.local.scene import JACKAL_BOX, Disc, Segment, scan_at

PERIOD = 0.02
CORRIDOR: list[Segment] = [(0.0, 0.0, 0.0, 12.0), (4.8, 0.0, 4.8, 12.0)]
NORTH = math.pi / 2


def first_stop(motion: threats.FloatArray, discs: list[Disc]) -> float:
    """The first roll-out step (within STOPPABLE_S) at which the real safety_stop, judging
    the scan cast from that pose with the discs where they are then, stops the robot (inf:
    none). The robot starts at the origin facing +x: the roll-out's frame is the world's."""
    for k, t in enumerate(threats.times()):
        if t > threats.STOPPABLE_S + 1e-9:
            break
        x, y, th, v = (float(c) for c in motion[k])
        scan = scan_at((x, y, th), discs, [], float(t), k + 1)
        odom = Odometry(k + 1, "r1", float(t), x, y, th, v, 0.0)
        if SafetyStop.decide(scan, odom, JACKAL_BOX, {}) is not None:
            return float(t)
    return math.inf


def as_movers(discs: list[Disc]) -> list[threats.Mover]:
    return [threats.Mover(i + 1, d.x, d.y, d.vx, d.vy, d.radius) for i, d in enumerate(discs)]


def points_of(discs: list[Disc]) -> threats.FloatArray:
    """The hits of the scan at the origin, as dodge takes the standing ones."""
    scan = scan_at((0.0, 0.0, 0.0), discs, [], 0.0, 1)
    return static_hits(scan, Tracker())[0]


def test_whatever_safety_stop_stops_dodge_sees_first() -> None:
    # a post and a crossing mover at many places ahead, the robot at several speeds and
    # evasions: when the real safety_stop stops a motion at some step of its first 0.5 s,
    # dodge's judgement of the motion says so no later (it may say so sooner: it keeps 0.1 m
    # more, as the robot overshoots the speed asked and a track's outline is an estimate)
    told = stopped = cases = 0
    for v0 in (0.5, 1.0, 2.0):
        for target in ((2.0, 0.0), (1.4, 2.0), (0.8, -1.0), (0.4, 0.0)):
            motion = threats.rollout(v0, 0.0, *target, JACKAL_BOX)
            for ax in (0.5, 0.8, 1.1, 1.4):
                for ay in (-0.6, -0.3, 0.0, 0.3, 0.6):
                    for vy in (0.0, 0.8, -0.8):
                        discs = [Disc(ax, ay, 0.2, vy=vy)]
                        real = first_stop(motion, discs)
                        if vy == 0.0:  # standing: a hit of the scan
                            points, movers = points_of(discs), []
                        else:
                            points, movers = np.zeros((0, 2)), as_movers(discs)
                        judged = threats.stopped_at(
                            motion, points, movers, JACKAL_BOX, threats.StopReach()
                        )
                        assert judged[0] <= real, (v0, target, ax, ay, vy, real, judged)
                        cases += 1
                        stopped += math.isfinite(real)
                        told += math.isfinite(judged[0])
    assert stopped > cases // 4, "the cases include many that safety_stop stops"
    assert told < cases * 3 // 4, "and dodge does not call every motion stopped"


def test_the_evasion_chosen_is_not_one_safety_stop_stops() -> None:
    # a robot at 2 m/s; a mover 1.2 m ahead, crossing its way to the right at 1 m/s (its
    # contact margins clear of the box). A yield at 1.4 m/s keeps it in safety_stop's reach
    # 0.3 s later: stopped and held there, in the way of whatever comes next
    discs = [Disc(1.2, 0.0, 0.2, vy=-1.0)]
    movers = as_movers(discs)
    none = np.zeros((0, 2))
    chosen = threats.choose(2.0, 0.0, JACKAL_BOX, movers, none, False)
    motion = threats.rollout(2.0, 0.0, chosen.v, chosen.w, JACKAL_BOX)
    assert chosen.v >= threats.BRISK_SHARE * 2.0, "it keeps going, briskly"
    assert math.isinf(first_stop(motion, discs)), chosen
    # without the judgement (no step looked at): the faster yield, which safety_stop stops
    stoppable, threats.STOPPABLE_S = threats.STOPPABLE_S, 0.0
    try:
        blind = threats.choose(2.0, 0.0, JACKAL_BOX, movers, none, False)
    finally:
        threats.STOPPABLE_S = stoppable
    assert blind.v > chosen.v
    assert math.isfinite(first_stop(threats.rollout(2.0, 0.0, blind.v, blind.w, JACKAL_BOX), discs))


def test_a_mover_about_to_enter_safety_stops_reach_is_a_threat_without_contact() -> None:
    # 0.8 m ahead and 0.2 m left, leaving to the left at 1 m/s: never within the margins of
    # the box, but within safety_stop's reach of a robot at 1 m/s (or speeding up) at once
    mover = threats.Mover(1, 0.8, 0.2, 0.0, 1.0, 0.2)
    threat = threats.expected(1.0, 0.0, JACKAL_BOX, [mover])
    assert math.isinf(threat.ttc)
    assert threat.stop <= 0.2 and threat.stop_mover == 1
    assert threat.threat == threat.stop
    # once it has left the way, it is not
    gone = threats.Mover(1, 0.8, 0.6, 0.0, 1.0, 0.2)
    assert math.isinf(threats.expected(1.0, 0.0, JACKAL_BOX, [gone]).threat)


@dataclass(frozen=True)
class Shuttle:
    """A cylinder going back and forth along x between x0 and x1 at ``speed`` (the dynamic
    worlds' movers), starting at x0 heading toward x1."""

    x0: float
    x1: float
    y: float
    radius: float
    speed: float

    def at(self, t: float) -> tuple[float, float]:
        length = self.x1 - self.x0
        s = math.fmod(self.speed * t, 2.0 * length)
        return (self.x0 + s if s <= length else self.x1 - (s - length)), self.y


def test_a_mover_turning_back_stays_a_mover_and_its_velocity_turns_within_scans() -> None:
    # 0.8 m/s across 2.3 m ahead of a standing robot, turning back at x = 3.9 (t = 3.0 s):
    # its centres go out and come back, off any one line for the 0.5 s window, and its points
    # come back over the surface they left. Main's tracker dropped it from the movers for
    # 0.4 s through the turn, its speed falling to nothing; the robot drove at it
    shuttle = Shuttle(1.5, 3.9, 3.0, 0.2, 0.8)
    turn = (shuttle.x1 - shuttle.x0) / shuttle.speed
    tracker = Tracker()
    told_at: float | None = None
    turned_at: float | None = None
    for i in range(int((turn + 0.8) / PERIOD)):
        t = i * PERIOD
        scan = scan_at((2.4, 0.7, NORTH), [shuttle], CORRIDOR, t, i + 1)  # type: ignore[list-item]
        tracker.update(scan, Odometry(i + 1, "r1", t, 2.4, 0.7, NORTH, 0.0, 0.0))
        movers = tracker.movers()
        if told_at is None:
            if movers:
                told_at = t
            continue
        assert len(movers) == 1, (t, "lost through the turn")
        (k,) = movers
        if t < turn:
            assert k.vx == pytest.approx(0.8, abs=0.15), t
        elif turned_at is None and k.vx < -0.5:
            turned_at = t
        if turned_at is not None:
            assert k.vx == pytest.approx(-0.8, abs=0.25), (t, k.vx)
    assert told_at is not None and told_at < 0.5
    assert turned_at is not None and turned_at - turn <= 0.15, turned_at


def test_a_standing_box_is_not_kept_moving() -> None:
    # stickiness is for tracks told moving: a box that never was stays a standing hit
    tracker = Tracker()
    post = [Disc(3.0, 2.5, 0.2)]
    y = 0.7
    for i in range(int(STICKY_S / PERIOD) * 3):
        t = i * PERIOD
        scan = scan_at((2.4, y, NORTH), post, CORRIDOR, t, i + 1)
        command = decide_for(
            tracker, scan, Odometry(i + 1, "r1", t, 2.4, y, NORTH, 1.0, 0.0), JACKAL_BOX
        )
        assert command is None and tracker.movers() == [], t
        y += 1.0 * PERIOD


def test_a_mover_inside_the_margin_meets_the_robot_only_as_the_gap_closes() -> None:
    # 0.55 m to the left of a robot driving on at 1.9 m/s: inside the margins already (a box
    # beside the way told moving for two scans in static BARN: dodge yielded at 0.5 m/s for
    # it, and the run went another way). Leaving, or passing alongside: no threat; coming
    # at the robot: one at once; touching it: contact now
    def threat(vx: float, vy: float, y: float = 0.55) -> float:
        mover = threats.Mover(1, 0.05, y, vx, vy, 0.21)
        return threats.expected(1.9, 0.0, JACKAL_BOX, [mover]).ttc

    assert math.isinf(threat(0.0, 0.22)), "leaving to the left"
    assert math.isinf(threat(1.9, 0.0)), "alongside, as fast"
    assert threat(0.0, -0.3) <= 0.2, "coming at it"
    assert threat(0.0, 0.3, y=0.4) == 0.0, "touching it"


@pytest.mark.parametrize(("told_for", "kept"), [(0.04, False), (0.4, True)])
def test_only_a_track_told_moving_for_a_while_is_kept_moving(told_for: float, kept: bool) -> None:
    # a body's centres on a line at 0.5 m/s, its points off their old surface until
    # ``told_for`` after it was first told moving, then back on it (a box's faces turning
    # into view tell a moment's motion; a mover turning back returns over its surface)
    track = Track(1, 0.2)
    tracker = Tracker(tracks=[track])
    first: float | None = None
    for i in range(60):
        t = i * PERIOD
        track.add(t, Cluster(0.5 * t, 2.0, 0.2, 0, 10, True))
        track.displaced = first is None or t < first + told_for
        tracker.last_t = t
        tracker._told(t)
        if first is None and track.told:
            first = t
        if first is not None and t >= first + told_for:
            assert not track.told
            within = t - track.moved_t <= STICKY_S
            assert track.moving == (kept and within), (t, track.moved_t, track.told_from)
    assert first is not None
