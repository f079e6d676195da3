"""Every contract table name and every Zenoh key expression, in one place.

A service in any language can rebuild these from CONTRACT.md; Python code must take them
from here so a rename is one edit.

Key expressions (``{robot}`` is a robot id; ids are ``[A-Za-z0-9_-]+``):

- ``pnav/db/{table}/{robot}``     change notification after a committed write (hint only)
- ``pnav/db/{table}/_``           the same for tables that are not robot-scoped
- ``pnav/robot/{robot}/scan``     sim -> bridge, lidar scan
- ``pnav/robot/{robot}/odom``     sim -> bridge, odometry
- ``pnav/robot/{robot}/battery``  sim -> bridge, battery state
- ``pnav/robot/{robot}/collision`` sim -> bridge, contact event
- ``pnav/robot/{robot}/collision_ack`` bridge -> sim, a collision event is committed
- ``pnav/robot/{robot}/cmd_vel``  bridge -> sim, velocity command
- ``pnav/sim/clock``              sim time
- ``pnav/sim/world``              the loaded world (map, chargers, robots); also a queryable
- ``pnav/sim/run``                people -> a held sim (``--held``): run to a sim time, or on
- ``pnav/alive/{service}/{instance}`` liveliness token of a running service
- ``pnav/lockstep/{service}/{instance}`` a participant's quiet report (lockstep runs only)
- ``pnav/supervisor/{launcher}``  a launcher's report of the processes it supervises
"""

from __future__ import annotations

import re
from typing import Final

PREFIX: Final = "pnav"

# -- tables ------------------------------------------------------------------------------
SCHEMA_VERSION: Final = "schema_version"
ROBOT: Final = "robot"
ODOMETRY: Final = "odometry"
LASER_SCAN: Final = "laser_scan"
BATTERY: Final = "battery"
COLLISION_EVENT: Final = "collision_event"
MAP: Final = "map"
CHARGING_STATION: Final = "charging_station"
GOAL: Final = "goal"
GOAL_WAYPOINT: Final = "goal_waypoint"
USER_COMMAND: Final = "user_command"
STRATEGY: Final = "strategy"
ACTIVE_STRATEGY: Final = "active_strategy"
COMMAND_RECOMMENDATION: Final = "command_recommendation"
COMMAND2ROBOT: Final = "command2robot"
SYSTEM_COMMAND: Final = "system_command"
ENGINE_STATS: Final = "engine_stats"
RETENTION_POLICY: Final = "retention_policy"
ROBOT_LEASE: Final = "robot_lease"
PLANNED_PATH: Final = "planned_path"
SCENARIO_OFFER: Final = "scenario_offer"
ZONE: Final = "zone"
MODEL: Final = "model"

TABLES: Final = (
    SCHEMA_VERSION,
    ROBOT,
    ODOMETRY,
    LASER_SCAN,
    BATTERY,
    COLLISION_EVENT,
    MAP,
    CHARGING_STATION,
    GOAL,
    GOAL_WAYPOINT,
    USER_COMMAND,
    STRATEGY,
    ACTIVE_STRATEGY,
    COMMAND_RECOMMENDATION,
    COMMAND2ROBOT,
    SYSTEM_COMMAND,
    ENGINE_STATS,
    RETENTION_POLICY,
    ROBOT_LEASE,
    PLANNED_PATH,
    SCENARIO_OFFER,
    ZONE,
    MODEL,
)

# Tables written at sensor rate; the retention policy keeps them bounded.
SENSOR_TABLES: Final = (ODOMETRY, LASER_SCAN, BATTERY, COLLISION_EVENT)

# Stands for "no robot" in a notification key of a table that is not robot-scoped.
GLOBAL: Final = "_"

_ID = re.compile(r"^[A-Za-z0-9_-]+$")


def valid_id(value: str) -> bool:
    """A robot, service or instance id that is safe inside one key-expression chunk."""
    return bool(_ID.match(value))


# -- change notifications ----------------------------------------------------------------
def notify_key(table: str, robot: str | None = None) -> str:
    return f"{PREFIX}/db/{table}/{robot or GLOBAL}"


def notify_watch(table: str) -> str:
    """Key expression matching every notification of ``table``, for all robots."""
    return f"{PREFIX}/db/{table}/*"


NOTIFY_ALL: Final = f"{PREFIX}/db/**"


def parse_notify_key(key: str) -> tuple[str, str | None]:
    """``pnav/db/odometry/r1`` -> ``("odometry", "r1")``; the global robot maps to None."""
    parts = key.split("/")
    if len(parts) != 4 or parts[0] != PREFIX or parts[1] != "db":
        raise ValueError(f"not a notification key: {key!r}")
    return parts[2], (None if parts[3] == GLOBAL else parts[3])


# -- robot <-> bridge ------------------------------------------------------------------
SCAN: Final = "scan"
ODOM: Final = "odom"
BATTERY_MSG: Final = "battery"
COLLISION: Final = "collision"
CMD_VEL: Final = "cmd_vel"
# bridge -> sim: a collision event is committed; the robot stops resending it
COLLISION_ACK: Final = "collision_ack"
SENSOR_TOPICS: Final = (SCAN, ODOM, BATTERY_MSG, COLLISION)


def robot_key(robot: str, topic: str) -> str:
    return f"{PREFIX}/robot/{robot}/{topic}"


def robot_watch(topic: str) -> str:
    """Key expression matching ``topic`` for every robot."""
    return f"{PREFIX}/robot/*/{topic}"


def parse_robot_key(key: str) -> tuple[str, str]:
    """``pnav/robot/r1/scan`` -> ``("r1", "scan")``."""
    parts = key.split("/")
    if len(parts) != 4 or parts[0] != PREFIX or parts[1] != "robot":
        raise ValueError(f"not a robot key: {key!r}")
    return parts[2], parts[3]


SIM_CLOCK: Final = f"{PREFIX}/sim/clock"
SIM_WORLD: Final = f"{PREFIX}/sim/world"
SIM_RUN: Final = f"{PREFIX}/sim/run"


# -- liveliness --------------------------------------------------------------------------
def alive_key(service: str, instance: str) -> str:
    return f"{PREFIX}/alive/{service}/{instance}"


def alive_watch(service: str | None = None) -> str:
    return f"{PREFIX}/alive/{service or '*'}/*"


# -- lockstep with the sim (common/lockstep.py, services/sim/lockstep_barrier.py) --------
def lockstep_key(service: str, instance: str) -> str:
    return f"{PREFIX}/lockstep/{service}/{instance}"


LOCKSTEP_WATCH: Final = f"{PREFIX}/lockstep/*/*"


def parse_lockstep_key(key: str) -> tuple[str, str]:
    """``pnav/lockstep/planner/host-12`` -> ``("planner", "host-12")``."""
    parts = key.split("/")
    if len(parts) != 4 or parts[0] != PREFIX or parts[1] != "lockstep":
        raise ValueError(f"not a lockstep key: {key!r}")
    return parts[2], parts[3]


# -- robot leases (migration 2) ------------------------------------------------------------
# SQL functions of the contract a replica calls on its one lock connection.
LEASE_KEY_FN: Final = "lease_key"
LEASE_ACQUIRE_FN: Final = "robot_lease_acquire"
LEASE_RELEASE_FN: Final = "robot_lease_release"
# robot -> holder, then the live replicas, counting only sessions that may hold leases
# (migration 10)
LEASE_HOLDERS_FN: Final = "robot_lease_holders"
# The second key of the shared advisory lock every live replica of a service holds.
LEASE_MEMBER_KEY: Final = 0


# -- the launcher's supervisor (pnav up / pnav demo): restarts, for /metrics ----------------
def supervisor_key(launcher: str) -> str:
    return f"{PREFIX}/supervisor/{launcher}"


SUPERVISOR_WATCH: Final = f"{PREFIX}/supervisor/*"
