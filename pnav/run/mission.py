"""Follow a robot's mission from the contract tables: pose, distance, strategy, decisions.

Used by ``pnav demo``, ``pnav bench faults`` and the end-to-end tests. It only reads tables,
as any dashboard could: it polls often enough (every ``poll_s`` of wall time) that the sensor
retention never drops an odometry row before it is counted.

A goal that ends without being reached, ``failed`` (the planner proved it unreachable) or
``cancelled`` (by people), is an end of the mission: :meth:`MissionMonitor.wait_for` told to
follow that goal raises :class:`GoalEnded` with the goal's reason at once, instead of waiting
out its time limit for something that will not happen.
"""

from __future__ import annotations

import asyncio
import math
import time
from dataclasses import asdict, dataclass, field
from typing import Any

import asyncpg

# a goal in one of these states will never be reached: the mission is over
GOAL_ENDS = ("failed", "cancelled")


class GoalEnded(Exception):
    """The goal a mission waits on ended without being reached (``status``, ``reason``)."""

    def __init__(self, goal_id: int, status: str, reason: str | None) -> None:
        self.goal_id, self.status, self.reason = goal_id, status, reason
        super().__init__(f"goal {goal_id} {status}: {reason or 'no reason given'}")


@dataclass
class Snapshot:
    stamp: float = 0.0
    x: float = math.nan
    y: float = math.nan
    yaw: float = math.nan
    battery_pct: float = math.nan
    charging: bool = False
    strategy: str = "-"
    goal_id: int | None = None
    goal: tuple[float, float] | None = None
    decision: str = ""


@dataclass
class MissionLog:
    robot: str
    distance_m: float = 0.0
    collisions: int = 0
    decisions: int = 0
    strategy_timeline: list[tuple[float, str]] = field(default_factory=list)
    goals: dict[int, str] = field(default_factory=dict)
    goal_reasons: dict[int, str] = field(default_factory=dict)  # goals that have a reason
    min_battery_pct: float = math.inf
    max_battery_pct: float = -math.inf
    now: Snapshot = field(default_factory=Snapshot)
    _odom_id: int = 0
    _last_xy: tuple[float, float] | None = None
    _first_decision: int | None = None

    def ended(self, goal_id: int) -> GoalEnded | None:
        """Why goal ``goal_id`` will never be reached (failed, cancelled), or None."""
        status = self.goals.get(goal_id)
        if status not in GOAL_ENDS:
            return None
        return GoalEnded(goal_id, status, self.goal_reasons.get(goal_id))

    def as_dict(self) -> dict[str, Any]:
        out = {k: v for k, v in asdict(self).items() if not k.startswith("_")}
        out["now"] = asdict(self.now)
        return out


class MissionMonitor:
    def __init__(self, pool: asyncpg.Pool, robot: str) -> None:
        self.pool = pool
        self.log = MissionLog(robot)

    async def poll(self) -> MissionLog:
        log, robot = self.log, self.log.robot
        async with self.pool.acquire() as conn:
            odoms = await conn.fetch(
                "SELECT id, stamp, x, y, yaw FROM odometry WHERE robot_id = $1 AND id > $2 "
                "ORDER BY id",
                robot,
                log._odom_id,
            )
            strategy = await conn.fetchval(
                "SELECT strategy_code FROM active_strategy WHERE robot_id = $1", robot
            )
            goals = await conn.fetch(
                "SELECT id, status, reason, x, y FROM goal WHERE robot_id = $1 ORDER BY id", robot
            )
            battery = await conn.fetchrow(
                "SELECT percentage, charging FROM battery WHERE robot_id = $1 "
                "ORDER BY id DESC LIMIT 1",
                robot,
            )
            decision = await conn.fetchrow(
                "SELECT id, source, reason FROM command2robot WHERE robot_id = $1 "
                "ORDER BY id DESC LIMIT 1",
                robot,
            )
            log.collisions = await conn.fetchval(
                "SELECT count(*) FROM collision_event WHERE robot_id = $1", robot
            )
            log.decisions = await conn.fetchval(
                "SELECT count(*) FROM command2robot WHERE robot_id = $1", robot
            )
        for row in odoms:
            if log._last_xy is not None:
                log.distance_m += math.hypot(row["x"] - log._last_xy[0], row["y"] - log._last_xy[1])
            log._last_xy = (row["x"], row["y"])
            log._odom_id = row["id"]
            log.now.stamp, log.now.x, log.now.y, log.now.yaw = (
                row["stamp"],
                row["x"],
                row["y"],
                row["yaw"],
            )
        if strategy and (not log.strategy_timeline or log.strategy_timeline[-1][1] != strategy):
            log.strategy_timeline.append((round(log.now.stamp, 2), strategy))
        log.now.strategy = strategy or "-"
        log.goals = {g["id"]: g["status"] for g in goals}
        log.goal_reasons = {g["id"]: g["reason"] for g in goals if g["reason"]}
        active = [g for g in goals if g["status"] == "active"]
        log.now.goal_id = active[0]["id"] if active else None
        log.now.goal = (active[0]["x"], active[0]["y"]) if active else None
        if battery is not None:
            log.now.battery_pct, log.now.charging = battery["percentage"], battery["charging"]
            log.min_battery_pct = min(log.min_battery_pct, battery["percentage"])
            log.max_battery_pct = max(log.max_battery_pct, battery["percentage"])
        if decision is not None:
            log.now.decision = f"{decision['source'] or 'stop'}: {decision['reason']}"
        return log

    async def wait_for(
        self,
        predicate: Any,
        limit_s: float,
        poll_s: float = 0.1,
        on_poll: Any = None,
        *,
        goal: int | None = None,
    ) -> bool:
        """Poll until ``predicate(log)`` holds; False after ``limit_s`` of wall time. With
        ``goal``, raise :class:`GoalEnded` as soon as that goal fails or is cancelled."""
        deadline = time.monotonic() + limit_s
        while time.monotonic() < deadline:
            log = await self.poll()
            if on_poll is not None:
                on_poll(log)
            if predicate(log):
                return True
            if goal is not None and (end := log.ended(goal)) is not None:
                raise end
            await asyncio.sleep(poll_s)
        return False
