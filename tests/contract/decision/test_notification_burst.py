"""No change notification is lost in a burst: the decision service, running as its process
would on a real Zenoh session through a router, gets every one of thousands of
recommendation notifications put back to back for 50 robots (a fleet's batch, many times
over). Its own count of notifications lost (a skip in a publisher's numbering) stays 0."""

from __future__ import annotations

import pytest

from common.config import ServiceConfig
from common.contract import keys
from common.runtime import Runtime
from pnav._testing import eventually, running_service
from services.decision.service import DecisionService

ROBOTS = [f"r{i}" for i in range(50)]
ROUNDS = 60  # 3,000 notifications, far beyond the 16 batches of a link's queue


@pytest.mark.timeout(120)
async def test_a_burst_of_notifications_reaches_the_service_whole(
    service_config: ServiceConfig, client: Runtime
) -> None:
    async with running_service(DecisionService, service_config, settle_s=1.0) as service:
        assert isinstance(service, DecisionService)
        notifier = client.database.notifier
        # no image: the service counts each one's number, then reads the table (empty)
        for _ in range(ROUNDS):
            for robot in ROBOTS:
                notifier.notify(keys.COMMAND_RECOMMENDATION, robot, None)
        seqs = service.store.sequences
        keys_sent = [f"{keys.COMMAND_RECOMMENDATION}/{robot}" for robot in ROBOTS]

        def all_arrived() -> bool:
            return all(seqs.newest(key, notifier.src) == ROUNDS for key in keys_sent)

        # a lost last one never arrives: the wait ends and names it
        await eventually(all_arrived, within=60.0, what="every robot's last notification")
        assert service.notifications_lost() == 0
