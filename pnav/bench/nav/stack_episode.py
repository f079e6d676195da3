"""One navigation run of the whole stack: a world, a strategy, a goal; what the robot did.

The stack runs as ``pnav up`` runs it (embedded Postgres, router, sim, bridge, the four
scenario services), with the sim at ``--rate max`` in lockstep with the stack (by default;
``PNAV_LOCKSTEP``, docs/SIM.md): the sim holds at sim time 0 until the services and this
runner (a participant that sends the mission, then only watches) report quiet, and then
steps only when everything its readings caused has been handled, so the same world and seed
give the same run on a quiet or a loaded machine. ``pacing="lag"`` runs the older pacing
instead (``--max-lag``: decisions never staler than 0.1 s of sim time; faster, not
repeatable).

The episode watches what a user would: odometry (the driven trajectory), collision events
and the commands reaching the sim. Sim time counts from the first decided command that
moves the robot, because before it the robot stands still while the services start; the
episode ends at the first of reaching the goal (within the episode's goal tolerance, BARN's
0.3 m by default), a collision, or the time limit.

What the run cost is measured over the same span (first decision to the end): the CPU
seconds of every process of the stack (``pnav.bench.processes.Usage``: the services,
Postgres, and this process with its Zenoh router) and the wall time, so that a benchmark can
put them per sim second next to another way of running the same logic; and the
sense-to-act latency of every decision of the run (wall ms from the sim publishing the
reading a recommendation was made from to the command reaching the sim), joined through
the sim's trace and the commands' provenance exactly as ``pnav bench latency`` does. The
sim's pacing figures (``gate_timeouts``: waits that gave up after 2 s wall, i.e. the pacing
failed) are read from its log once it stopped.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import re
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
from common.trace import CMD_VEL, read_trace
from pnav.bench import provenance_samples as prov
from pnav.bench.nav.scores import GOAL_TOLERANCE_M
from pnav.bench.processes import Usage
from pnav.bench.sense_to_act import Collected, collect
from pnav.cli import stack_commands
from pnav.run.launcher import launched
from pnav.run.stack_options import StackOptions

SUCCESS_RADIUS_M = GOAL_TOLERANCE_M  # BARN: the goal counts as reached within 0.3 m
MAX_LAG_S = 0.1  # the decision service re-issues every 0.1 s sim: never staler than that
LOCKSTEP = "lockstep"
LAG = "lag"
PACINGS = (LOCKSTEP, LAG)
# who the lockstep sim waits for: the stack's services and this runner
PARTICIPANTS = ("bridge", "strategy", "planner", "controller", "decision", "navbench")
WALL_FACTOR = 8.0  # a run may take this many times its time limit in wall time, plus START
# read new commands (and the sensor rows they name) this often, wall: Postgres keeps 900
# odometry rows a robot, 30 s of sim time, which a paced run crosses in 3 s or more
COLLECT_PERIOD_S = 1.0


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
    goal_tolerance_m: float = SUCCESS_RADIUS_M
    pacing: str = LOCKSTEP
    # keep the run's database in this directory (a training set: docs/LEARNING.md); "": a
    # temporary one, removed at the end
    keep_db: str = ""


# rows kept per robot and sensor table when the database is kept: the whole run, not the
# last seconds that retention_policy keeps by default (30 s of odometry, of scans)
KEEP_DB_ROWS = 1_000_000


@dataclass
class Outcome:
    """What happened; times are sim seconds from the first decided command."""

    end: str  # "goal", "collision", "timeout", "stalled" (wall-time cap: the stack hung)
    time_s: float
    trajectory: list[tuple[float, float, float]] = field(default_factory=list)  # (t, x, y)
    collisions: list[tuple[float, float, float, str]] = field(default_factory=list)
    final_distance_m: float = math.inf
    wall_s: float = 0.0  # the whole episode, the stack's start-up and shut-down included
    run_wall_s: float = 0.0  # wall time from the first decision to the end
    cpu_s: float = 0.0  # CPU seconds of the whole stack over the same span
    cpu_by_role: dict[str, float] = field(default_factory=dict)  # sim, postgres, launcher...
    # the sim's pacing gave up waiting for the stack this often (its log; None: unread)
    gate_timeouts: int | None = None
    # the sim waited for the stack this often per sim second of its whole run (its log)
    gate_waits_per_sim_s: float | None = None
    log_dir: str = ""
    latency_ms: list[float] = field(default_factory=list)  # sense-to-act, one per decision


class Watcher:
    """Odometry, collisions and commands of one robot, from Zenoh's threads."""

    def __init__(
        self, robot: str, goal: tuple[float, float], tolerance_m: float = SUCCESS_RADIUS_M
    ) -> None:
        self.robot, self.goal, self.tolerance_m = robot, goal, tolerance_m
        self.lock = threading.Lock()
        self.odom: list[tuple[float, float, float]] = []
        self.collisions: list[tuple[float, float, float, str]] = []
        self.first_decision: float | None = None
        self.checked = 0  # odometry points already looked at for arrival
        self._events: set[tuple[object, object]] = set()  # collision events seen (run, seq)

    def on_odom(self, _key: str, payload: bytes) -> None:
        m = bus.unpack(payload)
        with self.lock:
            self.odom.append((float(m["stamp"]), float(m["x"]), float(m["y"])))

    def on_collision(self, _key: str, payload: bytes) -> None:
        m = bus.unpack(payload)
        with self.lock:
            # the sim resends an event until the bridge acknowledges it: count it once
            event = (m.get("run"), m.get("seq"))
            if event[0] is not None and event in self._events:
                return
            self._events.add(event)
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
            # every point since the last look, oldest first: the arrival is the first point
            # inside the tolerance, however many came in between two looks
            for t, x, y in self.odom[self.checked :]:
                if t >= t0 and math.dist((x, y), self.goal) <= self.tolerance_m:
                    return "goal", t - t0
            self.checked = len(self.odom)
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


async def keep_history(rt: Runtime) -> None:
    """Keep every sensor row of the run: a kept database is a training set."""
    await rt.database.write(
        keys.RETENTION_POLICY,
        None,
        "UPDATE retention_policy SET keep_rows_per_robot = $1",
        KEEP_DB_ROWS,
    )


def gate_figures(sim_log: Path) -> dict[str, float]:
    """``gate_waits`` and ``gate_timeouts`` from the sim's last "sim stopped" line ({} if
    there is none: the sim did not stop cleanly, or the log is elsewhere); a lockstep sim's
    ``lockstep_waits`` under the same name, its ``lockstep_timeouts`` plus
    ``lockstep_lost`` as ``gate_timeouts``; and ``gate_waits_per_sim_s``, the waits over
    the line's ``sim_time`` (the whole run, the hold at sim time 0 included)."""
    try:
        text = sim_log.read_text(errors="replace")
    except OSError:
        return {}
    stops = [line for line in text.splitlines() if "sim stopped" in line]
    if not stops:
        return {}
    found = dict(re.findall(r"(?:gate|lockstep)_(waits|timeouts|lost)=(\d+)", stops[-1]))
    figures: dict[str, float] = {
        f"gate_{name}": int(found[name]) for name in ("waits", "timeouts") if name in found
    }
    if "lost" in found and "gate_timeouts" in figures:
        # a message that never reached a participant mid-run spoils the repeat as a wait
        # given up does
        figures["gate_timeouts"] += int(found["lost"])
    sim_time = re.search(r"\bsim_time=([0-9.]+)", stops[-1])
    if sim_time is not None and "gate_waits" in figures and float(sim_time.group(1)) > 0:
        figures["gate_waits_per_sim_s"] = round(figures["gate_waits"] / float(sim_time[1]), 2)
    return figures


def sense_to_act_ms(trace: Path, collected: Collected, since: float, until: float) -> list[float]:
    """The latency of each decision whose reading the sim published between ``since`` and
    ``until`` (wall, time.time()), in ms; [] without a trace."""
    try:
        events = read_trace(trace)
    except OSError:
        return []
    published: dict[tuple[str, str, int], float] = {}
    arrivals: dict[int, float] = {}
    for e in events:
        if e.kind == CMD_VEL:
            arrivals.setdefault(e.ref, e.wall_ns / 1e9)
        else:
            published[(e.kind, e.robot, e.ref)] = e.wall_ns / 1e9
    found, _ = prov.samples(arrivals, collected.commands, collected.rows, published)
    return [s.total_ms for s in found if since <= s.published <= until]


async def run_episode(episode: Episode, log_dir: Path | None = None) -> Outcome:
    log_dir = log_dir or Path(tempfile.mkdtemp(prefix="pnav-nav-"))
    if episode.pacing not in PACINGS:
        raise ValueError(f"pacing {episode.pacing!r}: one of {', '.join(PACINGS)}")
    pacing = (
        {"PNAV_LOCKSTEP": ",".join(PARTICIPANTS)}
        if episode.pacing == LOCKSTEP
        else {"PNAV_SIM_MAX_LAG": str(MAX_LAG_S)}
    )
    options = StackOptions(
        world=str(episode.world),
        rate="max",
        zenoh_port=None,
        log_dir=log_dir,
        data_dir=Path(episode.keep_db) if episode.keep_db else None,
        extra_env={
            **pacing,
            "PNAV_SIM_SEED": str(episode.seed),
            "PNAV_SIM_TRACE": str(log_dir / "trace.csv"),
        },
    )
    started = time.monotonic()
    watcher = Watcher(episode.robot, episode.goal, episode.goal_tolerance_m)
    usage: Usage | None = None
    collected, window, next_collect = Collected(), [0.0, 0.0], 0.0
    async with launched(options) as stack:
        config = ServiceConfig(
            service="navbench",
            database_url=stack.local.database_url,
            zenoh=stack.local.zenoh,
            lockstep=PARTICIPANTS if episode.pacing == LOCKSTEP else (),
        )
        # in lockstep a sender-only participant: what it writes counts, what it watches not
        rt = await Runtime.open(config, receipts=False)
        subs: list[Any] = []
        ledger = rt.ledger
        try:
            for topic, handler in (
                (keys.ODOM, watcher.on_odom),
                (keys.COLLISION, watcher.on_collision),
                (keys.CMD_VEL, watcher.on_cmd_vel),
            ):
                key = keys.robot_key(episode.robot, topic)
                subs.append(bus.subscribe_threaded(rt.zenoh, key, handler, ledger=ledger))
            if episode.robot not in await stack_commands.robot_ids(rt, wait_s=30.0):
                raise RuntimeError(f"robot {episode.robot} never registered from {episode.world}")
            await ensure_combo(rt, episode.combo)
            if episode.keep_db:
                await keep_history(rt)
            verdict, reason = await stack_commands.send_user_command(
                rt, episode.robot, "SET_STRATEGY", episode.combo.code, wait_s=15.0
            )
            if verdict != "accepted":
                raise RuntimeError(f"strategy {episode.combo.code} {verdict}: {reason}")
            await stack_commands.set_goal(rt, episode.robot, *episode.goal)
            if ledger is not None:
                ledger.report_if_settled(ledger.mark())  # the mission is sent: the sim may go
            wall_cap = started + 30.0 + WALL_FACTOR * episode.time_limit_s
            async with contextlib.AsyncExitStack() as measuring:
                while (result := watcher.verdict(episode.time_limit_s)) is None:
                    if usage is None and watcher.first_decision is not None:
                        # the run starts: measure its cost from here to its end
                        usage = Usage(stack, period_s=5.0)  # few samples: little of our own CPU
                        await measuring.enter_async_context(usage.measuring())
                        window[0] = time.time()
                    if time.monotonic() >= next_collect:
                        next_collect = time.monotonic() + COLLECT_PERIOD_S
                        await collect(rt, collected)
                    if time.monotonic() > wall_cap:
                        t0 = watcher.first_decision
                        last = watcher.odom[-1][0] if watcher.odom else 0.0
                        result = ("stalled", last - t0 if t0 is not None else 0.0)
                        break
                    await asyncio.sleep(0.02)
            window[1] = time.time()
            await collect(rt, collected)  # the last decisions, before the rows go
        finally:
            for sub in subs:
                with contextlib.suppress(Exception):
                    sub.undeclare()
            await rt.close()
    end, time_s = result
    t0 = watcher.first_decision or 0.0
    with watcher.lock:
        trajectory = [(t - t0, x, y) for t, x, y in watcher.odom if t0 <= t <= t0 + time_s]
        # a contact reported after the run ended (the goal reached first) is not the run's
        collisions = [
            (t - t0, x, y, o) for t, x, y, o in watcher.collisions if t0 <= t <= t0 + time_s
        ]
    final = math.dist(trajectory[-1][1:], episode.goal) if trajectory else math.inf
    cpu = {role: float(r["cpu_s"]) for role, r in usage.report().items()} if usage else {}
    paced = gate_figures(log_dir / "sim.log")
    timeouts = paced.get("gate_timeouts")
    return Outcome(
        end,
        time_s,
        trajectory,
        collisions,
        final,
        wall_s=time.monotonic() - started,
        run_wall_s=usage.wall_s if usage else 0.0,
        cpu_s=sum(cpu.values()),
        cpu_by_role=cpu,
        gate_timeouts=None if timeouts is None else int(timeouts),
        gate_waits_per_sim_s=paced.get("gate_waits_per_sim_s"),
        log_dir=str(log_dir),
        latency_ms=sense_to_act_ms(log_dir / "trace.csv", collected, *window) if usage else [],
    )
