"""The contract tables' columns, declared once with the bounds their CHECKs enforce.

schema.sql is the authority; a :class:`Table` here says the same in Python so that a reader
can hold a row image (CONTRACT.md "Row images") to the rules the table holds its rows to:
an image that names another robot than its key, a priority-1000 forward command, a NaN
stamp, an id no sequence gives, is refused before any reader acts on it. Each bound is
declared beside its column, with the constraint(s) that enforce it in the database;
tests/contract/test_table_bounds.py writes a row just outside each bound (the database must
refuse it, with one of those constraints) and just inside (it must accept it), so this
declaration cannot drift from schema.sql unnoticed.

A bound with no constraint (``checks=()``) is the documented writer's rule, not the table's:
command2robot has no CHECK (its reader, the bridge, clamps what it reads), but its one
writer, the decision, copies every velocity from a recommendation the table bounded, so an
image beyond those bounds did not come from it. The test checks that the database accepts
such a value, so a writer's rule is never mistaken for the table's.

Only the tables whose images a shipped reader acts on are declared (:data:`IMAGED`); the
declaration (common.contract.columns) is meant to grow to every table (its columns, types,
defaults) when the contract is generated from one place.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Final

from common.contract import keys, limits
from common.contract.columns import (
    BOOL,
    FLOAT,
    FLOATS,
    ID,
    INT,
    INTS,
    JSON,
    ROBOT_ID,
    TEXT,
    TIMESTAMP,
    Column,
    Rule,
    Table,
)


def _id(name: str = "id", *, nullable: bool = False, inserted: bool = True) -> Column:
    # the row's own id comes from its sequence: never in an INSERT
    return Column(name, ID, nullable=nullable, inserted=inserted and name != "id")


def _clock(name: str) -> Column:
    # received_at / created_at: the database's clock (a default), never in an image
    return Column(name, TIMESTAMP, inserted=False)


def _seq() -> Column:
    return Column("seq", INT, sql="bigint")


def _robot() -> Column:
    # robot_id references robot, whose CHECK is the pattern
    return Column("robot_id", TEXT, pattern=ROBOT_ID, checks=("robot_robot_id_check",))


def _finite(name: str, check: str, *, nullable: bool = False) -> Column:
    return Column(name, FLOAT, nullable=nullable, finite=True, checks=(check,))


# -- command_recommendation (migration 1, bounded by migration 3) -------------------------------
_REC = "command_recommendation"
_REC_VELOCITY = f"{_REC}_velocity_bounded"


def _safety_band(image: Mapping[str, Any]) -> bool:
    # from SAFETY_PRIORITY up, only a robot command that stops travel (CONTRACT.md)
    return bool(
        image["priority"] < limits.SAFETY_PRIORITY
        or (image["kind"] == "robot" and image["linear_mps"] == 0)
    )


COMMAND_RECOMMENDATION: Final = Table(
    keys.COMMAND_RECOMMENDATION,
    (
        _id(),
        _robot(),
        Column("kind", TEXT, choices=("robot", "system"), checks=(f"{_REC}_kind_check",)),
        Column("source", TEXT),
        Column(
            "priority",
            INT,
            low=limits.MIN_PRIORITY,
            high=limits.MAX_PRIORITY,
            checks=(f"{_REC}_priority_bounded",),
        ),
        Column(
            "linear_mps",
            FLOAT,
            nullable=True,
            abs_high=limits.MAX_ABS_LINEAR_MPS,
            checks=(_REC_VELOCITY,),
        ),
        Column(
            "angular_rps",
            FLOAT,
            nullable=True,
            abs_high=limits.MAX_ABS_ANGULAR_RPS,
            checks=(_REC_VELOCITY,),
        ),
        Column("system_command", TEXT, nullable=True),
        # NaN also breaks expires_stamp >= stamp, which Postgres may report first
        Column("stamp", FLOAT, finite=True, checks=(f"{_REC}_stamps_finite", f"{_REC}_check")),
        Column(
            "expires_stamp", FLOAT, finite=True, checks=(f"{_REC}_stamps_finite", f"{_REC}_check")
        ),
        Column("inputs", JSON),
        Column("reason", TEXT),
        _id("treated_by", nullable=True, inserted=False),  # the decision's UPDATE sets it
        _clock("created_at"),
    ),
    (
        Rule(
            "priority from 100 up must be a robot command that stops (the safety band)",
            _safety_band,
            (f"{_REC}_safety_band",),
            refuses=(
                {"priority": limits.SAFETY_PRIORITY, "linear_mps": 0.01},
                {"priority": limits.MAX_PRIORITY, "linear_mps": -0.2},
            ),
            accepts=(
                {"priority": limits.SAFETY_PRIORITY - 1, "linear_mps": 0.2},
                {"priority": limits.MAX_PRIORITY, "linear_mps": 0.0, "angular_rps": 1.0},
            ),
        ),
        Rule(
            "expires_stamp before stamp",
            lambda r: r["expires_stamp"] >= r["stamp"],
            (f"{_REC}_check",),
            refuses=({"stamp": 10.0, "expires_stamp": 9.99},),
            accepts=({"stamp": 10.0, "expires_stamp": 10.0},),
        ),
        Rule(
            "a robot recommendation without its velocity",
            lambda r: (
                r["kind"] != "robot"
                or (r["linear_mps"] is not None and r["angular_rps"] is not None)
            ),
            (f"{_REC}_check1",),
            refuses=({"linear_mps": None}, {"angular_rps": None}),
        ),
        Rule(
            "a system recommendation without its command",
            lambda r: r["kind"] != "system" or r["system_command"] is not None,
            (f"{_REC}_check2",),
            refuses=(
                {
                    "kind": "system",
                    "linear_mps": None,
                    "angular_rps": None,
                    "system_command": None,
                },
            ),
            accepts=(
                {
                    "kind": "system",
                    "linear_mps": None,
                    "angular_rps": None,
                    "system_command": "CMD_BATTSAVE",
                },
            ),
        ),
    ),
)

# -- command2robot: no CHECK; its writer's rules (see the module) -------------------------------


def _cites_what_it_considered(image: Mapping[str, Any]) -> bool:
    # the decision's winner is always one of the rows it considered
    rec = image.get("recommendation_id")
    return rec is None or "considered_ids" not in image or rec in image["considered_ids"]


COMMAND2ROBOT: Final = Table(
    keys.COMMAND2ROBOT,
    (
        _id(),
        _robot(),
        Column("stamp", FLOAT, finite=True),
        Column("linear_mps", FLOAT, abs_high=limits.MAX_ABS_LINEAR_MPS),
        Column("angular_rps", FLOAT, abs_high=limits.MAX_ABS_ANGULAR_RPS),
        _id("recommendation_id", nullable=True),
        Column("source", TEXT, nullable=True),
        Column("considered_ids", INTS),
        Column("reason", TEXT),
        _clock("created_at"),
        # migration 4: what the bridge's safety layer did with it (its one UPDATE)
        Column("safety", TEXT, nullable=True, inserted=False),
        Column("sent_linear_mps", FLOAT, nullable=True, inserted=False),
        Column("sent_angular_rps", FLOAT, nullable=True, inserted=False),
    ),
    (
        Rule(
            "a command whose recommendation is not among those it considered",
            _cites_what_it_considered,
            refuses=({"recommendation_id": 8, "considered_ids": [7]},),
            accepts=({"recommendation_id": None, "considered_ids": [4, 5]},),
        ),
    ),
)

# -- sensor rows (writer: the bridge) ----------------------------------------------------------
ODOMETRY: Final = Table(
    keys.ODOMETRY,
    (
        _id(),
        _robot(),
        _finite("stamp", "odometry_finite"),
        _seq(),
        *(
            _finite(name, "odometry_finite")
            for name in ("x", "y", "yaw", "linear_mps", "angular_rps")
        ),
        _clock("received_at"),
    ),
)

LASER_SCAN: Final = Table(
    keys.LASER_SCAN,
    (
        _id(),
        _robot(),
        _finite("stamp", "laser_scan_finite"),
        _seq(),
        *(
            _finite(name, "laser_scan_finite")
            for name in ("angle_min", "angle_increment", "range_min", "range_max")
        ),
        Column("ranges", FLOATS, sql="real[]"),  # Infinity kept: "nothing within range_max"
        _clock("received_at"),
    ),
)

BATTERY: Final = Table(
    keys.BATTERY,
    (
        _id(),
        _robot(),
        _finite("stamp", "battery_finite"),
        Column(
            "energy_wh",
            FLOAT,
            finite=True,
            low=0.0,
            checks=("battery_finite", "battery_energy_wh_check"),
        ),
        Column(
            "capacity_wh",
            FLOAT,
            finite=True,
            low=0.0,
            low_open=True,
            checks=("battery_finite", "battery_capacity_wh_check"),
        ),
        Column("percentage", FLOAT, low=0.0, high=100.0, checks=("battery_percentage_check",)),
        Column("charging", BOOL),
        _finite("power_w", "battery_finite"),
        _clock("received_at"),
    ),
)

# -- planned_path (writer: the planner; migration 6) -------------------------------------------
PLANNED_PATH: Final = Table(
    keys.PLANNED_PATH,
    (
        _id(),
        _robot(),
        _finite("stamp", "planned_path_stamp_check"),
        _id("goal_id", nullable=True),
        Column(
            "target",
            TEXT,
            choices=("goal", "charger", "none"),
            checks=("planned_path_target_check",),
        ),
        Column(
            "target_x",
            FLOAT,
            nullable=True,
            abs_high=limits.GOAL_MAX_ABS_M,
            checks=("planned_path_target_x_check",),
        ),
        Column(
            "target_y",
            FLOAT,
            nullable=True,
            abs_high=limits.GOAL_MAX_ABS_M,
            checks=("planned_path_target_y_check",),
        ),
        Column("xs", FLOATS),
        Column("ys", FLOATS),
        Column("length_m", FLOAT, finite=True, low=0.0, checks=("planned_path_length_m_check",)),
        _clock("created_at"),
    ),
    (
        Rule(
            "xs and ys of different lengths, or more than 100000 points",
            lambda r: len(r["xs"]) == len(r["ys"]) <= 100_000,
            ("planned_path_points",),
            refuses=({"xs": [0.0, 1.0], "ys": [0.0]},),
            accepts=({"xs": [0.0, 1.0], "ys": [0.0, 1.0]},),
        ),
    ),
)

# -- collision_event (writer: the bridge; an event, durable, written once per (robot, run, seq))
COLLISION_EVENT: Final = Table(
    keys.COLLISION_EVENT,
    (
        _id(),
        _robot(),
        _finite("stamp", "collision_event_finite"),
        Column("other", TEXT),
        _finite("x", "collision_event_finite"),
        _finite("y", "collision_event_finite"),
        _clock("received_at"),
        # migration 7: NULL in rows older than it, and from writers that send no run
        Column(
            "seq", INT, nullable=True, low=0, sql="bigint", checks=("collision_event_seq_check",)
        ),
        Column("run", TEXT, nullable=True, checks=("collision_event_run_check",)),
    ),
)

# The tables whose row images a shipped reader acts on, by name.
IMAGED: Final[Mapping[str, Table]] = {
    t.name: t
    for t in (COMMAND_RECOMMENDATION, COMMAND2ROBOT, ODOMETRY, LASER_SCAN, BATTERY, PLANNED_PATH)
}

# Every declared table, by name: tests/contract/test_declared_tables.py holds each to the
# live schema (the same columns, types and nullability, in the same order).
DECLARED: Final[Mapping[str, Table]] = {**IMAGED, COLLISION_EVENT.name: COLLISION_EVENT}
