"""Forged command2robot images (CONTRACT.md "Row images", "Forged images"): the relay holds
each image to command2robot's rules, and its id to what the table can hold, before it sends
it; an image that fails is dropped, counted (``Counters.images_refused``), and the table
read instead, so the robot is sent the table's newest row, never the forgery.

The forgeries are numbered as the decision numbers its notifications (no ``seq`` gap): only
their content gives them away.
"""

from __future__ import annotations

import math
from typing import Any

import asyncpg
import pytest

from common.contract import keys
from pnav._testing import eventually
from services.bridge import BridgeSettings
from services.bridge.command_images import ID_HORIZON
from tests.contract.bridge.conftest import BridgeFactory, FakeSim, ready, vel
from tests.contract.bridge.test_command_images import decided, publish, started

pytestmark = pytest.mark.timeout(60)


def forged(image: dict[str, Any], **changes: Any) -> dict[str, Any]:
    return {**image, "recommendation_id": None, "linear_mps": 0.2, **changes}


async def test_a_forged_command_image_is_dropped_counted_and_the_table_read(
    start_bridge: BridgeFactory, sim: FakeSim, conn: asyncpg.Connection
) -> None:
    bridge, cmd_vel = await started(start_bridge, sim)
    real, image = await decided(conn, 0.0, 0.0)
    publish(sim, real, image, seq=1)
    assert vel((await cmd_vel.next())[1]) == (0.0, 0.0, real)
    reads = bridge.counters.command_reads
    far = real + ID_HORIZON + 1  # no sequence got there since the relay read the table
    forgeries = [
        forged(image, id=far),
        forged(image, id=real + 1, linear_mps=50.0),  # not a recommendation's speed
        forged(image, id=real + 2, stamp=math.nan),
        forged(image, id=real + 3, robot_id="r2"),  # another robot's row on r1's key
        forged(image, id=real + 4, recommendation_id=9, considered_ids=[4, 5]),
    ]
    for seq, bad in enumerate(forgeries, start=2):
        publish(sim, bad["id"], bad, seq=seq)
    await eventually(
        lambda: bridge.counters.images_refused.get(keys.COMMAND2ROBOT) == len(forgeries),
        within=20,
        what="every forged image refused",
    )
    assert bridge.counters.snapshot()["images_refused"] == {keys.COMMAND2ROBOT: len(forgeries)}
    # nothing forged was sent: each refusal read the table, whose newest row was sent already
    assert await cmd_vel.quiet(0.3) == []
    assert bridge.counters.command_reads > reads
    assert bridge.counters.commands_out == 1

    after, image = await decided(conn, 0.1, 0.0)  # the decision's next row goes through
    publish(sim, after, image, seq=len(forgeries) + 2)
    assert vel((await cmd_vel.next())[1]) == (0.1, 0.0, after)


async def test_a_command_sent_from_an_image_the_table_never_had_holds_nothing_back(
    start_bridge: BridgeFactory, sim: FakeSim, conn: asyncpg.Connection
) -> None:
    """A forgery inside every rule, put as the decision, is sent once; the relay's next read
    of the table (every 50 ms) does not find it: counted, and the decision's own rows,
    with lower ids than the forgery's, are sent again from then on."""
    settings = BridgeSettings(command_period_s=0.05, prune_period_s=30.0, world_retry_s=0.5)
    bridge, cmd_vel = await ready(start_bridge, sim, settings=settings)
    await eventually(lambda: bridge.commands.limits.of("r1") is not None, what="r1's limits")
    real, image = await decided(conn, 0.0, 0.0)
    publish(sim, real, image, seq=1)
    assert vel((await cmd_vel.next())[1]) == (0.0, 0.0, real)
    phantom = real + 1000
    publish(sim, phantom, {**image, "id": phantom, "linear_mps": 0.1}, seq=2)
    await eventually(
        lambda: bridge.counters.images_refused.get(keys.COMMAND2ROBOT) == 1,
        within=20,
        what="the phantom found missing from the table",
    )
    after, image = await decided(conn, 0.05, 0.0)
    publish(sim, after, image, seq=3)

    async def sent_after() -> bool:
        while True:
            _, body = await cmd_vel.next(within=10)
            if vel(body)[2] == after:
                return True

    assert await sent_after()
