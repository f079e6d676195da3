"""The decision service with row images (CONTRACT.md "Row images"), against Postgres and
Zenoh: recommendations written as the controller and planner write them
(``recommendations.recommend_velocity``, one row per notification, with its image).

With images the service keeps the live rows from the notifications and decides without
reading the table (its period fallback set out of the way here, so any read would show);
with PNAV_NOTIFY_IMAGES=off for the service and for the test's writes, it reads the table
for each notification and decides the same. Its own command2robot notification carries the
row as committed.
"""

from __future__ import annotations

from dataclasses import replace

import pytest

from common import bus
from common.bus import Notification
from common.config import ServiceConfig
from common.contract import keys, recommendations
from common.runtime import Runtime
from pnav._testing import ClockPlayer, eventually, running_service
from services.decision.service import DecisionService
from services.decision.store import DecisionStore
from tests.contract.decision.test_decision_service import add_robot, clock_at, newest_from

NOT_THE_DECISIONS = ("created_at", "safety", "sent_linear_mps", "sent_angular_rps")


async def recommend(client: Runtime, source: str, priority: int, linear: float) -> int:
    return await recommendations.recommend_velocity(
        client.database,
        "r1",
        source=source,
        priority=priority,
        linear=linear,
        angular=0.0,
        stamp=10.0,
        ttl_s=990.0,
        reason=f"{source} says so",
    )


@pytest.fixture(params=["images", "images off"])
def images(request: pytest.FixtureRequest) -> bool:
    return bool(request.param == "images")


async def test_decided_from_images_without_reading_the_table(
    client: Runtime, clock: ClockPlayer, service_config: ServiceConfig, images: bool
) -> None:
    client.database.notifier.images = images  # the test's writes, as PNAV_NOTIFY_IMAGES says
    heard: list[Notification] = []

    def on_command(key: str, payload: bytes) -> None:
        heard.append(Notification.decode(key, payload))

    watch = bus.subscribe(client.zenoh, keys.notify_watch(keys.COMMAND2ROBOT), on_command)
    await add_robot(client)
    config = replace(service_config, notify_images=images)
    try:
        async with running_service(DecisionService, config) as service:
            store = service.store  # type: ignore[attr-defined]
            assert isinstance(store, DecisionStore)
            await clock_at(service, 10.0)
            store.reread_s = 1e9  # no period read: any read now is for a notification
            reads = store.reads
            low = await recommend(client, "turn_then_move", 10, 0.2)
            first = await newest_from(client, low)
            high = await recommend(client, "avoid_left", 50, 0.05)
            second = await newest_from(client, high)
            assert sorted(second["considered_ids"]) == [low, high]
            assert second["reason"] == (
                "avoid_left (priority 50) over turn_then_move (10): avoid_left says so"
            )
            if images:
                assert store.reads == reads  # both decided from their images
            else:
                assert store.reads >= reads + 2  # a read per notification
            # the notifications of both rows arrive (a fixed sleep missed them under load)
            ids = {first["id"], second["id"]}
            await eventually(lambda: ids <= {n.id for n in heard}, what="command notes")
    finally:
        watch.undeclare()
    by_id = {n.id: n for n in heard}
    for row in (first, second):
        note = by_id[row["id"]]
        if not images:
            assert note.row is None
            continue
        assert note.row is not None
        # created_at is the database's; safety and sent_* are the bridge's, written after it
        # sent the command (CONTRACT.md, command2robot): not part of the decision's image
        written = {k: v for k, v in row.items() if k not in NOT_THE_DECISIONS}
        assert dict(note.row) == written  # the image is the row as committed
