"""One navigation episode in one process: the monolith's ``run_episode``.

The same :class:`~pnav.bench.nav.stack_episode.Episode` in, an :class:`Outcome` with the same
fields out (plus what only the monolith can measure), and the same judge: the episode's
:class:`~pnav.bench.nav.stack_episode.Watcher` is fed the odometry and collision messages and the
commands reaching the sim, and says when the run is over exactly as it does for the stack
(the goal within the tolerance, BARN's 0.3 m; a collision; the time limit), with times
counted from the first decided command that moves the robot.

Differences in what is measured: the run is deterministic (same episode, same trajectory)
and as fast as the CPU allows, so ``wall_s`` and ``cpu_s`` say what the logic and the
physics cost, with no transport, database or scheduling in between; ``cpu_s`` and
``run_wall_s`` cover the same span as the stack's (first decision to the end).
"""

from __future__ import annotations

import math
import time
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

from common.contract import keys
from pnav.bench.nav.stack_episode import Episode, Outcome, Watcher
from pnav.monolith.memory_bridge import Applied
from pnav.monolith.monolith_stack import MonolithStack
from pnav.monolith.strategies import combo_strategy, shipped_strategies
from services.sim.sim import SimConfig
from services.sim.world_spec import load_world


@dataclass
class MonolithOutcome(Outcome):
    """An :class:`Outcome` (``end`` is never "stalled": nothing here can hang), plus:"""

    cpu_s: float = 0.0  # process CPU (time.process_time) from the first decision to the end
    # sense-to-act, wall ms: a sensor message produced -> the command decided from it handed
    # to the sim; one sample per recommendation obeyed (pnav bench latency's rule)
    latency_ms: list[float] = field(default_factory=list)
    watchdog_stops: int = 0  # the bridge's watchdog stopped the robot (no fresh command)
    rule_errors: int = 0  # errors the engines counted (a rule's own failure, as in the stack)
    # who spoke and who was obeyed: recommendations per source, command2robot rows per
    # winning source ("" for a stop with nothing live), over the whole run
    recommended_by: dict[str, int] = field(default_factory=dict)
    decided_by: dict[str, int] = field(default_factory=dict)


def run_monolith_episode(episode: Episode) -> MonolithOutcome:
    """Run ``episode`` with the planner, controller and decision logic in this process."""
    started = time.perf_counter()
    world = load_world(episode.world)
    if episode.robot not in {r.robot_id for r in world.robots}:
        raise ValueError(f"robot {episode.robot} is not in {episode.world}")
    shipped = shipped_strategies()
    strategy = combo_strategy(episode.combo, shipped)
    watcher = Watcher(episode.robot, episode.goal, episode.goal_tolerance_m)
    marks: dict[str, float] = {}  # cpu and wall at the first decision

    def on_message(robot_id: str, topic: str, m: dict[str, Any]) -> None:
        if robot_id != episode.robot:
            return
        # the stack's Watcher gets these from Zenoh; same fields, same order
        if topic == keys.ODOM:
            watcher.odom.append((float(m["stamp"]), float(m["x"]), float(m["y"])))
        elif topic == keys.COLLISION:
            watcher.collisions.append(
                (float(m["stamp"]), float(m["x"]), float(m["y"]), str(m["other"]))
            )

    def on_applied(applied: Applied) -> None:
        # Watcher.on_cmd_vel's test: the first decided command that moves the robot
        moving = applied.linear != 0.0 or applied.angular != 0.0
        if applied.robot_id != episode.robot or watcher.first_decision is not None:
            return
        if applied.decided_stamp is not None and moving:
            watcher.first_decision = applied.decided_stamp
            marks.update(cpu=time.process_time(), wall=time.perf_counter())

    stack = MonolithStack(
        world,
        SimConfig(seed=episode.seed),
        [*shipped.values(), strategy],
        on_applied=on_applied,
        on_message=on_message,
    )
    try:
        stack.set_strategy(episode.robot, strategy.code)
        stack.set_goal(episode.robot, *episode.goal)
        while (result := watcher.verdict(episode.time_limit_s)) is None:
            stack.step()
            if watcher.first_decision is None and stack.now > episode.time_limit_s:
                result = ("timeout", episode.time_limit_s)  # never set off at all
                break
        cpu_s = time.process_time() - marks["cpu"] if marks else 0.0
        run_wall_s = time.perf_counter() - marks["wall"] if marks else 0.0
    finally:
        stack.close()
    end, time_s = result
    t0 = watcher.first_decision or 0.0
    trajectory = [(t - t0, x, y) for t, x, y in watcher.odom if t0 <= t <= t0 + time_s]
    collisions = [(t - t0, x, y, o) for t, x, y, o in watcher.collisions if t0 <= t <= t0 + time_s]
    final = math.dist(trajectory[-1][1:], episode.goal) if trajectory else math.inf
    return MonolithOutcome(
        end,
        time_s,
        trajectory,
        collisions,
        final,
        wall_s=time.perf_counter() - started,
        run_wall_s=run_wall_s,
        cpu_s=cpu_s,
        cpu_by_role={"monolith": cpu_s},
        latency_ms=list(stack.bridge.counters.latency_ms),
        watchdog_stops=stack.bridge.counters.watchdog_stops,
        rule_errors=sum(e.errors for e in stack.engines),
        recommended_by=_count(stack, keys.COMMAND_RECOMMENDATION, episode.robot),
        decided_by=_count(stack, keys.COMMAND2ROBOT, episode.robot),
    )


def _count(stack: MonolithStack, table: str, robot_id: str) -> dict[str, int]:
    counts = Counter(row["source"] or "" for row in stack.contract[table].rows(robot_id))
    return dict(sorted(counts.items()))
