"""The sim as a ROS 2 robot and the bridge on the ROS 2 link, started as `pnav up
--robot-link ros2` starts them: rows come from the ROS 2 wire, commands drive the robot over
it, and the graph (rmw_zenoh's liveliness tokens) shows both nodes and their topics."""

from __future__ import annotations

import asyncio
from pathlib import Path

import asyncpg
import pytest

from common import bus, ros2types
from common.contract import rmw_zenoh as rz
from common.trace import CMD_VEL, NO_REF, read_trace
from pnav._testing import eventually
from pnav.run.launcher import launched
from pnav.run.stack_options import StackOptions

pytestmark = [pytest.mark.timeout(120), pytest.mark.slow]

NEWEST = "SELECT stamp, x, y, linear_mps FROM odometry ORDER BY id DESC LIMIT 1"
INSERT = (
    "INSERT INTO command2robot (robot_id, stamp, linear_mps, angular_rps, reason) "
    "VALUES ('r1', $1, $2, 0.0, 'ros2 contract test')"
)


@pytest.mark.parametrize("clock", ["sim", "ros"])
async def test_the_sim_drives_as_a_ros2_robot_and_both_nodes_are_in_the_graph(
    clock: str, tmp_path: Path
) -> None:
    """``clock: ros``: the sim publishes ROS /clock as Gazebo does, and the bridge makes it
    the stack's clock (use_sim_time), as it would for a simulated robot of another sim."""
    link = tmp_path / "link.yaml"
    link.write_text(f"clock: {clock}\nuse_sim_time: true\n")
    sim_trace, bridge_trace = tmp_path / "sim.csv", tmp_path / "bridge.csv"
    options = StackOptions(
        world="open_room",
        rate="1",
        zenoh_port=None,
        services=("sim", "bridge"),
        extra_env={
            "PNAV_ROBOT_LINK": "ros2",
            "PNAV_ROS_DOMAIN_ID": "7",
            "PNAV_ROS2_LINK_FILE": str(link),
            # the three traces `pnav bench latency --robot-link ros2` joins (common/trace.py)
            "PNAV_SIM_TRACE": str(sim_trace),
            "PNAV_BRIDGE_TRACE": str(bridge_trace),
        },
    )
    async with launched(options) as stack:
        conn = await asyncpg.connect(stack.local.database_url)
        session = await asyncio.to_thread(bus.open_session, stack.local.zenoh_for("user"))
        try:
            before = await eventually(lambda: conn.fetchrow(NEWEST), within=30, what="odometry")
            for _ in range(60):  # 3 s of commands, each fresh
                now = (await conn.fetchrow(NEWEST))["stamp"]
                await conn.execute(INSERT, now, 0.2)
                await asyncio.sleep(0.05)
            after = await conn.fetchrow(NEWEST)
            assert after["x"] - before["x"] > 0.2  # it moved forward, over ROS 2
            assert await conn.fetchval("SELECT count(*) FROM laser_scan") > 0
            assert await conn.fetchval("SELECT count(*) FROM battery") > 0

            # the traces join what no ROS 2 message carries: the bridge names the command id
            # each cmd_vel's attachment number stood for, the sim applied those numbers, and
            # a row's seq is the number the sim's publisher gave the reading
            await asyncio.sleep(1.0)  # both flush every 0.5 s
            sent = {(e.robot, e.wire): e.ref for e in read_trace(bridge_trace)}
            ids = {r["id"] for r in await conn.fetch("SELECT id FROM command2robot")}
            assert len(sent) > 30 and set(sent.values()) <= ids
            applied = [e for e in read_trace(sim_trace) if e.kind == CMD_VEL]
            assert applied and all(e.ref == NO_REF for e in applied)
            assert len({(e.robot, e.wire) for e in applied} & set(sent)) > 30
            odom = {e.wire: e.ref for e in read_trace(sim_trace) if e.kind == "odom"}
            rows = [r["seq"] for r in await conn.fetch("SELECT seq FROM odometry")]
            traced = [seq for seq in rows if seq <= max(odom)]
            assert len(traced) > 10 and all(seq in odom for seq in traced)

            replies = await asyncio.to_thread(
                lambda: list(session.liveliness().get(rz.graph_watch(7), timeout=5.0))
            )
            tokens = [rz.parse_token(str(r.ok.key_expr)) for r in replies if r.ok is not None]
            nodes = {t.node for t in tokens if t.kind == rz.NODE}
            assert {"pnav_sim", "pnav_bridge", "pnav_rviz"} <= nodes
            endpoints = {(t.node, t.kind, t.topic, t.type_name) for t in tokens}
            assert ("pnav_sim", rz.PUBLISHER, "/r1/scan", ros2types.LASER_SCAN) in endpoints
            assert ("pnav_bridge", rz.SUBSCRIPTION, "/r1/odom", ros2types.ODOMETRY) in endpoints
            assert ("pnav_bridge", rz.PUBLISHER, "/r1/cmd_vel", ros2types.TWIST) in endpoints
            assert ("pnav_sim", rz.SUBSCRIPTION, "/r1/cmd_vel", ros2types.TWIST) in endpoints
            assert ("pnav_rviz", rz.PUBLISHER, "/r1/plan", ros2types.PATH) in endpoints
            clock_topic = ("pnav_sim", rz.PUBLISHER, "/clock", ros2types.CLOCK)
            assert (clock_topic in endpoints) == (clock == "ros")
            if clock == "ros":
                assert ("pnav_bridge", rz.SUBSCRIPTION, "/clock", ros2types.CLOCK) in endpoints
        finally:
            session.close()
            await conn.close()
