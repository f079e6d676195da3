"""``pnav demo``: the Proactive Engine on real Postgres and Zenoh, in under a minute.

This is the foundation's demo, not yet the navigation mission (that arrives with the
scenario services). It starts an embedded Postgres with the contract and a Zenoh router,
runs a scenario service whose meta rule watches the ``goal`` table, and shows:

1. a goal written with its notification wakes the engine within a millisecond or so, and the
   meta rule creates a target rule that runs once and ends;
2. a goal written *without* a notification is still picked up, by the period F fallback;
3. the engine's statistics, as the service wrote them to ``engine_stats``.
"""

from __future__ import annotations

import asyncio
import json
import time
from pathlib import Path
from typing import Any

import uvloop

from common.config import EngineSettings, ServiceConfig
from common.contract import keys
from common.engine import Rule
from common.runtime import Runtime
from common.service import ScenarioService
from common.stack import local_stack

PERIOD_S = 0.5


class NewGoals(Rule):
    """Meta scenario: detect goals not seen yet and create one target rule per goal."""

    scenario = "demo_meta"
    meta = True
    watches = (keys.GOAL,)

    def __init__(self, demo: DemoService) -> None:
        self.demo = demo

    async def data_acquisition(self) -> None:
        self.started = time.monotonic()
        async with self.demo.runtime.database.pool.acquire() as conn:
            self.goals = await conn.fetch(
                "SELECT id, x, y FROM goal WHERE id > $1 ORDER BY id", self.demo.last_goal
            )

    def activation_guards(self) -> bool:
        return bool(self.goals)

    def actions(self) -> None:
        self.demo.last_goal = self.goals[-1]["id"]

    def rule_generation(self) -> list[Rule]:
        targets: list[Rule] = [
            ReportGoal(self.demo, g["id"], g["x"], g["y"], self.started) for g in self.goals
        ]
        return [*targets, self.clone()] if self.activated else [self.clone()]


class ReportGoal(Rule):
    """Target scenario: report one goal, then end (it does not clone itself)."""

    scenario = "demo_target"

    def __init__(self, demo: DemoService, goal_id: int, x: float, y: float, seen: float) -> None:
        self.demo, self.goal_id, self.x, self.y, self.seen = demo, goal_id, x, y, seen

    def actions(self) -> None:
        self.demo.seen[self.goal_id] = self.seen
        print(f"    target rule ran for goal {self.goal_id} at ({self.x:.1f}, {self.y:.1f})")


class DemoService(ScenarioService):
    service = "demo"

    def __init__(self, runtime: Runtime) -> None:
        super().__init__(runtime)
        self.last_goal = 0
        self.seen: dict[int, float] = {}

    def seed(self) -> None:
        self.engine.add_meta(lambda: NewGoals(self))


async def wait_for(service: DemoService, goal_id: int, limit_s: float = 10.0) -> float:
    deadline = time.monotonic() + limit_s
    while goal_id not in service.seen:
        if time.monotonic() > deadline:
            raise TimeoutError(f"goal {goal_id} was never picked up")
        await asyncio.sleep(0.0005)
    return service.seen[goal_id]


async def demo(json_path: str | None) -> dict[str, Any]:
    summary: dict[str, Any] = {"demo": "engine", "wake_ms": [], "fallback_ms": None}
    print("proactive-nav engine demo (the navigation mission arrives with the scenario services)")
    started = time.monotonic()
    async with local_stack() as stack:
        print(f"  Postgres + contract + Zenoh router up in {time.monotonic() - started:.2f} s")
        config = ServiceConfig(
            service="demo",
            database_url=stack.database_url,
            zenoh=stack.zenoh,
            engine=EngineSettings(period_s=PERIOD_S),
            stats_period_s=0.5,
            instance="demo-1",
        )
        service_rt = await Runtime.open(config)
        writer = await Runtime.open(
            ServiceConfig(service="cli", database_url=stack.database_url, zenoh=stack.zenoh)
        )
        service = DemoService(service_rt)
        stop = asyncio.Event()
        task = asyncio.create_task(service.run(stop))
        try:
            await writer.database.write(
                keys.ROBOT,
                "r1",
                "INSERT INTO robot (robot_id) VALUES ('r1') ON CONFLICT DO NOTHING",
            )
            await asyncio.sleep(0.5)
            insert = (
                "INSERT INTO goal (robot_id, x, y, status) "
                "VALUES ('r1', $1, $2, 'reached') RETURNING id"
            )
            f_ms = PERIOD_S * 1000
            print(f"  1. goals written with a notification (engine period F = {f_ms:.0f} ms):")
            for x, y in ((1.0, 2.0), (3.0, -1.0), (0.5, 0.5)):
                await asyncio.sleep(0.2)
                written = time.monotonic()
                goal_id = await writer.database.write(keys.GOAL, "r1", insert, x, y)
                latency_ms = (await wait_for(service, goal_id) - written) * 1000
                summary["wake_ms"].append(round(latency_ms, 3))
                print(f"    woken {latency_ms:.2f} ms after the write (F: up to {f_ms:.0f} ms)")
            print("  2. a goal written with NO notification (a lost hint):")
            async with writer.database.pool.acquire() as conn:
                written = time.monotonic()
                goal_id = await conn.fetchval(insert, 9.0, 9.0)
            latency_ms = (await wait_for(service, goal_id) - written) * 1000
            summary["fallback_ms"] = round(latency_ms, 1)
            print(f"    picked up {latency_ms:.0f} ms later by the period F fallback")
        finally:
            stop.set()
            await task
            await service_rt.close()
        print("  3. engine_stats, as the service wrote it:")
        async with writer.database.pool.acquire() as conn:
            rows = await conn.fetch(
                "SELECT rule_type, scenario, executed, activated, acted, errors, "
                "total_time_s * 1e6 / greatest(executed, 1) AS mean_us "
                "FROM engine_stats WHERE service = 'demo' ORDER BY rule_type"
            )
        print(
            f"    {'rule':<12}{'scenario':<14}{'executed':>9}{'activated':>10}"
            f"{'acted':>7}{'errors':>7}{'mean us':>9}"
        )
        for r in rows:
            print(
                f"    {r['rule_type']:<12}{r['scenario']:<14}{r['executed']:>9}{r['activated']:>10}"
                f"{r['acted']:>7}{r['errors']:>7}{r['mean_us']:>9.0f}"
            )
        summary["engine_stats"] = [dict(r) for r in rows]
        await writer.close()
    summary["wall_s"] = round(time.monotonic() - started, 2)
    print(f"  done in {summary['wall_s']} s")
    return summary


def run(json_path: str | None = None) -> int:
    summary = uvloop.run(demo(json_path))
    if json_path:
        Path(json_path).write_text(json.dumps(summary, indent=2, default=str) + "\n")
    return 0
