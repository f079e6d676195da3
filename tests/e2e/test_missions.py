"""The whole stack, end to end: sim, bridge and the four scenario services as processes.

Each test launches the stack as ``pnav up`` does (embedded Postgres, a router on a free
port), at an accelerated sim rate, and follows the mission from the contract tables.
"""

from __future__ import annotations

import os
import signal

import pytest

from common.config import ServiceConfig
from common.runtime import Runtime
from pnav._testing import eventually
from pnav.cli import stack_commands
from pnav.run import demo
from pnav.run.launcher import RunningStack, launched
from pnav.run.mission import MissionLog, MissionMonitor
from pnav.run.stack_options import StackOptions

pytestmark = pytest.mark.timeout(240)

RATE = "5"
ROBOT = "r1"
MISSIONS = {
    "open_room": (4.0, 4.0),
    "cluttered_room": (4.8, 5.6),
    "warehouse": (8.8, 6.6),
}


async def stack_monitor(stack: RunningStack) -> tuple[Runtime, MissionMonitor]:
    rt = await Runtime.open(
        ServiceConfig(service="e2e", database_url=stack.local.database_url, zenoh=stack.local.zenoh)
    )
    return rt, MissionMonitor(rt.database.pool, ROBOT)


@pytest.fixture
def options() -> StackOptions:
    return StackOptions(rate=RATE, robots=1, zenoh_port=None)


def reached(goal_id: int):  # type: ignore[no-untyped-def]
    return lambda log: log.goals.get(goal_id) == "reached"


def describe(log: MissionLog, stack: RunningStack) -> str:
    tails = []
    for name in stack.supervisor.children:
        path = stack.log_dir / f"{name}.log"
        if path.exists():
            lines = path.read_text().splitlines()[-5:]
            tails.append(f"--- {name}\n" + "\n".join(lines))
    return f"{log.as_dict()}\n" + "\n".join(tails)


@pytest.mark.parametrize("world", sorted(MISSIONS))
async def test_a_mission_succeeds_in_every_shipped_world_without_collision(
    world: str, options: StackOptions
) -> None:
    options.world = world
    async with launched(options) as stack:
        rt, monitor = await stack_monitor(stack)
        try:
            (robot,) = await stack_commands.pick_robots(rt, None, one=True)
            goal = await stack_commands.set_goal(rt, robot, *MISSIONS[world])
            ok = await monitor.wait_for(reached(goal), limit_s=150)
            log = await monitor.poll()
            assert ok, f"goal not reached in {world}:\n{describe(log, stack)}"
            assert log.collisions == 0, describe(log, stack)
        finally:
            await rt.close()


async def test_the_demo_mission_detours_to_charge_switches_strategy_and_changes_goal() -> None:
    summary = await demo.demo(RATE)
    assert summary["outcome"] == "success", summary
    # the user's steps at their sim times, however loaded the machine (the sim is held)
    user = [e["sim_s"] for e in summary["events"] if e["event"].startswith("user:")]
    assert user == list(demo.USER_STEPS_S), summary["events"]
    codes = [code for _, code in summary["strategy_timeline"]]
    # GOTO_AVOID -> GOTO_DIRECT -> GOTO_AVOID (user) -> CHARGE -> GOTO_AVOID (system)
    assert codes == ["GOTO_AVOID", "GOTO_DIRECT", "GOTO_AVOID", "CHARGE", "GOTO_AVOID"]
    assert summary["collisions"] == 0
    assert summary["max_battery_pct"] > demo.START_BATTERY_PCT  # it really charged


async def test_the_mission_completes_when_each_scenario_service_is_killed_in_turn(
    options: StackOptions,
) -> None:
    async with launched(options) as stack:
        rt, monitor = await stack_monitor(stack)
        try:
            (robot,) = await stack_commands.pick_robots(rt, None, one=True)
            goal = await stack_commands.set_goal(rt, robot, *MISSIONS["warehouse"])
            for name in ("strategy", "planner", "controller", "decision"):
                start = (await monitor.poll()).now.stamp
                assert await monitor.wait_for(lambda log, s=start: log.now.stamp > s + 3, 60)
                # composed, the host: its co-hosted services restart with it (so the host
                # killed for the previous service may still be restarting)
                process = stack.process_of(name)
                pid = await eventually(
                    lambda p=process: stack.supervisor.pids().get(p),
                    within=60,
                    what=f"{process} running",
                )
                os.kill(pid, signal.SIGKILL)
            ok = await monitor.wait_for(reached(goal), limit_s=150)
            log = await monitor.poll()
            assert ok, describe(log, stack)
            assert log.collisions == 0, describe(log, stack)
            restarts = {n: c.restarts for n, c in stack.supervisor.children.items()}
            scenario = ("strategy", "planner", "controller", "decision")
            assert all(restarts[stack.process_of(n)] >= 1 for n in scenario)
        finally:
            await rt.close()
