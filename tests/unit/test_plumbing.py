"""Write-and-notify over real Postgres and real Zenoh, across threads and processes."""

from __future__ import annotations

import asyncio
import os
import sys
import textwrap
import threading

import asyncpg
import pytest

from common import bus
from common.config import ZenohSettings
from common.contract import keys
from common.db import Database, create_pool

SUBSCRIBER = textwrap.dedent(
    """
    import sys, threading
    from common import bus
    from common.config import ZenohSettings
    from common.contract import keys
    got = threading.Event()
    def on(key, payload):
        n = bus.Notification.decode(key, payload)
        print(f"{n.table} {n.robot} {n.id}", flush=True)
        got.set()
    session = bus.open_session(ZenohSettings.from_env())
    sub = bus.subscribe_threaded(session, keys.notify_watch(keys.GOAL), on)
    print("ready", flush=True)
    ok = got.wait(20)
    session.close()
    sys.exit(0 if ok else 1)
    """
)


async def make_db(db_url: str, zenoh_settings: ZenohSettings) -> tuple[Database, object]:
    session = bus.open_session(zenoh_settings)
    pool = await create_pool(db_url, max_size=2)
    return Database(pool, bus.Notifier(session)), session


async def add_robot(db: Database, robot: str = "r1") -> None:
    await db.write(keys.ROBOT, robot, "INSERT INTO robot (robot_id) VALUES ($1)", robot)


async def test_write_and_notify_reaches_a_subscriber_in_another_process(
    db_url: str, zenoh_settings: ZenohSettings
) -> None:
    env = {**os.environ, **zenoh_settings.to_env()}
    child = await asyncio.create_subprocess_exec(
        sys.executable, "-c", SUBSCRIBER, env=env, stdout=asyncio.subprocess.PIPE
    )
    db, session = await make_db(db_url, zenoh_settings)
    try:
        assert child.stdout is not None
        line = await asyncio.wait_for(child.stdout.readline(), 20)
        assert line.decode().strip() == "ready"
        await add_robot(db)
        await asyncio.sleep(0.3)  # let the subscriber's declaration reach the router
        goal_id = await db.write(
            keys.GOAL,
            "r1",
            "INSERT INTO goal (robot_id, x, y) VALUES ($1, 1.5, -2.0) RETURNING id",
            "r1",
        )
        line = await asyncio.wait_for(child.stdout.readline(), 20)
        assert line.decode().split() == ["goal", "r1", str(goal_id)]
        assert await asyncio.wait_for(child.wait(), 20) == 0
        # the row was committed before the notification went out
        async with db.pool.acquire() as conn:
            assert await conn.fetchval("SELECT x FROM goal WHERE id = $1", goal_id) == 1.5
    finally:
        if child.returncode is None:
            child.kill()
            await child.wait()
        db.notifier.close()
        await db.close()
        session.close()  # type: ignore[attr-defined]


async def test_a_transaction_notifies_after_commit_and_not_on_rollback(
    db_url: str, zenoh_settings: ZenohSettings
) -> None:
    db, session = await make_db(db_url, zenoh_settings)
    listener = bus.open_session(zenoh_settings)
    received: list[bus.Notification] = []
    got = asyncio.Event()

    def on(key: str, payload: bytes) -> None:
        received.append(bus.Notification.decode(key, payload))
        got.set()

    sub = bus.subscribe(listener, keys.NOTIFY_ALL, on)
    try:
        await asyncio.sleep(0.3)
        with pytest.raises(RuntimeError):
            async with db.transaction() as tx:
                await tx.conn.execute("INSERT INTO robot (robot_id) VALUES ('ghost')")
                tx.changed(keys.ROBOT, "ghost")
                raise RuntimeError("abort")
        async with db.transaction() as tx:
            await tx.conn.execute("INSERT INTO robot (robot_id) VALUES ('r2')")
            tx.changed(keys.ROBOT, "r2")
            for x in (1.0, 2.0):
                gid = await tx.conn.fetchval(
                    "INSERT INTO goal (robot_id, x, y, status) "
                    "VALUES ('r2', $1, 0, 'cancelled') RETURNING id",
                    x,
                )
                tx.changed(keys.GOAL, "r2", gid)
        await asyncio.wait_for(got.wait(), 5)
        await asyncio.sleep(0.2)
        assert {(n.table, n.robot) for n in received} == {("robot", "r2"), ("goal", "r2")}
        goal_note = next(n for n in received if n.table == keys.GOAL)
        assert goal_note.id == gid  # one notification per (table, robot), newest id
        assert all(n.robot != "ghost" for n in received)
        async with db.pool.acquire() as conn:
            assert await conn.fetchval("SELECT count(*) FROM robot WHERE robot_id='ghost'") == 0
    finally:
        sub.undeclare()
        listener.close()
        db.notifier.close()
        await db.close()
        session.close()  # type: ignore[attr-defined]


async def test_subscribe_runs_handlers_on_the_event_loop_thread(
    zenoh_settings: ZenohSettings,
) -> None:
    a, b = bus.open_session(zenoh_settings), bus.open_session(zenoh_settings)
    threads: list[int] = []
    got = asyncio.Event()

    def on(key: str, payload: bytes) -> None:
        threads.append(threading.get_ident())
        got.set()

    sub = bus.subscribe(b, keys.robot_watch(keys.ODOM), on)
    try:
        await asyncio.sleep(0.3)
        a.put(keys.robot_key("r1", keys.ODOM), bus.pack({"x": 1.0}))
        await asyncio.wait_for(got.wait(), 5)
        assert threads == [threading.get_ident()]
    finally:
        sub.undeclare()
        a.close()
        b.close()


async def test_retention_keeps_sensor_tables_bounded(conn: asyncpg.Connection) -> None:
    await conn.execute("INSERT INTO robot (robot_id) VALUES ('r1'), ('r2')")
    await conn.execute("UPDATE retention_policy SET keep_rows_per_robot = 10")
    for robot in ("r1", "r2"):
        await conn.executemany(
            "INSERT INTO odometry (robot_id, stamp, x, y, yaw, linear_mps, angular_rps) "
            "VALUES ($1, $2, 0, 0, 0, 0, 0)",
            [(robot, float(t)) for t in range(25)],
        )
    deleted = await conn.fetchval("SELECT prune_sensor_rows()")
    assert deleted == 30
    rows = await conn.fetch(
        "SELECT robot_id, count(*) AS n, min(stamp) AS oldest FROM odometry GROUP BY robot_id"
    )
    assert {(r["robot_id"], r["n"], r["oldest"]) for r in rows} == {
        ("r1", 10, 15.0),
        ("r2", 10, 15.0),
    }
    assert await conn.fetchval("SELECT prune_sensor_rows()") == 0


async def test_the_contract_refuses_rows_that_break_it(conn: asyncpg.Connection) -> None:
    await conn.execute("INSERT INTO robot (robot_id) VALUES ('r1')")
    await conn.execute("INSERT INTO goal (robot_id, x, y) VALUES ('r1', 1, 1)")
    with pytest.raises(asyncpg.UniqueViolationError):  # one active goal per robot
        await conn.execute("INSERT INTO goal (robot_id, x, y) VALUES ('r1', 2, 2)")
    with pytest.raises(asyncpg.CheckViolationError):  # a robot recommendation needs a velocity
        await conn.execute(
            "INSERT INTO command_recommendation (robot_id, kind, source, priority, stamp,"
            " expires_stamp) VALUES ('r1', 'robot', 'x', 1, 0, 1)"
        )
    with pytest.raises(asyncpg.ForeignKeyViolationError):  # sensors need a known robot
        await conn.execute(
            "INSERT INTO odometry (robot_id, stamp, x, y, yaw, linear_mps, angular_rps)"
            " VALUES ('nobody', 0, 0, 0, 0, 0, 0)"
        )
    with pytest.raises(asyncpg.CheckViolationError):  # robot ids fit one Zenoh key chunk
        await conn.execute("INSERT INTO robot (robot_id) VALUES ('a/b')")
