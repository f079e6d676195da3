"""The sensor tables as the writer writes them: per table, its batched INSERT, the column
arrays one batch of records becomes, and the image of one row (CONTRACT.md, "Row images").

Every batch is ONE statement per table, all robots together:
``INSERT ... SELECT FROM unnest($1::text[], $2::float8[], ...) RETURNING id, robot_id``,
column arrays in, every new id out, which ``executemany`` could not give us (the
notifications need the newest id per robot, and its row). A scan batch sends all ranges as
one flat real[] and each row takes its slice, since Postgres arrays cannot hold rows of
arrays.

An image holds exactly the columns the writer wrote, as the table holds them, so a reader
that builds its record from the image gets the record the SQL read would give: the record's
values go in unchanged (double precision keeps a Python float exactly), except a scan's
``ranges``, a ``real[]``, whose floats are first rounded to float32 as Postgres stores them.
``id`` is added from RETURNING; ``received_at`` is the database's (its default), not written,
so not in the image.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from common.contract import keys
from services.bridge.messages import BatteryState, Collision, LaserScan, Odometry, SensorRecord

Image = dict[str, Any]

_ODOMETRY_SQL = f"""
INSERT INTO {keys.ODOMETRY} (robot_id, stamp, seq, x, y, yaw, linear_mps, angular_rps)
SELECT * FROM unnest($1::text[], $2::float8[], $3::int8[], $4::float8[], $5::float8[],
                     $6::float8[], $7::float8[], $8::float8[])
RETURNING id, robot_id"""

_LASER_SCAN_SQL = f"""
INSERT INTO {keys.LASER_SCAN} (robot_id, stamp, seq, angle_min, angle_increment,
                               range_min, range_max, ranges)
SELECT u.robot_id, u.stamp, u.seq, u.angle_min, u.angle_increment, u.range_min, u.range_max,
       ($8::real[])[u.first:u.last]
FROM unnest($1::text[], $2::float8[], $3::int8[], $4::float8[], $5::float8[], $6::float8[],
            $7::float8[], $9::int4[], $10::int4[])
     AS u(robot_id, stamp, seq, angle_min, angle_increment, range_min, range_max, first, last)
RETURNING id, robot_id"""

_BATTERY_SQL = f"""
INSERT INTO {keys.BATTERY} (robot_id, stamp, energy_wh, capacity_wh, percentage, charging,
                            power_w)
SELECT * FROM unnest($1::text[], $2::float8[], $3::float8[], $4::float8[], $5::float8[],
                     $6::bool[], $7::float8[])
RETURNING id, robot_id"""

# The same rows again with the ids they were given, after a Postgres crash may have lost them
# (replay.py): the ids come last, so the arguments are the INSERT's plus one array.
_ODOMETRY_REPLAY_SQL = f"""
INSERT INTO {keys.ODOMETRY} (robot_id, stamp, seq, x, y, yaw, linear_mps, angular_rps, id)
SELECT * FROM unnest($1::text[], $2::float8[], $3::int8[], $4::float8[], $5::float8[],
                     $6::float8[], $7::float8[], $8::float8[], $9::int8[])
ON CONFLICT (id) DO NOTHING
RETURNING id"""

_LASER_SCAN_REPLAY_SQL = f"""
INSERT INTO {keys.LASER_SCAN} (robot_id, stamp, seq, angle_min, angle_increment,
                               range_min, range_max, ranges, id)
SELECT u.robot_id, u.stamp, u.seq, u.angle_min, u.angle_increment, u.range_min, u.range_max,
       ($8::real[])[u.first:u.last], u.id
FROM unnest($1::text[], $2::float8[], $3::int8[], $4::float8[], $5::float8[], $6::float8[],
            $7::float8[], $9::int4[], $10::int4[], $11::int8[])
     AS u(robot_id, stamp, seq, angle_min, angle_increment, range_min, range_max, first, last,
          id)
ON CONFLICT (id) DO NOTHING
RETURNING id"""

_BATTERY_REPLAY_SQL = f"""
INSERT INTO {keys.BATTERY} (robot_id, stamp, energy_wh, capacity_wh, percentage, charging,
                            power_w, id)
SELECT * FROM unnest($1::text[], $2::float8[], $3::float8[], $4::float8[], $5::float8[],
                     $6::bool[], $7::float8[], $8::int8[])
ON CONFLICT (id) DO NOTHING
RETURNING id"""

# A resent event (CONTRACT.md, "Robot and sim") finds its row there and adds none; RETURNING
# then gives fewer rows than the batch, and the writer sends no image (a plain hint).
_COLLISION_SQL = f"""
INSERT INTO {keys.COLLISION_EVENT} (robot_id, stamp, other, x, y, seq, run)
SELECT * FROM unnest($1::text[], $2::float8[], $3::text[], $4::float8[], $5::float8[],
                     $6::int8[], $7::text[])
ON CONFLICT (robot_id, run, seq) DO NOTHING
RETURNING id, robot_id"""


def _odometry_args(rows: Sequence[Any]) -> list[Any]:
    r: Sequence[Odometry] = rows
    return [
        [o.robot_id for o in r],
        [o.stamp for o in r],
        [o.seq for o in r],
        [o.x for o in r],
        [o.y for o in r],
        [o.yaw for o in r],
        [o.linear for o in r],
        [o.angular for o in r],
    ]


def _odometry_image(record: Any) -> Image:
    o: Odometry = record
    return {
        "robot_id": o.robot_id,
        "stamp": o.stamp,
        "seq": o.seq,
        "x": o.x,
        "y": o.y,
        "yaw": o.yaw,
        "linear_mps": o.linear,
        "angular_rps": o.angular,
    }


def _laser_scan_args(rows: Sequence[Any]) -> list[Any]:
    r: Sequence[LaserScan] = rows
    flat: list[float] = []
    first: list[int] = []
    last: list[int] = []
    for s in r:
        first.append(len(flat) + 1)  # Postgres arrays are 1-based, slices inclusive
        flat.extend(s.ranges)
        last.append(len(flat))
    return [
        [s.robot_id for s in r],
        [s.stamp for s in r],
        [s.seq for s in r],
        [s.angle_min for s in r],
        [s.angle_increment for s in r],
        [s.range_min for s in r],
        [s.range_max for s in r],
        flat,
        first,
        last,
    ]


def _laser_scan_image(record: Any) -> Image:
    s: LaserScan = record
    return {
        "robot_id": s.robot_id,
        "stamp": s.stamp,
        "seq": s.seq,
        "angle_min": s.angle_min,
        "angle_increment": s.angle_increment,
        "range_min": s.range_min,
        "range_max": s.range_max,
        # real[]: each value rounded to float32 (round to nearest, as the driver and Postgres
        # do), then widened back, so these are the very floats a SELECT returns
        "ranges": s.values().astype(np.float32).tolist(),
    }


def _battery_args(rows: Sequence[Any]) -> list[Any]:
    r: Sequence[BatteryState] = rows
    return [
        [b.robot_id for b in r],
        [b.stamp for b in r],
        [b.energy_wh for b in r],
        [b.capacity_wh for b in r],
        [b.percentage for b in r],
        [b.charging for b in r],
        [b.power_w for b in r],
    ]


def _battery_image(record: Any) -> Image:
    b: BatteryState = record
    return {
        "robot_id": b.robot_id,
        "stamp": b.stamp,
        "energy_wh": b.energy_wh,
        "capacity_wh": b.capacity_wh,
        "percentage": b.percentage,
        "charging": b.charging,
        "power_w": b.power_w,
    }


def _collision_args(rows: Sequence[Any]) -> list[Any]:
    r: Sequence[Collision] = rows
    return [
        [c.robot_id for c in r],
        [c.stamp for c in r],
        [c.other for c in r],
        [c.x for c in r],
        [c.y for c in r],
        [c.seq for c in r],
        [c.run for c in r],
    ]


def _collision_image(record: Any) -> Image:
    c: Collision = record
    return {
        "robot_id": c.robot_id,
        "stamp": c.stamp,
        "other": c.other,
        "x": c.x,
        "y": c.y,
        "seq": c.seq,
        "run": c.run,
    }


@dataclass(frozen=True)
class SensorTable:
    """One sensor table: its INSERT, the column arrays of a batch, the image of a record."""

    name: str
    sql: str
    args: Callable[[Sequence[Any]], list[Any]]
    image: Callable[[Any], Image]
    # committed with synchronous_commit on: the robot forgets an event once it is
    # acknowledged, so its row must survive a Postgres crash (writer.py)
    durable: bool = False
    # the other tables commit asynchronously, and the writer restores what a crash lost
    # with this INSERT (replay.py)
    replay_sql: str | None = None


SENSOR_TABLES: dict[type, SensorTable] = {
    Odometry: SensorTable(
        keys.ODOMETRY,
        _ODOMETRY_SQL,
        _odometry_args,
        _odometry_image,
        replay_sql=_ODOMETRY_REPLAY_SQL,
    ),
    LaserScan: SensorTable(
        keys.LASER_SCAN,
        _LASER_SCAN_SQL,
        _laser_scan_args,
        _laser_scan_image,
        replay_sql=_LASER_SCAN_REPLAY_SQL,
    ),
    BatteryState: SensorTable(
        keys.BATTERY, _BATTERY_SQL, _battery_args, _battery_image, replay_sql=_BATTERY_REPLAY_SQL
    ),
    Collision: SensorTable(
        keys.COLLISION_EVENT, _COLLISION_SQL, _collision_args, _collision_image, durable=True
    ),
}


def newest_per_robot(
    spec: SensorTable,
    batch: Sequence[SensorRecord],
    rows: Sequence[tuple[int, str]],
    *,
    images: bool,
) -> list[tuple[str, int, Image | None]]:
    """Per robot of a written batch: its newest id, and that row's image (None when images
    are off, or when RETURNING's rows cannot be paired with the records one to one)."""
    newest: dict[str, tuple[int, int]] = {}  # robot -> (id, position in the batch)
    for i, (row_id, robot_id) in enumerate(rows):
        held = newest.get(robot_id)
        if held is None or row_id > held[0]:
            newest[robot_id] = (row_id, i)
    paired = (
        images
        and len(rows) == len(batch)
        and all(row[1] == record.robot_id for row, record in zip(rows, batch, strict=True))
    )
    return [
        (robot_id, row_id, {"id": row_id, **spec.image(batch[i])} if paired else None)
        for robot_id, (row_id, i) in newest.items()
    ]
