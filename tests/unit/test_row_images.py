"""Notifications that carry the committed row (docs/ARCHITECTURE.md): encoding, the write that
sends them, numbering per publisher and key, and the gap a reader sees."""

from __future__ import annotations

import asyncio
import contextlib

from common import bus
from common.bus import Notification
from common.config import DATA_QUEUE_BATCHES, ZenohSettings
from common.contract import keys
from common.db import Database, create_pool
from common.freshness import Sequences
from pnav._testing import eventually

GOAL_KEY = keys.notify_key(keys.GOAL, "r1")


def test_an_image_travels_with_its_row_id_and_nothing_else_is_taken_for_one() -> None:
    note = Notification(keys.GOAL, "r1", 7, {"id": 7, "x": 1.5}, "ab12", 3)
    back = Notification.decode(GOAL_KEY, note.encode())
    assert back == note
    # an image naming another row, or no row id at all, is not an image of this change
    stray = Notification(keys.GOAL, "r1", 7, {"id": 6, "x": 1.5}).encode()
    assert Notification.decode(GOAL_KEY, stray).row is None
    idless = Notification(keys.GOAL, "r1", None, {"id": 6}).encode()
    assert Notification.decode(GOAL_KEY, idless).row is None
    # a hint from a client that knows nothing of images still reads
    plain = bus.pack({"table": keys.GOAL, "robot": "r1", "id": 9})
    assert Notification.decode(GOAL_KEY, plain) == Notification(keys.GOAL, "r1", 9)


def test_a_skipped_seq_from_one_publisher_is_a_gap_and_other_publishers_are_apart() -> None:
    seqs = Sequences()
    assert not seqs.gap(GOAL_KEY, "a", 5)  # the first heard from "a": no gap
    assert not seqs.gap(GOAL_KEY, "a", 6)
    assert not seqs.gap(GOAL_KEY, "b", 1)  # another publisher counts on its own
    assert seqs.gap(GOAL_KEY, "a", 8)  # 7 never came
    assert not seqs.gap(GOAL_KEY, "a", 9)
    assert seqs.gap(GOAL_KEY, None, None)  # unnumbered: nothing can be known


def test_the_notifications_skipped_are_counted_lost() -> None:
    seqs = Sequences()
    seqs.gap(GOAL_KEY, "a", 1)  # lost: 0 (the first heard from "a")
    seqs.gap(GOAL_KEY, "a", 4)  # lost: 2 (2 and 3)
    seqs.gap(GOAL_KEY, "b", 9)  # lost: 2 (the first from "b" says nothing of 1 to 8)
    seqs.gap(GOAL_KEY, "a", 3)  # lost: 2 (late: already counted when 4 came)
    seqs.gap(GOAL_KEY, "a", 5)  # lost: 2
    seqs.gap(GOAL_KEY, None, None)  # lost: 2 (unnumbered: nothing to count)
    seqs.gap(GOAL_KEY, "b", 12)  # lost: 4 (10 and 11)
    assert seqs.lost == 4


async def test_a_write_with_an_image_notifies_it_with_the_committed_id(
    db_url: str, zenoh_settings: ZenohSettings
) -> None:
    got: asyncio.Queue[Notification] = asyncio.Queue()
    session = bus.open_session(zenoh_settings)
    sub = bus.subscribe(
        session,
        keys.notify_watch(keys.ROBOT),
        lambda key, payload: got.put_nowait(Notification.decode(key, payload)),
    )
    pool = await create_pool(db_url, max_size=2)
    plain = Database(pool, bus.Notifier(session, images=False))
    imaged = Database(pool, bus.Notifier(session))
    try:
        sql = "INSERT INTO robot (robot_id) VALUES ($1) RETURNING 41"
        await imaged.write(keys.ROBOT, "r1", sql, "r1", image={"robot_id": "r1"})
        first = await asyncio.wait_for(got.get(), 10)
        assert (first.id, first.row, first.seq) == (41, {"robot_id": "r1", "id": 41}, 1)
        await plain.write(keys.ROBOT, "r2", sql, "r2", image={"robot_id": "r2"})
        second = await asyncio.wait_for(got.get(), 10)
        assert (second.id, second.row) == (41, None)  # PNAV_NOTIFY_IMAGES=off: a hint only
        assert first.src != second.src  # two notifiers, two publishers
    finally:
        sub.undeclare()
        await plain.lane.close()  # each Database holds a pool connection between statements
        await imaged.lane.close()
        await pool.close()
        session.close()


async def test_the_first_notification_on_a_fresh_key_is_not_lost(
    zenoh_settings: ZenohSettings,
) -> None:
    # A fresh publisher's first put used to be dropped about half the time (writer-side
    # filtering until the router answers its interest): every robot's first row unannounced.
    # In bursts of half the link's queue, each waited for: a longer burst (kept whole by
    # congestion control BLOCK) is tests/contract/decision/test_notification_burst.py.
    got: set[str] = set()
    listener = bus.open_session(zenoh_settings)
    sub = bus.subscribe_threaded(
        listener, keys.notify_watch(keys.ODOMETRY), lambda key, _payload: got.add(key)
    )
    writer = bus.open_session(zenoh_settings)
    try:
        await asyncio.sleep(1.0)  # the subscription reaches the router
        notifier = bus.Notifier(writer)
        robots = [f"r{i}" for i in range(60)]
        burst = DATA_QUEUE_BATCHES // 2
        for start in range(0, len(robots), burst):
            sent = robots[start : start + burst]
            for robot in sent:
                notifier.notify(keys.ODOMETRY, robot, 1, {"robot_id": robot, "id": 1})
            wanted = {keys.notify_key(keys.ODOMETRY, r) for r in sent}
            with contextlib.suppress(AssertionError):  # the assertion below names the lost
                await eventually(lambda wanted=wanted: wanted <= got, within=2.0, what="notes")
        assert sorted(got) == sorted(keys.notify_key(keys.ODOMETRY, r) for r in robots)
        notifier.close()
    finally:
        sub.undeclare()
        listener.close()
        writer.close()
