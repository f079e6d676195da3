"""A command2robot row as the relay reads it (command_relay.py): the newest row per robot joined
with the robot's limits, from the table (:data:`NEWEST`) or from the row's image
(:meth:`Command.from_image`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import asyncpg

from common.contract import keys
from common.footprint import Footprint
from services.bridge.robot_limits import Limits, limits_of

# LATERAL + LIMIT 1 walks the (robot_id, id DESC) index once per robot: the cost stays flat
# however long command2robot grows (it is not a pruned sensor table).
NEWEST = f"""
SELECT r.robot_id, c.id, c.stamp, c.linear_mps, c.angular_rps,
       r.max_linear_mps, r.max_angular_rps, r.footprint_radius_m, r.footprint_polygon,
       r.max_linear_accel_mps2
FROM {keys.ROBOT} r
CROSS JOIN LATERAL (
    SELECT id, stamp, linear_mps, angular_rps FROM {keys.COMMAND2ROBOT} c
    WHERE c.robot_id = r.robot_id ORDER BY c.id DESC LIMIT 1
) c"""
NEWEST_OF = NEWEST + "\nWHERE r.robot_id = ANY($1::text[])"


@dataclass(frozen=True, slots=True)
class Command:
    robot_id: str
    id: int
    stamp: float
    linear: float
    angular: float
    max_linear: float
    max_angular: float
    footprint: Footprint  # its polygon, or the disc of its radius
    max_accel: float  # the robot's linear acceleration limit: it brakes no harder

    @classmethod
    def from_row(cls, row: asyncpg.Record) -> Command:
        values = tuple(row)
        max_linear, max_angular, footprint, max_accel = limits_of(values[5:])
        robot, row_id, stamp, linear, angular = values[:5]
        return cls(
            robot, row_id, stamp, linear, angular, max_linear, max_angular, footprint, max_accel
        )

    @classmethod
    def from_image(cls, robot: str, image: Mapping[str, Any], limits: Limits) -> Command | None:
        """The command of a command2robot image, or None if the image lacks a column the
        relay needs (or has a wrong type in it, or names another robot)."""
        row_id = image.get("id")
        if type(row_id) is not int or image.get("robot_id") != robot:
            return None
        values: list[float] = []
        for column in ("stamp", "linear_mps", "angular_rps"):
            value = image.get(column)
            if not isinstance(value, float | int) or isinstance(value, bool):
                return None  # absent, or not a number
            values.append(float(value))
        stamp, linear, angular = values
        return cls(robot, row_id, stamp, linear, angular, *limits)
