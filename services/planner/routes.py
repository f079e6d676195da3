"""Routes: where a robot is going (``Target``) and the cached A* route that takes it there.

:class:`Router` keeps one route per robot and plans again only when it must: the target,
the map or the keepout zones that apply to the robot changed (a zone's cells are obstacles
on the planning grid: keepout.py), the robot strayed, a straight fallback is due a retry,
or a newly seen unmapped obstacle (obstacles.py) is close to the route ahead. Its own gates
(replanning, retries) count on the store's clock: wall time in a service, sim time in
lockstep and in the monolith; the obstacle checks count sim time.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

import services.planner.fit as fit
import services.planner.reachability as reachability
from common import log
from common.contract import records
from common.contract.limits import DEFAULT_YAW_TOLERANCE_RAD
from services.planner.grid import PlanGrid
from services.planner.keepout import names as keepout_names
from services.planner.keepout import zones_key
from services.planner.obstacles import Points, Seen, buckets, known, recent
from services.planner.path import path_length, plan_path, with_obstacles
from services.planner.tracking import Progress, Route, follow
from services.planner.world_model import RobotState, Station, World, inflation_m

logger = logging.getLogger("pnav.planner")

STRAY_M = 0.4  # farther than this from the route: plan again from where the robot is
REPLAN_MIN_S = 0.5  # ...but not more often than this (store clock), so avoidance cannot thrash
RETRY_PLAN_S = 2.0  # how long a straight-line fallback stands before A* is tried again
CHARGER_MARGIN_M = 0.1  # a charger is reached this far inside its radius
BLOCKED_M = 0.3  # a new obstacle closer than this to the route ahead: plan again...
BLOCKED_RANGE_M = 2.0  # ...if it is within this of the robot
REPLAN_BLOCKED_S = 0.5  # ...at most this often (sim s)


@dataclass(frozen=True)
class Target:
    """Where the robot is going: the active goal, or the chosen charging station."""

    kind: str  # "goal" or "charger"
    ref: str  # the goal id or the station id
    x: float
    y: float
    reach_m: float  # closer than this: reached
    hold_m: float  # once reached, stay stopped while closer than this
    goal_id: int | None = None
    # the heading to turn to once there (rad, map frame; None: any) and within what
    yaw: float | None = None
    yaw_tol: float = DEFAULT_YAW_TOLERANCE_RAD
    # a route's waypoint: its seq (None: the goal's own pose, or a charger)
    seq: int | None = None
    halts: bool = True  # the robot stops here (False: a waypoint passed through)
    # straight-line metres beyond this target to the next pose the robot stops at: the
    # speed slows only toward that one
    beyond_m: float = 0.0

    @property
    def key(self) -> tuple[Any, ...]:
        return (self.kind, self.ref, self.x, self.y)

    @property
    def label(self) -> str:
        if self.seq is not None:
            return f"waypoint {self.seq} of goal {self.goal_id}"
        return f"{self.kind} {self.ref}"

    @property
    def poses(self) -> bool:
        """Whether arriving asks more than the position: a heading, or a halt on a route
        (the robot stands still before the pose counts as reached)."""
        return self.yaw is not None or (self.seq is not None and self.halts)

    def inputs(self) -> dict[str, Any]:
        if self.kind != "goal":
            return {"charger": self.ref}
        return (
            {"goal": self.goal_id}
            if self.seq is None
            else {"goal": self.goal_id, "waypoint": self.seq}
        )

    @classmethod
    def of_goal(cls, goal: records.Goal) -> Target:
        yaw_tol = goal.yaw_tolerance_rad or DEFAULT_YAW_TOLERANCE_RAD
        return cls(
            "goal", str(goal.id), goal.x, goal.y, goal.tolerance_m, 0.0, goal.id, goal.yaw, yaw_tol
        )

    @classmethod
    def of_station(cls, station: Station) -> Target:
        reach = max(station.radius_m - CHARGER_MARGIN_M, station.radius_m / 2)
        return cls("charger", station.station_id, station.x, station.y, reach, station.radius_m)


def check_due(route: Route, seen: Seen | None, now: float | None) -> bool:
    """Whether ``seen`` is a scan not yet checked against ``route`` that may be checked now:
    at most one replan for obstacles every REPLAN_BLOCKED_S, and each scan once."""
    if seen is None or seen.scan_id == route.checked_scan or now is None:
        return False
    return not now - route.made_stamp < REPLAN_BLOCKED_S


def blocks(route: Route, points: Points, x: float, y: float) -> bool:
    """Whether ``points`` hold an obstacle the route was not planned around within BLOCKED_M
    of the route ahead and BLOCKED_RANGE_M of the robot at (x, y)."""
    if not len(points):
        return False
    near = np.hypot(points[:, 0] - x, points[:, 1] - y) <= BLOCKED_RANGE_M
    points = points[near]
    if not len(points):
        return False
    close = points[route.clearance_ahead(x, y, points) < BLOCKED_M]
    return any(not known(route.avoided, px, py) for px, py in close)


class Router:
    def __init__(self, world: World, clock: Callable[[], float]) -> None:
        self.world = world
        self.clock = clock

    def route_for(
        self, state: RobotState, x: float, y: float, target: Target, now: float | None = None
    ) -> Progress:
        """Progress along the robot's cached route to ``target``; plans (again) when the
        target or the map changed, the robot strayed, a straight fallback is due a retry, or
        a newly seen unmapped obstacle is close to the route ahead. ``now``: sim time."""
        data = self.world.map_for(state.info)
        keepouts = self.world.keepouts(state.info)
        # a route is made on the map and the keepout zones: a zone added, moved or removed
        # makes it stale, as a new map does, so the robot plans again at once
        version = data.version if data else None
        if data is not None and keepouts:
            version = f"{data.version}#{zones_key(keepouts)}"
        route = state.route
        clock = self.clock()
        if route is not None and route.target_key == target.key and route.map_version == version:
            progress = follow(route, x, y)
            age = clock - route.made_at
            retry = data is not None and not route.planned and age > RETRY_PLAN_S
            blocked = False
            if data is not None and check_due(route, state.seen, now):
                assert state.seen is not None  # check_due holds
                route.checked_scan = state.seen.scan_id
                blocked = blocks(route, recent(state.seen, now), x, y)
            if (
                not retry
                and not blocked
                and (progress.deviation_m <= STRAY_M or age < REPLAN_MIN_S)
            ):
                return progress
        obstacles = recent(state.seen, now)
        unreachable = self.spot_problem(state, target)
        points = None
        if unreachable is None:
            points = self.plan(state, (x, y), (target.x, target.y), target.label, obstacles)
        if points is None and len(obstacles) and unreachable is None:
            # They close every way (or cover the goal): the map alone, and these obstacles
            # count as considered, so the next scans do not call for the same failed plan.
            points = self.plan(state, (x, y), (target.x, target.y), target.label)
        planned = points is not None
        if not planned and data is not None and unreachable is None:
            unreachable = self.cut_off(state, x, y, target)
            self.world.warn_once(
                f"nopath-{state.info.robot_id}-{target.key}",
                "no path on the map; heading straight (retried every few seconds)",
                robot=state.info.robot_id,
                target=target.label,
            )
        state.route = Route.of(
            target.key, version, points or [(x, y), (target.x, target.y)], planned
        )
        state.route.unreachable = unreachable
        state.route.made_at = self.clock()
        state.route.made_stamp = now if now is not None else 0.0
        state.route.avoided = buckets(obstacles)
        state.route.checked_scan = state.seen.scan_id if state.seen is not None else None
        return follow(state.route, x, y)

    def spot_problem(self, state: RobotState, target: Target) -> str | None:
        """Why the map proves a goal's spot unreachable (outside the map, in an obstacle);
        judged once per goal and map version. Only goals: a charger is the world's own."""
        data = self.world.map_for(state.info)
        if target.kind != "goal" or data is None:
            return None
        footprint = state.info.footprint
        keepouts = self.world.keepouts(state.info)
        key = (target.key, data.version, footprint, zones_key(keepouts))
        if state.spot is None or state.spot[0] != key:
            # the least room the robot needs, at the heading it arrives with
            inflation = inflation_m(footprint.inscribed_m)
            why = reachability.spot_problem(
                data, inflation, target.x, target.y, target.reach_m, keepouts
            )
            state.spot = (key, why)
        return state.spot[1]

    def cut_off(self, state: RobotState, x: float, y: float, target: Target) -> str | None:
        """Why the map proves no way leads from (x, y) to a goal (None: it may, or nothing
        is proved), once A* on the map alone found none."""
        data = self.world.map_for(state.info)
        if target.kind != "goal" or data is None:
            return None
        keepouts = self.world.keepouts(state.info)
        grid = data.grid(state.info.footprint.inscribed_m, keepouts)
        if not reachability.cut_off(grid, (x, y), (target.x, target.y), target.reach_m):
            return None
        if keepouts:
            alone = data.grid(state.info.footprint.inscribed_m)
            if not reachability.cut_off(alone, (x, y), (target.x, target.y), target.reach_m):
                return (
                    f"no path on the map from ({x:.2f}, {y:.2f}) to the goal outside keepout "
                    f"zone {keepout_names(keepouts)}"
                )
        return f"no path on the map from ({x:.2f}, {y:.2f}) to the goal"

    def plan(
        self,
        state: RobotState,
        start: tuple[float, float],
        goal: tuple[float, float],
        what: str,
        obstacles: Points | None = None,
    ) -> list[tuple[float, float]] | None:
        """A* on the robot's map, around ``obstacles`` too if given (None: no map, or no path
        on it); for a footprint polygon, a path it fits along (fit.py)."""
        data = self.world.map_for(state.info)
        if data is None:
            return None
        started = time.perf_counter()
        footprint = state.info.footprint
        # inflated by the inscribed radius: the heading is known along a path, and the
        # polygon is checked along it below (for a disc, both radii are its radius)
        keepouts = self.world.keepouts(state.info)
        grid = data.grid(footprint.inscribed_m, keepouts)
        if obstacles is not None and len(obstacles):
            grid = with_obstacles(grid, obstacles)
        points = plan_path(grid, start, goal)
        fitting = "disc"
        if points and not footprint.is_disc:

            def wide() -> PlanGrid:
                g = data.grid(footprint.circumscribed_m, keepouts)
                return with_obstacles(g, obstacles) if obstacles is not None else g

            points, fitting = fit.fitted(footprint, points, data, grid, wide, plan_path, obstacles)
        elapsed_ms = (time.perf_counter() - started) * 1000
        log.event(
            logger,
            logging.DEBUG,
            "path planned" if points else "no path",
            robot=state.info.robot_id,
            target=what,
            waypoints=len(points) - 1 if points else 0,
            length_m=round(path_length(points), 2) if points else None,
            unmapped=len(obstacles) if obstacles is not None else 0,
            footprint=fitting,
            ms=round(elapsed_ms, 1),
        )
        return points

    def distance(self, state: RobotState, a: tuple[float, float], b: tuple[float, float]) -> float:
        """Path length from a to b on the robot's map; straight line without one."""
        points = self.plan(state, a, b, "distance")
        return path_length(points) if points else math.hypot(b[0] - a[0], b[1] - a[1])
