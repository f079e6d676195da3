"""The sensor tables as the writer writes them: per table, its batched INSERT, the column
arrays one batch of records becomes, and the image of one row (CONTRACT.md, "Row images"),
all derived from the table's declaration (common.contract.tables, by
common.contract.inserts): a record's attribute is its column's name but where said here.

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
from operator import attrgetter
from typing import Any

import numpy as np

from common.contract import tables
from common.contract.inserts import Insert
from services.bridge.sensor_payloads import (
    BatteryState,
    Collision,
    LaserScan,
    Odometry,
    SensorRecord,
)

Image = dict[str, Any]


def _float32s(record: Any) -> list[float]:
    # real[]: each value rounded to float32 (round to nearest, as the driver and Postgres
    # do), then widened back, so these are the very floats a SELECT returns
    scan: LaserScan = record
    return list(scan.values().astype(np.float32).tolist())


_ODOMETRY = Insert(
    tables.ODOMETRY,
    fields={"linear_mps": attrgetter("linear"), "angular_rps": attrgetter("angular")},
)
_LASER_SCAN = Insert(tables.LASER_SCAN, images={"ranges": _float32s})
_BATTERY = Insert(tables.BATTERY)
_COLLISION = Insert(tables.COLLISION_EVENT)


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


def _sensor_table(
    insert: Insert, *, conflict: str = "", durable: bool = False, replay: bool = True
) -> SensorTable:
    return SensorTable(
        insert.table.name,
        insert.batch_sql(conflict=conflict),
        insert.args,
        insert.image,
        durable=durable,
        replay_sql=insert.replay_sql() if replay else None,
    )


SENSOR_TABLES: dict[type, SensorTable] = {
    Odometry: _sensor_table(_ODOMETRY),
    LaserScan: _sensor_table(_LASER_SCAN),
    BatteryState: _sensor_table(_BATTERY),
    # A resent event (CONTRACT.md, "Robot and sim") finds its row there and adds none;
    # RETURNING then gives fewer rows than the batch, and the writer sends no image.
    Collision: _sensor_table(
        _COLLISION,
        conflict="ON CONFLICT (robot_id, run, seq) DO NOTHING",
        durable=True,
        replay=False,
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
