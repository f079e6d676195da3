"""The sim on Zenoh: publishes sensors, clock and world, obeys cmd_vel, answers world queries.

The loop runs on one thread (the main thread under ``python -m services.sim``, a worker thread
in tests). Zenoh delivers cmd_vel and world queries on its own threads; they only hand a
command to :meth:`Simulation.set_command` (thread-safe) or reply with bytes built at start.
"""

from __future__ import annotations

import functools
import logging
import threading
import time
from typing import Any

import zenoh

import services.sim.messages as messages
from common.bus import pack, subscribe_threaded, unpack
from common.contract import keys
from common.log import event
from common.robotlink import RobotLinkSettings
from common.trace import CMD_VEL, NO_REF, Tracer
from services.sim.hold import Hold
from services.sim.lag_gate import Gate
from services.sim.lockstep_barrier import Barrier
from services.sim.matching import await_listeners, warn_unmatched
from services.sim.outbox import CollisionOutbox
from services.sim.pacing import Pacer
from services.sim.ros2wire import TOPICS as ROS2_TOPICS
from services.sim.ros2wire import make_wire
from services.sim.sim import SimConfig, Simulation
from services.sim.world_spec import World

log = logging.getLogger(__name__)

SERVICE = "sim"
# the clock goes out at this wall rate, above the contract's 20 Hz floor
CLOCK_HZ = 30.0
# paced by the stack (--max-lag), the clock also goes out every this many sim seconds: the
# services then stamp their decisions with a time at most this far behind the sim's
GATE_CLOCK_SIM_S = 0.02
# in lockstep, the clock goes out every this many sim seconds, before the readings of the
# step it falls on: the engines' F (0.05 s) and the bridge's watchdog run on it. Each clock
# costs a wait for the whole stack: it no longer goes out before every step with readings
# too (odometry at 30 Hz: 30 clocks a sim second instead of 20; the readings carry their
# own stamps, and a service's sim time is then at most this stale).
LOCKSTEP_CLOCK_S = 0.05
# and the world every this many wall seconds, besides the queryable
WORLD_PERIOD_S = 1.0
# at most one log line per robot per this many seconds about bad cmd_vel
BAD_COMMAND_LOG_PERIOD_S = 1.0
# how often (wall s) the loop looks for collision events to resend (outbox.py)
RESEND_CHECK_S = 0.1


class SimNode:
    def __init__(
        self,
        world: World,
        config: SimConfig,
        session: zenoh.Session,
        *,
        rate: float = 1.0,
        instance: str = "sim",
        tracer: Tracer | None = None,
        gate: Gate | None = None,
        lockstep: tuple[str, ...] = (),
        robot_link: RobotLinkSettings | None = None,
        ros2_session: zenoh.Session | None = None,
        held: bool = False,
    ) -> None:
        if gate is not None and lockstep:
            raise ValueError("--max-lag and --lockstep exclude each other: lockstep waits always")
        if held and lockstep:
            raise ValueError("--held and --lockstep exclude each other: lockstep holds at 0 itself")
        self.session = session
        self.rate = rate
        self.tracer = tracer
        self.gate = gate
        self.barrier = Barrier(session, lockstep) if lockstep else None
        # held (hold.py): steps only as far as pnav/sim/run lets it
        self.hold = Hold(session) if held else None
        # in lockstep a step's readings wait here, to go out one at a time
        self._held: list[tuple[str, str, dict[str, Any]]] = []
        self._publishers: dict[tuple[str, str], zenoh.Publisher] = {}
        # collision events are held until acknowledged and resent meanwhile (outbox.py)
        self.outbox = CollisionOutbox()
        # ROS 2 (ros2wire.py): scan, odom, battery and cmd_vel; clock, world, collisions here
        self.wire = make_wire(
            robot_link,
            ros2_session or session,
            [spec.robot_id for spec in world.robots],
            self._ros2_command,
            functools.partial(self._complain, msg="malformed ROS 2 cmd_vel ignored"),
            paced=bool(lockstep) or gate is not None,
        )
        for spec in world.robots:
            for topic in keys.SENSOR_TOPICS:
                if self.wire is not None and topic in ROS2_TOPICS:
                    continue
                # Every topic drops under congestion rather than stall the sim: a reading is
                # replaced by the next, a collision event is resent until acknowledged (a
                # blocking put would stop the physics for as long as a router is frozen).
                # express: sent at once, not held for Zenoh's batching (up to a millisecond
                # per link, twice through the router, measured in sense-to-act latency)
                self._publishers[(spec.robot_id, topic)] = session.declare_publisher(
                    keys.robot_key(spec.robot_id, topic),
                    congestion_control=zenoh.CongestionControl.DROP,
                    express=True,
                )
        self._clock_pub = session.declare_publisher(keys.SIM_CLOCK, express=True)
        self._world_pub = session.declare_publisher(
            keys.SIM_WORLD, congestion_control=zenoh.CongestionControl.BLOCK
        )
        self.sim = Simulation(world, config, self._publish)
        self._world_payload = pack(world.message())
        self._bad_logged: dict[str, float] = {}
        self._subscriber = (
            None
            if self.wire is not None
            else subscribe_threaded(session, keys.robot_watch(keys.CMD_VEL), self._on_cmd_vel)
        )
        self._ack_subscriber = subscribe_threaded(
            session, keys.robot_watch(keys.COLLISION_ACK), self.outbox.on_ack
        )
        self._queryable = session.declare_queryable(keys.SIM_WORLD, self._on_world_query)
        self._token = session.liveliness().declare_token(keys.alive_key(SERVICE, instance))
        self.commands_received = 0
        self._matching_checked = False  # warn_unmatched ran
        # paced by the stack, the sim time of the next clock the gate owes (_pass_gate)
        self._next_gate_clock = 0.0

    # -- Zenoh callbacks (Zenoh's threads) --------------------------------------------------
    def _on_cmd_vel(self, key: str, payload: bytes) -> None:
        try:
            robot, _topic = keys.parse_robot_key(key)
        except ValueError:
            return
        try:
            cmd = messages.parse_cmd_vel(unpack(payload))
        except ValueError as exc:
            self._complain(robot, str(exc), "malformed cmd_vel ignored")
            return
        if not self.sim.set_command(robot, cmd.linear, cmd.angular):
            self._complain(robot, robot, "cmd_vel for an unknown robot ignored")
            return
        if self.tracer is not None and cmd.command_id is not None:
            self.tracer.record(CMD_VEL, robot, cmd.command_id)
        if self.gate is not None and cmd.decided_stamp is not None:
            self.gate.on_decision(robot, cmd.decided_stamp)
        self.commands_received += 1
        if self.barrier is not None:
            self.barrier.on_cmd_vel(key)

    def _ros2_command(self, robot: str, linear: float, angular: float, wire: int) -> None:
        """A ROS 2 cmd_vel (ros2wire.py checked it): no command id, no decided stamp; the
        trace names it by its attachment's number, which the bridge's trace joins to the id."""
        if not self.sim.set_command(robot, linear, angular):
            self._complain(robot, robot, "cmd_vel for an unknown robot ignored")
            return
        if self.tracer is not None:
            self.tracer.record(CMD_VEL, robot, NO_REF, wire)
        self.commands_received += 1

    def _complain(self, robot: str, problem: str, msg: str = "") -> None:
        now = time.monotonic()
        if now - self._bad_logged.get(robot, -1e9) >= BAD_COMMAND_LOG_PERIOD_S:
            self._bad_logged[robot] = now
            event(log, logging.WARNING, msg, robot=robot, problem=problem)

    def _on_world_query(self, query: zenoh.Query) -> None:
        query.reply(keys.SIM_WORLD, self._world_payload)

    # -- publishing --------------------------------------------------------------------------
    def _publish(self, robot: str, topic: str, message: dict[str, Any]) -> None:
        if self.barrier is not None:
            self._held.append((robot, topic, message))
            return
        self._send(robot, topic, message)

    def _send(self, robot: str, topic: str, message: dict[str, Any]) -> None:
        if topic == keys.COLLISION:
            message = {**message, "run": self.outbox.run}
            self.outbox.sent(robot, message)
        if self.wire is not None and topic in ROS2_TOPICS:
            # stamped before it goes, as on the native wire; named by the attachment's number
            sent_ns = Tracer.now()
            wire = self.wire.publish(robot, topic, message)
            if self.tracer is not None:
                self.tracer.record(topic, robot, message["seq"], wire, sent_ns)
            return
        if self.tracer is not None:
            self.tracer.record(topic, robot, message["seq"])
        self._publishers[(robot, topic)].put(pack(message))

    def resend_collisions(
        self, barrier: Barrier | None = None, stop: threading.Event | None = None
    ) -> None:
        """Send again every collision event not acknowledged within the outbox's resend_s
        (in lockstep each counted and waited for, as any reading)."""
        for robot, message in self.outbox.due():
            key = keys.robot_key(robot, keys.COLLISION)
            if barrier is not None:
                barrier.published(key)
            self._publishers[(robot, keys.COLLISION)].put(pack(message))
            if barrier is not None:
                barrier.wait(stop or threading.Event())

    def publish_clock(self) -> None:
        if self.wire is not None and self.wire.publish_clock(self.sim.time):
            return  # a ROS /clock instead (clock: ros, ros2wire.py)
        # in lockstep the clock stands still between messages, and a held sim stands still:
        # rate 0, no extrapolation
        rate = 0.0 if self.barrier is not None or self._holding() else self.rate
        self._clock_pub.put(pack(messages.clock(self.sim.time, rate)))

    def publish_world(self) -> None:
        self._world_pub.put(self._world_payload)

    # -- the loop ----------------------------------------------------------------------------
    def run(self, stop: threading.Event, *, until_sim_s: float | None = None) -> None:
        """Step the sim at ``rate`` until ``stop`` is set (or sim time reaches ``until_sim_s``),
        publishing the clock at CLOCK_HZ and the world every WORLD_PERIOD_S of wall time."""
        if self.barrier is not None:
            self._run_lockstep(self.barrier, stop, until_sim_s)
            return
        sim = self.sim
        pacer = Pacer(self.rate, sim.dt)
        clock_period = 1.0 / CLOCK_HZ
        self.publish_world()
        next_world = time.monotonic() + WORLD_PERIOD_S
        next_clock = next_resend = 0.0
        self._next_gate_clock = 0.0
        await_listeners(self._publishers, stop)
        self._log_running(
            max_lag=None if self.gate is None else self.gate.max_lag_s,
            held=self.hold is not None,
        )
        while not stop.is_set() and not _reached(sim, until_sim_s):
            now = time.monotonic()
            holding = self._holding()  # sim time does not move until a step below
            if holding:
                pacer.restart(sim.steps)  # sim time stands: no steps owed on release
            if now >= next_clock:
                self.publish_clock()
                next_clock = now + clock_period
            if now >= next_world:
                # a world period after the start, once
                self._matching_checked = self._matching_checked or warn_unmatched(self._publishers)
                self.publish_world()
                next_world = now + WORLD_PERIOD_S
            if now >= next_resend:
                self.resend_collisions()
                next_resend = now + RESEND_CHECK_S
            if self.tracer is not None:
                self.tracer.maybe_flush()
            owed = 0 if holding else pacer.steps_due(sim.steps)
            if owed == 0:
                clock_due = max(0.0, next_clock - now)
                # asked again: a run message that came since would not wake the wait
                if self.hold is not None and self._holding():
                    self.hold.wait(clock_due)  # a run message wakes it at once
                else:
                    stop.wait(min(pacer.wall_until_next(sim.steps), clock_due))
                continue
            self._step_owed(owed, stop, until_sim_s, next_clock)
        self.publish_clock()
        if pacer.slips:
            event(
                log,
                logging.WARNING,
                "sim could not keep up with the rate asked",
                rate=self.rate,
                slips=pacer.slips,
            )
        self._log_stopped()

    def _step_owed(
        self, owed: int, stop: threading.Event, until_sim_s: float | None, next_clock: float
    ) -> None:
        """Run the ``owed`` steps, each once the gate (if any) lets it; back early when the
        clock is due at ``next_clock`` (wall) or sim time reaches ``until_sim_s``."""
        for k in range(owed):
            if self.gate is not None:
                self._pass_gate(self.gate, stop)
            self.sim.step()
            # come back in time for the clock however many steps are owed
            if k & 15 == 15 and time.monotonic() >= next_clock:
                break
            if _reached(self.sim, until_sim_s):
                break
            if self._holding():
                self.publish_clock()  # the time it holds at, with rate 0, at once
                break

    def _holding(self) -> bool:
        """Held (hold.py) at the sim time reached."""
        return self.hold is not None and self.hold.holding(self.sim.time)

    def _pass_gate(self, gate: Gate, stop: threading.Event) -> None:
        """Wait until the next step is no further than max_lag past every robot's newest
        decision (lag_gate.py), publishing the clock every GATE_CLOCK_SIM_S of sim time."""
        sim = self.sim
        if not gate.heard:
            # services still starting: real time, not max (services/sim/lag_lag_gate.py)
            stop.wait(sim.dt)
        gate.wait(sim.time, stop, self.publish_clock)
        if sim.time >= self._next_gate_clock:
            self.publish_clock()
            self._next_gate_clock = sim.time + GATE_CLOCK_SIM_S

    def _run_lockstep(
        self, barrier: Barrier, stop: threading.Event, until_sim_s: float | None
    ) -> None:
        """Step only when the stack is quiet (lockstep_barrier.py): the clock every
        LOCKSTEP_CLOCK_S, then each reading of a step on its own, each followed by a wait."""
        sim = self.sim
        pacer = Pacer(self.rate, sim.dt)
        self.publish_world()
        event(
            log,
            logging.INFO,
            "sim holding at 0 for the stack (lockstep)",
            world=sim.world.name,
            expected=",".join(sorted(barrier.expected)),
        )
        # at 0 until everyone is there and quiet, then once more with the clock of sim time 0:
        # whoever joined late has it too before the first step
        barrier.hold(stop, lambda: self._count_clock(barrier))
        self._clock_barrier(barrier, stop)
        self._log_running(lockstep=",".join(sorted(barrier.expected)))
        next_clock = sim.time + LOCKSTEP_CLOCK_S
        while not stop.is_set() and not _reached(sim, until_sim_s):
            if self.rate and pacer.steps_due(sim.steps) == 0:
                stop.wait(pacer.wall_until_next(sim.steps))
                continue
            sim.step()
            if sim.time >= next_clock - 1e-9:
                self._clock_barrier(barrier, stop)
                next_clock = sim.time + LOCKSTEP_CLOCK_S
            held, self._held = self._held, []
            for robot, topic, message in held:
                barrier.published(keys.robot_key(robot, topic))
                self._send(robot, topic, message)
                barrier.wait(stop)
            self.resend_collisions(barrier, stop)
            if self.tracer is not None:
                self.tracer.maybe_flush()
        self.publish_clock()
        self._log_stopped()

    def _log_stopped(self) -> None:
        """The line ``pnav bench nav`` reads the pacing's figures from (``gate_figures``)."""
        event(
            log,
            logging.INFO,
            "sim stopped",
            sim_time=round(self.sim.time, 3),
            commands=self.commands_received,
            cmd_timeout_stops=self.sim.cmd_timeout_stops,
            contacts=self.sim.counts[keys.COLLISION],
            max_after_command_m=round(self.sim.max_after_command_m, 4),
            collisions_resent=self.outbox.resent,
            collisions_unacked=self.outbox.waiting(),
            **self.gate_figures(),
        )

    def _log_running(self, **pacing: Any) -> None:
        sim = self.sim
        event(
            log,
            logging.INFO,
            "sim running",
            world=sim.world.name,
            rate=self.rate or "max",
            **pacing,
            robots=[r.robot_id for r in sim.robots],
            physics_hz=sim.config.physics_hz,
            cmd_timeout_s=sim.config.cmd_timeout_s,
        )

    def _clock_barrier(self, barrier: Barrier, stop: threading.Event) -> None:
        self._count_clock(barrier)
        barrier.wait(stop)

    def _count_clock(self, barrier: Barrier) -> None:
        barrier.published(keys.SIM_CLOCK)
        self.publish_clock()

    def gate_figures(self) -> dict[str, Any]:
        """How often and how long the sim waited for the stack (empty without a gate)."""
        if self.barrier is not None:
            return self.barrier.figures()
        if self.gate is None:
            return {}
        return {
            "gate_waits": self.gate.waits,
            "gate_timeouts": self.gate.timeouts,
            "gate_waited_wall_s": round(self.gate.waited_wall_s, 3),
        }

    def close(self) -> None:
        """Undeclare everything this node declared and free pybullet (not the session)."""
        if self.barrier is not None:
            self.barrier.close()
        if self.hold is not None:
            self.hold.close()
        entities: list[Any] = [
            self._subscriber,
            self._ack_subscriber,
            self._queryable,
            self._token,
            self._clock_pub,
            self._world_pub,
            *self._publishers.values(),
        ]
        if self.wire is not None:
            self.wire.close()
        for entity in entities:
            if entity is None:
                continue
            try:
                entity.undeclare()
            except Exception:  # the session is already closed
                log.debug("undeclare failed", exc_info=True)
        self._publishers.clear()
        self.sim.close()
        if self.tracer is not None:
            self.tracer.close()


def _reached(sim: Simulation, until_sim_s: float | None) -> bool:
    return until_sim_s is not None and sim.time >= until_sim_s
