"""``pnav up --record``: the whole stack records a mission, and the file reads back.

The stack is launched as ``pnav up --record FILE`` launches it (the recorder a supervised
process beside the services); a goal is set and reached; the stack stops; the MCAP is read
with the ``mcap`` reader.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from mcap.reader import make_reader

from common.config import ServiceConfig
from common.runtime import Runtime
from pnav.cli import stack_commands
from pnav.record import topics
from pnav.run.launcher import launched
from pnav.run.mission import MissionMonitor
from pnav.run.stack_options import StackOptions

pytestmark = [pytest.mark.timeout(240), pytest.mark.slow]

ROBOT = "r1"
# what a mission in open_room always produces (the path only if the planner writes one)
ALWAYS = ("/map", "/charging_stations", "/tf", "/{robot}/pose", "/{robot}/scan",
          "/{robot}/decisions", "/{robot}/events", "/{robot}/recommendations", "/{robot}/goal",
          "/{robot}/battery")  # fmt: skip


async def test_a_mission_of_the_whole_stack_is_recorded_in_sim_time(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    options = StackOptions(world="open_room", rate="5", robots=1, zenoh_port=None, record=path)
    async with launched(options) as stack:
        # started first, so that the supervisor stops it last: the file ends with the mission
        assert next(iter(stack.supervisor.children)) == "recorder"
        rt = await Runtime.open(
            ServiceConfig(
                service="e2e", database_url=stack.local.database_url, zenoh=stack.local.zenoh
            )
        )
        try:
            monitor = MissionMonitor(rt.database.pool, ROBOT)
            (robot,) = await stack_commands.pick_robots(rt, None, one=True)  # once the sim is up
            goal = await stack_commands.set_goal(rt, robot, 3.0, 2.0)
            ok = await monitor.wait_for(lambda log: log.goals.get(goal) == "reached", 150)
            final = (await monitor.poll()).now.stamp
            assert ok, f"goal not reached: {monitor.log.as_dict()}"
        finally:
            await rt.close()
        assert stack.supervisor.children["recorder"].restarts == 0
    # the stack stopped the recorder last: the file is closed, with its summary
    with path.open("rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None and summary.statistics is not None
    counts = {
        summary.channels[cid].topic: n
        for cid, n in summary.statistics.channel_message_counts.items()
    }
    for topic in ALWAYS:
        name = topic.replace("{robot}", ROBOT)
        assert counts.get(name, 0) > 0, f"{name} has no messages: {counts}"
    for channel in summary.channels.values():
        schema = summary.schemas[channel.schema_id].name
        assert topics.TOPICS[channel.topic.replace(f"/{ROBOT}/", "/{robot}/")] == schema
    # sim time: the mission's seconds (a few tens), nothing near the wall clock's 1.7e18 ns
    assert summary.statistics.message_start_time < 10e9  # recording from the start
    assert summary.statistics.message_end_time <= (final + 5.0) * 1e9
    assert counts[f"/{ROBOT}/scan"] >= 5 * final * 0.5  # 5 Hz, most of the mission
