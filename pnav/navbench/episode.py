"""One navigation run of the whole stack: a world, a strategy, a goal; what the robot did.

The stack runs as ``pnav up`` runs it (embedded Postgres, router, sim, bridge, the four
scenario services), with the sim at ``--rate max`` paced by the stack (``--max-lag``,
docs/SIM.md): the services always decide within ``max_lag`` sim seconds, so a loaded machine
makes a run slower in wall time, not different in sim time.

The episode watches what a user would: odometry (the driven trajectory), collision events
and the commands reaching the sim. Sim time counts from the first decided command that
moves the robot, because before it the robot stands still while the services start; the
episode ends at the first of reaching the goal (within ``SUCCESS_RADIUS_M``), a collision,
or the time limit.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from common import bus
from common.config import ServiceConfig
from common.contract import keys
from common.runtime import Runtime
from pnav import commands
from pnav.launcher import StackOptions, launched

SUCCESS_RADIUS_M = 0.3  # BARN: the goal counts as reached within this distance
MAX_LAG_S = 0.1  # the decision service re-issues every 0.1 s sim: never staler than that
WALL_FACTOR = 4.0  # a run may take this many times its time limit in wall time, plus START


@dataclass(frozen=True)
class Combo:
    """A strategy/planner combination: a shipped strategy's controller scenarios with a
    planner scenario; ``code`` is the strategy row the benchmark uses for it."""

    strategy: str
    planner: str

    @property
    def code(self) -> str:
        return f"NAV_{self.strategy}_{self.planner.upper()}"

    @property
    def label(self) -> str:
        return f"{self.strategy}/{self.planner}"


@dataclass(frozen=True)
class Episode:
    world: Path
    goal: tuple[float, float]
    combo: Combo
    time_limit_s: float
    seed: int = 0
    robot: str = "r1"


@dataclass
class Outcome:
    """What happened; times are sim seconds from the first decided command."""

    end: str  # "goal", "collision", "timeout", "stalled" (wall-time cap: the stack hung)
    time_s: float
    trajectory: list[tuple[float, float, float]] = field(default_factory=list)  # (t, x, y)
    collisions: list[tuple[float, float, float, str]] = field(default_factory=list)
    final_distance_m: float = math.inf
    wall_s: float = 0.0


class Watcher:
    """Odometry, collisions and commands of one robot, from Zenoh's threads."""

    def __init__(self, robot: str, goal: tuple[float, float]) -> None:
        self.robot, self.goal = robot, goal
        self.lock = threading.Lock()
        self.odom: list[tuple[float, float, float]] = []
        self.collisions: list[tuple[float, float, float, str]] = []
        self.first_decision: float | None = None

    def on_odom(self, _key: str, payload: bytes) -> None:
        m = bus.unpack(payload)
        with self.lock:
            self.odom.append((float(m["stamp"]), float(m["x"]), float(m["y"])))

    def on_collision(self, _key: str, payload: bytes) -> None:
        m = bus.unpack(payload)
        with self.lock:
            self.collisions.append((float(m["stamp"]), m["x"], m["y"], str(m["other"])))

    def on_cmd_vel(self, _key: str, payload: bytes) -> None:
        m = bus.unpack(payload)
        decided = m.get("decided_stamp")
        # the first command that moves the robot: a stop issued before the goal is not a start
        moving = m.get("linear", 0.0) != 0.0 or m.get("angular", 0.0) != 0.0
        if self.first_decision is None and decided is not None and moving:
            self.first_decision = float(decided)

    def verdict(self, limit_s: float) -> tuple[str, float] | None:
        """(end, sim time from the first decision) once the run is over, else None."""
        with self.lock:
            t0 = self.first_decision
            if t0 is None or not self.odom:
                return None
            hits = [c for c in self.collisions if c[0] >= t0]
            if hits:
                return "collision", hits[0][0] - t0
            for t, x, y in reversed(self.odom[-10:]):
                if t >= t0 and math.dist((x, y), self.goal) <= SUCCESS_RADIUS_M:
                    return "goal", t - t0
            if self.odom[-1][0] - t0 > limit_s:
                return "timeout", limit_s
        return None


async def ensure_combo(rt: Runtime, combo: Combo) -> None:
    """The combo's strategy row: the shipped strategy with the combo's planner scenario."""
    await rt.database.write(
        keys.STRATEGY,
        None,
        "INSERT INTO strategy (code, planner_scenario, controller_scenarios, params, description) "
        "SELECT $1, $2, controller_scenarios, params, 'pnav bench nav: ' || code || ' with ' || $2"
        " FROM strategy WHERE code = $3 ON CONFLICT (code) DO NOTHING",
        combo.code,
        combo.planner,
        combo.strategy,
    )


async def run_episode(episode: Episode, log_dir: Path | None = None) -> Outcome:
    options = StackOptions(
        world=str(episode.world),
        rate="max",
        zenoh_port=None,
        log_dir=log_dir or Path(tempfile.mkdtemp(prefix="pnav-nav-")),
        extra_env={"PNAV_SIM_MAX_LAG": str(MAX_LAG_S), "PNAV_SIM_SEED": str(episode.seed)},
    )
    started = time.monotonic()
    watcher = Watcher(episode.robot, episode.goal)
    async with launched(options) as stack:
        config = ServiceConfig(
            service="navbench", database_url=stack.local.database_url, zenoh=stack.local.zenoh
        )
        rt = await Runtime.open(config)
        subs: list[Any] = []
        try:
            for topic, handler in (
                (keys.ODOM, watcher.on_odom),
                (keys.COLLISION, watcher.on_collision),
                (keys.CMD_VEL, watcher.on_cmd_vel),
            ):
                key = keys.robot_key(episode.robot, topic)
                subs.append(bus.subscribe_threaded(rt.zenoh, key, handler))
            if episode.robot not in await commands.robot_ids(rt, wait_s=30.0):
                raise RuntimeError(f"robot {episode.robot} never registered from {episode.world}")
            await ensure_combo(rt, episode.combo)
            verdict, reason = await commands.send_user_command(
                rt, episode.robot, "SET_STRATEGY", episode.combo.code, wait_s=15.0
            )
            if verdict != "accepted":
                raise RuntimeError(f"strategy {episode.combo.code} {verdict}: {reason}")
            await commands.set_goal(rt, episode.robot, *episode.goal)
            wall_cap = started + 30.0 + WALL_FACTOR * episode.time_limit_s
            while (result := watcher.verdict(episode.time_limit_s)) is None:
                if time.monotonic() > wall_cap:
                    t0 = watcher.first_decision
                    last = watcher.odom[-1][0] if watcher.odom else 0.0
                    result = ("stalled", last - t0 if t0 is not None else 0.0)
                    break
                await asyncio.sleep(0.02)
        finally:
            for sub in subs:
                with contextlib.suppress(Exception):
                    sub.undeclare()
            await rt.close()
    end, time_s = result
    t0 = watcher.first_decision or 0.0
    with watcher.lock:
        trajectory = [(t - t0, x, y) for t, x, y in watcher.odom if t0 <= t <= t0 + time_s]
        collisions = [(t - t0, x, y, o) for t, x, y, o in watcher.collisions if t >= t0]
    final = math.dist(trajectory[-1][1:], episode.goal) if trajectory else math.inf
    return Outcome(end, time_s, trajectory, collisions, final, time.monotonic() - started)
