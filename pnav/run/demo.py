"""``pnav demo``: the thesis' mission, end to end, in well under two minutes.

On the warehouse world, at an accelerated sim rate, one robot:

1. gets a goal in the first aisle and drives toward it (GOTO_AVOID);
2. has its strategy switched at run time to GOTO_DIRECT, then back to GOTO_AVOID;
3. has its goal changed in motion to the far corner, past a pallet that is not on the map;
4. finds its battery (started low) will not cover the new path: the planner recommends
   CMD_BATTSAVE, the decision service passes it to the strategy service, CHARGE takes over;
5. drives to the nearest charger, charges, and resumes GOTO_AVOID by itself (CMD_RESUME);
6. reaches the goal.

Nobody intervenes after step 3. The demo then prints a mission summary (and writes it as
JSON with ``--json``) and exits 0 on success, 1 with the reason otherwise.

The user's steps are taken at fixed sim times (:data:`USER_STEPS_S`), not after some wall
time: the sim is held (``--held``, services/sim/hold.py) at sim time 0 until the stack is up
and the first goal given, then let run to each next step's time and held there while the
step is taken. A driver on wall time against a sim at 5x was another mission on a loaded
machine: it once gave the first goal at 33 s of sim time, the battery drained meanwhile,
and CHARGE came before the strategy switch. Held, a loaded machine makes the mission take
longer in wall time, never another mission.
"""

from __future__ import annotations

import asyncio
import json
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import uvloop

from common.bus import pack
from common.config import ServiceConfig
from common.contract import keys
from common.robotmodel import DEFAULT_MODEL, load_model
from common.runtime import Runtime
from pnav.cli import stack_commands
from pnav.run.launcher import launched
from pnav.run.mission import GoalEnded, MissionLog, MissionMonitor
from pnav.run.stack_options import DashboardOptions, StackOptions

ROBOT = "r1"
WORLD = "warehouse"
RATE = "5"
# 0.45 % of the Burger's 19.98 Wh = 0.09 Wh: enough for the first goal, not for the far one
# (another model starts with the same energy: the sim's load model is the same for all)
START_BATTERY_PCT = 0.45
GOAL_NEAR = (3.7, 2.5)
GOAL_FAR = (8.8, 6.6)
WALL_LIMIT_S = 105.0
# the sim times of the user's steps: the first goal, GOTO_DIRECT, GOTO_AVOID, the goal change
USER_STEPS_S = (0.0, 3.0, 6.0, 7.0)
# the services the stack must have up before the sim may run (the sim's own is not waited on)
STACK_SERVICES = ("bridge", "strategy", "planner", "controller", "decision")
# a run message put before the sim's subscription reached the router is lost: say it again
RUN_RESEND_S = 0.5


class Demo:
    def __init__(self, monitor: MissionMonitor, rt: Runtime) -> None:
        self.monitor, self.rt = monitor, rt
        self.events: list[dict[str, Any]] = []
        self.started = time.monotonic()
        self.tty = sys.stdout.isatty()
        self._last_print = 0.0
        self.goal: int | None = None  # the goal in force: its failure ends the demo

    def event(self, text: str) -> None:
        now = self.rt.clock.now()  # the sim's clock: where the sim holds, exactly
        self.events.append({"sim_s": round(now, 2), "event": text})
        print(
            f"\r\x1b[K[sim {now:6.1f} s] {text}" if self.tty else f"[sim {now:6.1f} s] {text}",
            flush=True,
        )

    def progress(self, log: MissionLog) -> None:
        now = time.monotonic()
        if now - self._last_print < (0.2 if self.tty else 5.0):
            return
        self._last_print = now
        n = log.now
        goal = "-" if n.goal is None else f"({n.goal[0]:.1f}, {n.goal[1]:.1f})"
        line = (
            f"  sim {n.stamp:6.1f} s  pose ({n.x:5.2f}, {n.y:5.2f})  goal {goal}  "
            f"{n.strategy:<11} battery {n.battery_pct:5.2f}%{'+' if n.charging else ' '} "
            f"| {n.decision}"
        )
        if self.tty:
            print("\r\x1b[K" + line[:150], end="", flush=True)
        else:
            print(line, flush=True)

    def remaining(self) -> float:
        return max(1.0, WALL_LIMIT_S - (time.monotonic() - self.started))

    async def until(
        self, what: str, predicate: Callable[[MissionLog], bool], within: float | None = None
    ) -> bool:
        """Wait for ``predicate``; MissionFailed past the demo's time limit. With ``within``
        (wall seconds), False if it did not hold by then."""
        limit = self.remaining() if within is None else min(within, self.remaining())
        try:
            ok = await self.monitor.wait_for(
                predicate, limit, on_poll=self.progress, goal=self.goal
            )
        except GoalEnded as end:
            raise MissionFailed(f"waiting for {what}: {end}") from None
        if not ok and (within is None or self.remaining() <= 1.0):
            raise MissionFailed(f"{what} did not happen within the demo's time limit")
        return ok

    async def stack_up(self) -> None:
        """Until every service of :data:`STACK_SERVICES` holds its liveliness token: the
        held sim is let run only once nothing is still starting."""

        def missing() -> set[str]:
            replies = self.rt.zenoh.liveliness().get(keys.alive_watch(), timeout=2.0)
            up = {str(r.ok.key_expr).split("/")[2] for r in replies if r.ok is not None}
            return set(STACK_SERVICES) - up

        while gone := await asyncio.to_thread(missing):
            if self.remaining() <= 1.0:
                raise MissionFailed(f"services not up within the demo's time limit: {gone}")
            await asyncio.sleep(0.2)

    async def run_to(self, sim_s: float | None) -> None:
        """Let the held sim run to sim time ``sim_s`` and wait until it holds there (None:
        let it run on, and wait until it moved)."""
        start = self.rt.clock.stamp or 0.0

        def arrived(_: MissionLog) -> bool:
            stamp = self.rt.clock.stamp
            if stamp is None:
                return False
            return stamp > start if sim_s is None else stamp >= sim_s - 1e-6

        what = "the sim to run on" if sim_s is None else f"the sim to reach {sim_s} s"
        while True:
            self.rt.zenoh.put(keys.SIM_RUN, pack({"until": sim_s}))
            if await self.until(what, arrived, within=RUN_RESEND_S):
                return

    async def strategy(self, code: str) -> None:
        verdict, reason = await stack_commands.send_user_command(
            self.rt, ROBOT, "SET_STRATEGY", code
        )
        if verdict != "accepted":
            raise MissionFailed(f"SET_STRATEGY {code} was {verdict}: {reason}")
        self.event(f"user: strategy {code} ({reason})")

    async def run(self) -> int:
        first, direct, avoid, change = USER_STEPS_S
        await self.stack_up()
        await self.until("the default strategy", lambda log: log.now.strategy == "GOTO_AVOID")
        await self.run_to(first)  # the sim's clock heard: it holds at 0
        near = self.goal = await stack_commands.set_goal(self.rt, ROBOT, *GOAL_NEAR)
        self.event(f"user: goal {near} at {GOAL_NEAR} (GOTO_AVOID)")
        await self.run_to(direct)
        await self.strategy("GOTO_DIRECT")
        await self.run_to(avoid)
        await self.strategy("GOTO_AVOID")
        await self.run_to(change)
        if (await self.monitor.poll()).goals.get(near) != "active":
            raise MissionFailed("the first goal ended before the goal change")
        far = self.goal = await stack_commands.set_goal(self.rt, ROBOT, *GOAL_FAR)
        self.event(f"user: goal changed in motion to {far} at {GOAL_FAR}; hands off from now")
        await self.run_to(None)
        await self.until("the battery detour (CHARGE)", lambda log: log.now.strategy == "CHARGE")
        self.event(f"system: CMD_BATTSAVE -> CHARGE at {self.monitor.log.now.battery_pct:.2f}%")
        await self.until("charging at a station", lambda log: log.now.charging)
        self.event("robot: charging")
        await self.until("CMD_RESUME", lambda log: log.now.strategy == "GOTO_AVOID")
        self.event(f"system: CMD_RESUME -> GOTO_AVOID at {self.monitor.log.now.battery_pct:.2f}%")
        await self.until("the goal", lambda log: log.goals.get(far) == "reached")
        self.event(f"robot: goal {far} reached")
        return far


class MissionFailed(Exception):
    pass


def summary_text(summary: dict[str, Any]) -> str:
    timeline = " -> ".join(f"{code}@{t:.1f}s" for t, code in summary["strategy_timeline"])
    return "\n".join(
        [
            "",
            "mission summary",
            f"  outcome          {summary['outcome']}",
            f"  sim time         {summary['sim_s']:.1f} s   wall time {summary['wall_s']:.1f} s"
            f"   (rate {summary['rate']})",
            f"  distance         {summary['distance_m']:.2f} m",
            f"  collisions       {summary['collisions']}",
            f"  decisions        {summary['decisions']} command2robot rows",
            f"  battery          min {summary['min_battery_pct']:.2f}%  "
            f"max {summary['max_battery_pct']:.2f}%",
            f"  strategy         {timeline}",
        ]
    )


def start_battery_pct(model: str | None) -> float:
    """The start charge giving the demo's robot the Burger's 0.09 Wh, whatever its model."""
    if model is None:
        return START_BATTERY_PCT
    burger = load_model(DEFAULT_MODEL).battery_capacity_wh
    return START_BATTERY_PCT * burger / load_model(model).battery_capacity_wh


async def demo(
    rate: str,
    record: Path | None = None,
    dashboard: DashboardOptions | None = None,
    model: str | None = None,
    robot_link: dict[str, str] | None = None,
    record_encoding: str = "foxglove",
) -> dict[str, Any]:
    """``robot_link``: the robot link's variables (pnav.cli.options.robot_link_env); none:
    native."""
    wall_start = time.monotonic()
    what = f"robot {ROBOT}" if model is None else f"robot {ROBOT} ({model})"
    print(f"proactive-nav demo: {WORLD} world, sim rate {rate}, {what}")
    options = StackOptions(
        world=WORLD,
        rate=rate,
        robots=1,
        battery=start_battery_pct(model),
        sim_held=True,  # the user's steps at their sim times (USER_STEPS_S)
        zenoh_port=None,
        dashboard=dashboard,
        model=model,
    )
    options.record, options.record_encoding = record, record_encoding
    options.extra_env.update(robot_link or {})
    if robot_link:
        print(f"  robot link: {robot_link.get('PNAV_ROBOT_LINK')} (the robot's topics on ROS 2)")
    async with launched(options) as stack:
        print(f"  stack up in {time.monotonic() - wall_start:.1f} s; logs in {stack.log_dir}")
        if stack.dashboard_url:
            print(f"  dashboard: {stack.dashboard_url} (watch the mission live)", flush=True)
        rt = await Runtime.open(
            ServiceConfig(
                service="demo", database_url=stack.local.url_for("user"), zenoh=stack.local.zenoh
            )
        )
        monitor = MissionMonitor(rt.database.pool, ROBOT)
        runner = Demo(monitor, rt)
        outcome = "success"
        try:
            await runner.run()
            if monitor.log.collisions:
                outcome = f"failed: {monitor.log.collisions} collision(s)"
        except MissionFailed as exc:
            outcome = f"failed: {exc}"
        finally:
            log = await monitor.poll()
            await rt.close()
        if runner.tty:
            print()
        restarts = {n: c.restarts for n, c in stack.supervisor.children.items() if c.restarts}
    summary: dict[str, Any] = {
        "outcome": outcome,
        "world": WORLD,
        "rate": rate,
        "sim_s": log.now.stamp,
        "wall_s": round(time.monotonic() - wall_start, 2),
        "events": runner.events,
        "restarts": restarts,
        **{k: v for k, v in log.as_dict().items() if k != "now"},
    }
    print(summary_text(summary))
    if record is not None:
        print(f"  recording        {record} (`pnav record info {record}`; open it in Foxglove)")
    return summary


def run(
    json_path: str | None = None,
    rate: str | None = None,
    record: Path | None = None,
    dashboard: DashboardOptions | None = None,
    model: str | None = None,
    robot_link: dict[str, str] | None = None,
    record_encoding: str = "foxglove",
) -> int:
    summary = uvloop.run(demo(rate or RATE, record, dashboard, model, robot_link, record_encoding))
    if json_path:
        Path(json_path).write_text(json.dumps(summary, indent=2, default=str) + "\n")
    return 0 if summary["outcome"] == "success" else 1
