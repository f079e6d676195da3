"""Sense-to-act samples from the provenance every command carries.

A ``cmd_vel`` carries its ``command_id``; that ``command2robot`` row names the
``recommendation_id`` it obeyed; the recommendation's ``inputs`` name the sensor rows it was
decided from (``laser_scan`` and/or ``odometry`` ids); a sensor row keeps the ``seq`` of the
sim message it stores. The sim's trace (common/trace.py) gives the two ends on the wall
clock: when that message left the sim, and when the command reached it. Postgres'
``clock_timestamp()`` columns (``received_at``, ``created_at``) mark the stages between.

The origin of a sample is the input that starts the recommender: the laser scan for a
controller recommendation (the controller wakes on scans; the odometry it also names is
context), otherwise the odometry (the planner wakes on odometry). Each recommendation counts
once, at the first arrival at the sim of any command that obeyed it: the decision service
re-issues a command every 0.1 s sim while its recommendation is live, and those repeats say
nothing about how fast the system reacted.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

# recommendation input name -> (sensor table, sim trace kind)
ORIGINS: tuple[tuple[str, str, str], ...] = (
    ("laser_scan", "laser_scan", "scan"),
    ("odometry", "odometry", "odom"),
)
STAGES = ("sensor_to_row", "row_to_recommendation", "recommendation_to_decision",
          "decision_to_robot")  # fmt: skip


@dataclass(frozen=True)
class Command:
    """A command2robot row joined with the recommendation it obeyed (times: wall s)."""

    command_id: int
    robot_id: str
    recommendation_id: int
    decided_at: float
    source: str
    recommended_at: float
    inputs: Mapping[str, Any]


@dataclass(frozen=True)
class SensorRow:
    table: str
    row_id: int
    robot_id: str
    seq: int
    received_at: float


@dataclass(frozen=True)
class Sample:
    robot_id: str
    source: str
    origin: str  # the sensor table the chain starts from
    published: float  # the sim put the sensor message on Zenoh
    stored: float  # the bridge's INSERT of its row
    recommended: float
    decided: float
    arrived: float  # the command reached the sim

    @property
    def total_ms(self) -> float:
        return (self.arrived - self.published) * 1e3

    def stages_ms(self) -> dict[str, float]:
        marks = (self.published, self.stored, self.recommended, self.decided, self.arrived)
        return {name: (b - a) * 1e3 for name, a, b in zip(STAGES, marks, marks[1:], strict=False)}


def origin_of(inputs: Mapping[str, Any]) -> tuple[str, str, int] | None:
    """(table, trace kind, row id) of the input that started the recommender, if any."""
    for name, table, kind in ORIGINS:
        row = inputs.get(name)
        if isinstance(row, int) and not isinstance(row, bool):
            return table, kind, row
    return None


@dataclass
class Unmatched:
    """Why commands that reached the sim gave no sample (a non-zero count is worth a look)."""

    no_sensor_origin: int = 0  # e.g. a stop with no recommendation behind it
    sensor_row_missing: int = 0  # pruned before the benchmark read it
    publish_not_traced: int = 0


def samples(
    arrivals: Mapping[int, float],
    commands: Iterable[Command],
    rows: Mapping[tuple[str, int], SensorRow],
    published: Mapping[tuple[str, str, int], float],
) -> tuple[list[Sample], Unmatched]:
    """One sample per recommendation that some command obeyed and that reached the sim.

    ``arrivals``: command id -> first arrival at the sim; ``rows``: (table, row id) -> row;
    ``published``: (trace kind, robot, seq) -> when the sim published that message.
    """
    first: dict[int, tuple[float, Command]] = {}
    for cmd in commands:
        arrived = arrivals.get(cmd.command_id)
        if arrived is None:
            continue
        best = first.get(cmd.recommendation_id)
        if best is None or arrived < best[0]:
            first[cmd.recommendation_id] = (arrived, cmd)
    out: list[Sample] = []
    missing = Unmatched()
    for arrived, cmd in first.values():
        origin = origin_of(cmd.inputs)
        if origin is None:
            missing.no_sensor_origin += 1
            continue
        table, kind, row_id = origin
        row = rows.get((table, row_id))
        if row is None:
            missing.sensor_row_missing += 1
            continue
        pub = published.get((kind, row.robot_id, row.seq))
        if pub is None:
            missing.publish_not_traced += 1
            continue
        out.append(
            Sample(
                cmd.robot_id,
                cmd.source,
                table,
                pub,
                row.received_at,
                cmd.recommended_at,
                cmd.decided_at,
                arrived,
            )
        )
    return out, missing


def share_over(values_ms: Iterable[float], limit_ms: float) -> float:
    """The fraction of values strictly above ``limit_ms`` (0 for no values)."""
    values = list(values_ms)
    return sum(v > limit_ms for v in values) / len(values) if values else 0.0
