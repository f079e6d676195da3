"""The recorder's SQL: the rows of each recorded table, newer than what it recorded.

A recording wants every row, not only the newest of a burst (a notification names the newest
row; the bridge notifies a batch of sensor rows once), so the recorder reads each table by id
after its notifications: the table is the source of truth (CONTRACT.md, "Row images").
"""

from __future__ import annotations

from typing import Any

import asyncpg

from common.contract import keys

# table -> the columns recorded (append-only tables, read by id)
APPENDED: dict[str, str] = {
    keys.ODOMETRY: "id, robot_id, stamp, x, y, yaw, linear_mps, angular_rps",
    keys.LASER_SCAN: "id, robot_id, stamp, angle_min, angle_increment, range_min, range_max, "
    "ranges",
    keys.BATTERY: "id, robot_id, stamp, energy_wh, capacity_wh, percentage, charging, power_w",
    keys.COLLISION_EVENT: "id, robot_id, stamp, other, x, y",
    keys.COMMAND_RECOMMENDATION: "id, robot_id, kind, source, priority, linear_mps, "
    "angular_rps, system_command, stamp, expires_stamp, inputs, reason",
    keys.COMMAND2ROBOT: "id, robot_id, stamp, linear_mps, angular_rps, recommendation_id, "
    "source, considered_ids, reason",
    keys.PLANNED_PATH: "id, robot_id, stamp, goal_id, target, target_x, target_y, xs, ys, length_m",
}
# tables whose rows change in place: the recorder logs each change of status
GOAL_COLUMNS = "id, robot_id, x, y, tolerance_m, status, reason, stamp, finished_stamp"
USER_COMMAND_COLUMNS = "id, robot_id, command, argument, status, reason"
SYSTEM_COMMAND_COLUMNS = "id, robot_id, command, reason, status, status_reason, stamp"
BATCH = 2000  # rows per read: a recorder far behind catches up over a few reads


class RecordSource:
    def __init__(self, pool: asyncpg.Pool) -> None:
        self.pool = pool

    async def newer(self, table: str, after_id: int) -> list[asyncpg.Record]:
        """Rows of an appended table with ``id > after_id``, oldest first."""
        sql = f"SELECT {APPENDED[table]} FROM {table} WHERE id > $1 ORDER BY id LIMIT {BATCH}"
        rows: list[asyncpg.Record] = await self.pool.fetch(sql, after_id)
        return rows

    async def changed(self, table: str, after_id: int, ids: list[int]) -> list[asyncpg.Record]:
        """Rows of ``goal``, ``user_command`` or ``system_command``: the new ones and those
        named by notifications (a status changed in place)."""
        columns = {
            keys.GOAL: GOAL_COLUMNS,
            keys.USER_COMMAND: USER_COMMAND_COLUMNS,
            keys.SYSTEM_COMMAND: SYSTEM_COMMAND_COLUMNS,
        }[table]
        sql = f"SELECT {columns} FROM {table} WHERE id > $1 OR id = ANY($2) ORDER BY id"
        rows: list[asyncpg.Record] = await self.pool.fetch(sql, after_id, ids)
        return rows

    async def strategies(self) -> list[asyncpg.Record]:
        rows: list[asyncpg.Record] = await self.pool.fetch(
            f"SELECT robot_id, strategy_code, source, stamp FROM {keys.ACTIVE_STRATEGY}"
        )
        return rows

    async def newest_map(self) -> asyncpg.Record | None:
        row: asyncpg.Record | None = await self.pool.fetchrow(
            f"SELECT map_id, resolution_m, origin_x, origin_y, origin_yaw, width, height, grid, "
            f"loaded_at FROM {keys.MAP} ORDER BY loaded_at DESC LIMIT 1"
        )
        return row

    async def stations(self) -> list[asyncpg.Record]:
        rows: list[asyncpg.Record] = await self.pool.fetch(
            f"SELECT station_id, x, y, radius_m FROM {keys.CHARGING_STATION} ORDER BY station_id"
        )
        return rows


def as_dict(row: asyncpg.Record) -> dict[str, Any]:
    return dict(row.items())
