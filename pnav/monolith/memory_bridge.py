"""What the bridge does, in process: sensor messages in as rows, the newest decision out.

Shared with services/bridge: the validation of every sensor message into a record
(``messages.PARSERS``, the same wrap of yaw, the same checks), the row each record becomes
(its ``sensor_tables.SENSOR_TABLES`` image), the clamp of a command to the
robot's limits (``commands.clamp``, NaN to 0), the safety layer (``safety.SafetyLayer``: the
command checked against the robot's newest scan, limited or stopped if it would hit what the
scan shows, the reason written on the row) and the watchdog (``watchdog.Watchdog``, 0.5 s
of sim time with no fresh command2robot row: one stop). Adapted: rows go into the in-memory
contract instead of a batched INSERT, and a command2robot row goes to ``Simulation.
set_command`` instead of a Zenoh ``cmd_vel``; the safety note is set on the in-memory row.

It also takes the sense-to-act samples, with the rule ``pnav bench latency`` uses
(pnav/bench/provenance_samples.py): a command obeys a recommendation, whose ``inputs`` name the
sensor row it was decided from (the laser scan for a controller, the odometry for the
planner); each recommendation counts once, at the first command that obeyed it (re-issues
say nothing about how fast the system reacted); the sample is the wall time from the sim
producing that sensor message to the command being handed to the sim.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from common.contract import keys, records
from common.contract.limits import clamp
from common.footprint import Footprint
from pnav.bench.provenance_samples import origin_of
from pnav.monolith.contract import MemoryContract, Row
from services.bridge.safety import LIMITED, STOPPED, UNCHECKED, SafetyLayer
from services.bridge.sensor_payloads import PARSERS, TABLE_OF_TOPIC, LaserScan, SensorRecord
from services.bridge.sensor_tables import SENSOR_TABLES
from services.bridge.settings import BridgeSettings
from services.bridge.watchdog import Watchdog

# (robot, linear, angular) -> whether the sim knows the robot
SetCommand = Callable[[str, float, float], bool]


@dataclass
class Applied:
    """A command handed to the sim: what the episode watches (as it watches cmd_vel)."""

    robot_id: str
    linear: float
    angular: float
    decided_stamp: float | None  # the command2robot row's stamp; None for a watchdog stop


@dataclass
class BridgeCounters:
    commands_out: int = 0
    watchdog_stops: int = 0
    safety_stopped: int = 0
    safety_limited: int = 0
    safety_unchecked: int = 0
    latency_ms: list[float] = field(default_factory=list)


class Bridge:
    def __init__(
        self,
        contract: MemoryContract,
        set_command: SetCommand,
        on_applied: Callable[[Applied], None],
        settings: BridgeSettings | None = None,
    ) -> None:
        self.contract = contract
        self.set_command = set_command
        self.on_applied = on_applied
        settings = settings or BridgeSettings()
        self.watchdog = Watchdog(settings.watchdog_s)
        self.safety = SafetyLayer(settings.safety)
        self.counters = BridgeCounters()
        self.last_sent: dict[str, int] = {}  # newest command2robot id sent, per robot
        self.wanted: set[str] = set()  # robots whose command2robot changed (notifications)
        self._obeyed: set[int] = set()  # recommendations already sampled for latency
        contract.listeners.append(self._on_change)

    # -- sensors in ---------------------------------------------------------------------------
    def ingest(self, robot_id: str, topic: str, message: dict[str, Any], produced: float) -> None:
        """One sim message (``produced``: perf_counter when the sim emitted it) -> a row."""
        record = PARSERS[topic](robot_id, message)
        if isinstance(record, LaserScan):
            self.safety.scan(record)
        row = _row(record)
        row["produced"] = produced  # not a contract column: the start of a latency sample
        self.contract.insert(TABLE_OF_TOPIC[topic], row)

    # -- commands out -------------------------------------------------------------------------
    def _on_change(self, table: str, robot: str | None, _row_id: int | None) -> None:
        if table == keys.COMMAND2ROBOT and robot is not None:
            self.wanted.add(robot)

    def relay(self, now: float) -> int:
        """Send the newest command2robot row of every robot announced since the last call;
        how many were sent."""
        sent = 0
        wanted, self.wanted = self.wanted, set()
        for robot_id in sorted(wanted):
            row = self.contract[keys.COMMAND2ROBOT].newest(robot_id)
            if row is None or row["id"] <= self.last_sent.get(robot_id, 0):
                continue
            self.last_sent[robot_id] = row["id"]
            robot = next(self.contract[keys.ROBOT].rows(robot_id), None)
            if robot is None:
                continue
            angular = clamp(row["angular_rps"], robot["max_angular_rps"])
            linear = clamp(row["linear_mps"], robot["max_linear_mps"])
            footprint = Footprint.of(
                robot["footprint_radius_m"], records.polygon_of(robot.get("footprint_polygon"))
            )
            decel = robot["max_linear_accel_mps2"]
            verdict = self.safety.judge(robot_id, linear, footprint, now, decel, angular)
            linear = verdict.linear
            angular = angular if verdict.angular is None else verdict.angular
            self.set_command(robot_id, linear, angular)
            if verdict.noted:  # the bridge's one UPDATE of the row, after the send
                row |= {"safety": verdict.reason, "sent_linear_mps": linear}
                row["sent_angular_rps"] = angular
                self._count(verdict.outcome)
            self._sample(row)
            self.counters.commands_out += 1
            self.watchdog.feed(robot_id, now)
            self.on_applied(Applied(robot_id, linear, angular, row["stamp"]))
            sent += 1
        return sent

    def tick(self, now: float) -> None:
        """The watchdog: a robot with no fresh command for 0.5 s of sim time is stopped."""
        for robot_id, _age in self.watchdog.expired(now):
            self.set_command(robot_id, 0.0, 0.0)
            self.safety.sent_stop(robot_id)
            self.counters.watchdog_stops += 1
            self.on_applied(Applied(robot_id, 0.0, 0.0, None))

    def _count(self, outcome: str) -> None:
        if outcome == STOPPED:
            self.counters.safety_stopped += 1
        elif outcome == LIMITED:
            self.counters.safety_limited += 1
        elif outcome == UNCHECKED:
            self.counters.safety_unchecked += 1

    def _sample(self, command: Row) -> None:
        rec_id = command["recommendation_id"]
        if rec_id is None or rec_id in self._obeyed:
            return
        self._obeyed.add(rec_id)
        rec = self.contract[keys.COMMAND_RECOMMENDATION].by_id.get(rec_id)
        origin = origin_of(rec["inputs"]) if rec is not None else None
        if origin is None:
            return
        table, _kind, row_id = origin
        source = _find(self.contract, table, command["robot_id"], row_id)
        if source is not None:
            self.counters.latency_ms.append((time.perf_counter() - source["produced"]) * 1e3)


def _find(contract: MemoryContract, table: str, robot_id: str, row_id: int) -> Row | None:
    for row in contract[table].rows(robot_id, newest_first=True):
        if row["id"] == row_id:
            return row
        if row["id"] < row_id:
            break
    return None


def _row(record: SensorRecord) -> Row:
    """The contract row the bridge's writer inserts for ``record`` (no id yet): its sensor
    table's image, but a scan's ranges one float32 array (real[]) every reader shares."""
    row = SENSOR_TABLES[type(record)].image(record)
    if isinstance(record, LaserScan):
        ranges = record.values().astype(np.float32)
        ranges.flags.writeable = False  # shared by every reader of the row: never changed
        row["ranges"] = ranges
    return row
