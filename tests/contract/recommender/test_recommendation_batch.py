"""The recommendations of one activation in one statement (common/contract/recommendations.py).

A recommender queues every robot's rows while its rules run and writes them together at the
end of the activation. What must hold for each row all the same: its values, its own
notification with its own id and image (the decision keeps the live rows from them), in the
order queued; a row the database refuses costs only itself.
"""

from __future__ import annotations

from typing import Any

import pytest

from common import bus
from common.bus import Notification
from common.contract import keys
from common.contract.recommendations import (
    RecommendationBatch,
    RecommendationsRefused,
    VelocityRow,
)
from common.runtime import Runtime
from common.testing import eventually

NOT_IN_THE_IMAGE = ("created_at", "treated_by")


def row(robot_id: str, source: str, linear: float = 0.1, priority: int = 10) -> VelocityRow:
    return VelocityRow(
        robot_id, source, priority, linear, 0.2, 10.0, 0.5, f"{source} for {robot_id}",
        {"laser_scan": 7},
    )  # fmt: skip


async def add_robots(client: Runtime, *robots: str) -> None:
    for robot_id in robots:
        await client.database.pool.execute("INSERT INTO robot (robot_id) VALUES ($1)", robot_id)


async def rows(client: Runtime) -> list[dict[str, Any]]:
    sql = "SELECT *, xmin::text AS tx FROM command_recommendation ORDER BY id"
    return [dict(r) for r in await client.database.pool.fetch(sql)]


async def test_every_robots_rows_go_in_one_commit_each_with_its_own_image(
    client: Runtime,
) -> None:
    heard: list[Notification] = []
    watch = bus.subscribe(
        client.zenoh,
        keys.notify_watch(keys.COMMAND_RECOMMENDATION),
        lambda key, payload: heard.append(Notification.decode(key, payload)),
    )
    try:
        await add_robots(client, "r1", "r2", "r3")
        batch = RecommendationBatch(client.database)
        queued = [row("r1", "avoid"), row("r1", "safety_stop", 0.0), row("r2", "avoid", 0.3)]
        queued.append(row("r3", "dwa", 0.4))
        for r in queued:
            batch.add(r)
        assert await rows(client) == []  # queued, not written
        ids = await batch.flush()
        assert batch.pending == [] and batch.statements == 1 and batch.rows == 4
        written = await rows(client)
        assert [r["id"] for r in written] == ids
        assert len({r["tx"] for r in written}) == 1  # one statement, one transaction
        for r, db_row in zip(queued, written, strict=True):
            expected = {**r.image(), "id": db_row["id"]}
            assert {k: db_row[k] for k in expected} == expected
        await eventually(lambda: len(heard) == 4, what="a notification per row")
        assert [n.id for n in heard] == ids
        for note, db_row in zip(heard, written, strict=True):
            assert note.robot == db_row["robot_id"]
            image = {k: v for k, v in db_row.items() if k not in (*NOT_IN_THE_IMAGE, "tx")}
            assert note.row == image
    finally:
        watch.undeclare()


async def test_one_row_alone_keeps_the_single_row_statement(client: Runtime) -> None:
    await add_robots(client, "r1")
    batch = RecommendationBatch(client.database)
    batch.add(row("r1", "avoid"))
    [row_id] = await batch.flush()
    assert row_id is not None and batch.statements == 1 and batch.rows == 1
    assert await batch.flush() == []  # nothing queued: nothing written
    assert batch.statements == 1


async def test_a_refused_row_costs_only_itself(client: Runtime) -> None:
    await add_robots(client, "r1", "r2")
    batch = RecommendationBatch(client.database)
    batch.add(row("r1", "avoid"))
    batch.add(row("ghost", "avoid"))  # no such robot: the foreign key refuses it
    batch.add(row("r2", "avoid", priority=5000))  # beyond the contract's priorities
    batch.add(row("r2", "dwa"))
    refused = r"avoid for ghost: ForeignKey.*; avoid for r2: CheckViolation"
    with pytest.raises(RecommendationsRefused, match=refused):
        await batch.flush()
    written = await rows(client)
    assert [(r["robot_id"], r["source"]) for r in written] == [("r1", "avoid"), ("r2", "dwa")]
    assert batch.pending == []
