"""Recommendations of several robots and scenarios in one statement (common/contract/
recommendations.py), on Postgres: what a store that defers its rules' writes to the end of
an activation sends (common.writebehind).

Whatever the batching, each row must be exactly what the one-row write gives: its columns,
an id in the order asked, and a notification with that id and the row's image, heard after
the commit. A row the database refuses costs only itself.
"""

from __future__ import annotations

from typing import Any

import pytest

from common import bus
from common.bus import Notification
from common.contract import keys
from common.contract.recommendations import (
    Recommendation,
    write_recommendation,
    write_recommendations,
)
from common.db import ASYNC_COMMIT
from common.errors import UsageError
from common.runtime import Runtime
from pnav._testing import eventually

NOT_IN_THE_IMAGE = ("created_at", "treated_by", "tx")


async def add_robot(client: Runtime, robot_id: str) -> None:
    await client.database.execute("INSERT INTO robot (robot_id) VALUES ($1)", robot_id)


def velocity(robot_id: str, source: str, linear: float) -> Recommendation:
    return Recommendation.velocity(
        robot_id, source=source, priority=50, linear=linear, angular=-linear, stamp=10.0,
        ttl_s=0.5, reason=f"{source} says {linear}", inputs={"laser_scan": 7, "why": [1, 2]},
    )  # fmt: skip


async def rows(client: Runtime) -> list[dict[str, Any]]:
    sql = "SELECT *, xmin::text AS tx FROM command_recommendation ORDER BY id"
    return [dict(r) for r in await client.database.pool.fetch(sql)]


async def test_a_batch_is_one_commit_with_each_row_as_a_lone_write_gives_it(
    client: Runtime,
) -> None:
    heard: list[Notification] = []
    watch = bus.subscribe(
        client.zenoh,
        keys.notify_watch(keys.COMMAND_RECOMMENDATION),
        lambda key, payload: heard.append(Notification.decode(key, payload)),
    )
    try:
        for robot_id in ("r1", "r2"):
            await add_robot(client, robot_id)
        alone = await write_recommendation(client.database, velocity("r2", "avoid_left", 0.3))
        batch = [
            velocity("r1", "safety_stop", 0.0),
            velocity("r2", "avoid_left", 0.1),  # the same robot and source as the lone row
            velocity("r1", "avoid_left", 0.2),  # one robot, two sources
            Recommendation.system(
                "r2",
                source="battery_check",
                priority=60,
                command="CMD_BATTSAVE",
                stamp=10.0,
                ttl_s=2.0,
                reason="low",
            ),
        ]
        ids = await write_recommendations(client.database, batch)
        written = await rows(client)
        assert [r["id"] for r in written] == [alone, *ids]  # ids in the order asked
        assert alone < ids[0] < ids[1] < ids[2] < ids[3]
        assert len({r["tx"] for r in written[1:]}) == 1  # one statement, one commit
        for row, r in zip(batch, written[1:], strict=True):
            assert {k: v for k, v in r.items() if k not in (*NOT_IN_THE_IMAGE, "id")} == (
                row.image()
            )
        assert written[3]["expires_stamp"] == 10.5 and written[4]["linear_mps"] is None

        def all_heard() -> bool:
            return len(heard) == 5

        await eventually(all_heard, what="one notification per row")
        by_id = {r["id"]: r for r in written}
        for note in heard:
            row = by_id[note.id or 0]
            assert note.robot == row["robot_id"]
            assert note.row == {k: v for k, v in row.items() if k not in NOT_IN_THE_IMAGE}
    finally:
        watch.undeclare()


async def test_a_refused_row_costs_only_itself(client: Runtime) -> None:
    await add_robot(client, "r1")
    # "gone" is no robot (deleted meanwhile, say): its row breaks the foreign key
    ids = await write_recommendations(
        client.database, [velocity("r1", "a", 0.1), velocity("gone", "a", 0.2)]
    )
    assert ids[0] is not None and ids[1] is None
    assert [(r["id"], r["robot_id"]) for r in await rows(client)] == [(ids[0], "r1")]


async def test_a_batch_must_not_repeat_a_robot_and_source(client: Runtime) -> None:
    await add_robot(client, "r1")
    with pytest.raises(UsageError):
        await write_recommendations(
            client.database, [velocity("r1", "a", 0.1), velocity("r1", "a", 0.2)]
        )


async def test_a_recommendation_commits_without_waiting_for_its_wal_and_nothing_else_does(
    client: Runtime,
) -> None:
    # The FROM item the recommendation and planned-path INSERTs carry: the setting holds for
    # the statement's own transaction (Postgres reads it when that transaction commits) and
    # is gone for the next statement on the same connection, which may be a command.
    conn = await client.database.pool.acquire()
    try:
        inside = await conn.fetchval(
            f"SELECT current_setting('synchronous_commit') FROM {ASYNC_COMMIT}"
        )
        after = await conn.fetchval("SELECT current_setting('synchronous_commit')")
    finally:
        await client.database.pool.release(conn)
    assert (inside, after) == ("off", "on")
    # the statements themselves, on the service's lane: written, and the lane's next
    # statement commits synchronously again
    await add_robot(client, "r1")
    ids = [await write_recommendation(client.database, velocity("r1", "avoid_left", 0.2))]
    ids += await write_recommendations(
        client.database, [velocity("r1", "safety_stop", 0.0), velocity("r1", "dwa", 0.3)]
    )
    assert [r["id"] for r in await rows(client)] == ids
    assert await client.database.fetchval("SELECT current_setting('synchronous_commit')") == "on"
