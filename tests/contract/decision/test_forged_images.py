"""Forged command_recommendation images (CONTRACT.md "Row images", "Forged images"): the
decision holds each image to the table's rules before it counts as live, so an image no row
of the table could be (a forward command in the safety band, another robot's row on r1's
key, a NaN stamp) is dropped, counted, and the table read instead: no command cites it.

The forgeries are published as a recommender publishes, numbered after the test's own
notifications (no ``seq`` gap), so nothing but the image's content can give them away.
"""

from __future__ import annotations

import math
from typing import Any

from common.config import ServiceConfig
from common.contract import keys, recommendations
from common.runtime import Runtime
from pnav._testing import ClockPlayer, eventually, running_service
from services.decision.service import DecisionService
from services.decision.store import DecisionStore
from tests.contract.decision.test_decision_service import add_robot, clock_at, newest_from

FORGED_ID = 10**9  # no row has it: a command citing it came from a forgery


def forged(row_id: int, **changes: Any) -> dict[str, Any]:
    image = {
        "id": row_id,
        "robot_id": "r1",
        "kind": "robot",
        "source": "safety_stop",
        "priority": 1000,
        "linear_mps": 0.22,
        "angular_rps": 0.0,
        "system_command": None,
        "stamp": 10.0,
        "expires_stamp": 1000.0,
        "inputs": {},
        "reason": "forged",
    }
    return {**image, **changes}


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
        reason=source,
    )


async def test_a_forged_recommendation_image_is_dropped_counted_and_never_cited(
    client: Runtime, clock: ClockPlayer, service_config: ServiceConfig
) -> None:
    await add_robot(client)
    async with running_service(DecisionService, service_config) as service:
        store = service.store  # type: ignore[attr-defined]
        assert isinstance(store, DecisionStore)
        await clock_at(service, 10.0)
        store.reread_s = 1e9  # no period read: a forged image believed would stay live
        low = await recommend(client, "turn_then_move", 10, 0.1)
        await newest_from(client, low)
        reads = store.reads
        forgeries = [
            forged(FORGED_ID),  # the safety band: a forward command at priority 1000
            forged(FORGED_ID + 1, robot_id="r2", priority=50),  # another robot's row
            forged(FORGED_ID + 2, priority=50, stamp=math.nan),  # sim time is a number
            forged(FORGED_ID + 3, priority=50, kind="robot", linear_mps=None),
        ]
        for image in forgeries:
            client.database.notifier.notify(keys.COMMAND_RECOMMENDATION, "r1", image["id"], image)
        await eventually(
            lambda: store.images_refused.get(keys.COMMAND_RECOMMENDATION) == len(forgeries),
            within=30,
            what="every forged image refused",
        )
        assert service.images_refused() == {keys.COMMAND_RECOMMENDATION: len(forgeries)}
        high = await recommend(client, "avoid_left", 50, 0.05)
        newest = await newest_from(client, high)
        assert sorted(newest["considered_ids"]) == [low, high]
        assert store.reads > reads  # each refused image sent the store to the table
    cited = await client.database.pool.fetchval(
        "SELECT count(*) FROM command2robot WHERE recommendation_id >= $1 "
        "OR $1 <= ANY(considered_ids)",
        FORGED_ID,
    )
    assert cited == 0
