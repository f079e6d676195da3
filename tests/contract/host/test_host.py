"""The scenario services composed in one host process (pnav.run.host), against the contract.

The stack runs as ``pnav up --processes composed`` runs it: the sim and the bridge apart,
strategy, planner, controller and decision in one host with one Zenoh session and the host
identity (common.contract.acl.host_identity). A goal written as people write it is reached
through the host; each hosted service still writes as its own Postgres role and says so in
its own log file; and a hosted service that fails ends the host, naming it, and the
supervisor starts the host again.
"""

from __future__ import annotations

import dataclasses
import threading
from pathlib import Path

import asyncpg
import pytest
import zenoh

from common import bus
from common.config import ServiceConfig, ZenohSettings
from common.contract import acl, keys
from common.runtime import Runtime
from pnav._testing import eventually
from pnav.cli import stack_commands
from pnav.run.launcher import launched
from pnav.run.mission import MissionMonitor
from pnav.run.stack_options import StackOptions

pytestmark = pytest.mark.timeout(180)

SCENARIO = ("strategy", "planner", "controller", "decision")


def options(log_dir: Path) -> StackOptions:
    return StackOptions(
        world="open_room",
        rate="5",
        robots=1,
        zenoh_port=None,
        log_dir=log_dir,
        processes="composed",
    )


async def test_a_goal_is_reached_through_the_host_each_service_as_itself(tmp_path: Path) -> None:
    async with launched(options(tmp_path)) as stack:
        assert list(stack.supervisor.children) == ["sim", "bridge", "host"]
        assert {stack.process_of(s) for s in SCENARIO} == {"host"}
        rt = await Runtime.open(
            ServiceConfig(
                service="e2e", database_url=stack.local.url_for("user"), zenoh=stack.local.zenoh
            )
        )
        try:
            monitor = MissionMonitor(rt.database.pool, "r1")
            # the bridge registers the robot (slow on a loaded machine: not the host's part)
            assert await stack_commands.robot_ids(rt, wait_s=90) == ["r1"]
            (robot,) = await stack_commands.pick_robots(rt, None, one=True)
            goal = await stack_commands.set_goal(rt, robot, 3.0, 3.0)
            assert await monitor.wait_for(lambda log: log.goals.get(goal) == "reached", 120), (
                tmp_path / "host.log"
            ).read_text()[-3000:]
            async with rt.database.pool.acquire() as conn:
                # each hosted service holds its own lease and writes its engine_stats row
                instances = await conn.fetch("SELECT DISTINCT service, instance FROM engine_stats")
                decided = await conn.fetchval("SELECT count(*) FROM command2robot")
            assert {(s, f"{s}-1") for s in SCENARIO} <= {tuple(r) for r in instances}
            assert decided > 0
        finally:
            await rt.close()
    for service in SCENARIO:
        lines = (tmp_path / f"{service}.log").read_text().splitlines()
        assert any(" connected " in line and f"service={service}" in line for line in lines)
        # every line in a service's file names that service (tracebacks aside)
        assert all(line.split(" ")[2] == service for line in lines if line[:2] == "20")
    assert "host up services=strategy,planner,controller,decision" in (
        (tmp_path / "host.log").read_text()
    )


async def test_each_hosted_service_connects_as_its_own_postgres_role(tmp_path: Path) -> None:
    async with launched(options(tmp_path)) as stack:
        conn = await asyncpg.connect(stack.local.database_url)
        try:
            query = "SELECT DISTINCT usename FROM pg_stat_activity WHERE usename LIKE 'pnav_%'"

            async def roles() -> set[str] | None:
                found = {r["usename"] for r in await conn.fetch(query)}
                want = {f"pnav_{s}" for s in SCENARIO}
                return found if want <= found else None

            await eventually(roles, within=60, what="a connection of every hosted role")
        finally:
            await conn.close()


async def test_a_failing_hosted_service_ends_the_host_naming_it_and_the_host_restarts(
    tmp_path: Path,
) -> None:
    base = options(tmp_path)
    # the planner's role with a password that is not its own: it cannot connect and fails,
    # as a service fails; the others run until it does
    broken = dataclasses.replace(base, extra_env={"PNAV_DB_WAIT_S": "1"})
    async with launched(broken) as stack:
        host = stack.supervisor.children["host"]
        spec = host.spec
        good = spec.env["PNAV_DATABASE_URL_PLANNER"]
        spec.env["PNAV_DATABASE_URL_PLANNER"] = good.replace(
            "://pnav_planner:", "://pnav_planner:x"
        )
        assert spec.env["PNAV_DATABASE_URL_PLANNER"] != good
        assert host.process is not None
        host.process.terminate()  # started again with the planner's wrong password

        async def failed_and_restarted() -> bool | None:
            status = stack.supervisor.status()["host"]
            log = tmp_path / "host.log"
            text = log.read_text() if log.exists() else ""
            named = "host stopped: a service failed service=planner" in text
            return True if named and status["restarts"] >= 2 else None

        await eventually(failed_and_restarted, within=90, what="the host to fail and restart")
        planner = (tmp_path / "planner.log").read_text()
        assert "service failed: the host stops" in planner
        assert stack.supervisor.status()["host"]["last_exit"] == 1


def test_a_session_hears_its_own_puts_with_no_router_at_all() -> None:
    """What co-hosted services rely on: a session's put reaches that session's own
    subscribers in the process (here a peer linked to nothing: no router could relay it)."""
    alone = ZenohSettings(mode="peer", connect=(), listen=(), multicast=False)
    session = bus.open_session(alone)
    try:
        heard: list[str] = []
        done = threading.Event()

        def on_sample(sample: zenoh.Sample) -> None:
            heard.append(str(sample.key_expr))
            done.set()

        sub = session.declare_subscriber(keys.notify_watch(keys.GOAL), on_sample)
        key = keys.notify_key(keys.GOAL, "r9")
        session.put(key, b"x", express=True)  # as common.bus.Notifier puts
        assert done.wait(10), "a session's own put never reached its own subscriber"
        assert heard == [key]
        sub.undeclare()
    finally:
        session.close()


def test_the_host_identity_puts_exactly_the_union_of_its_services_keys() -> None:
    identity = acl.host_identity(SCENARIO)
    assert identity == "host-strategy-planner-controller-decision"
    assert acl.hosted_services(identity) == SCENARIO
    union = {k for s in SCENARIO for k in acl.put_keys(s)}
    assert set(acl.put_keys(identity)) == union
    assert set(acl.alive_keys(identity)) == {k for s in SCENARIO for k in acl.alive_keys(s)}
    assert keys.robot_watch(keys.CMD_VEL) not in union  # the bridge's, not the host's
    config = acl.access_control(hosts=(identity,))
    rules = {r["id"]: r for r in config["rules"]}
    assert set(rules[f"{identity} puts"]["key_exprs"]) == union
    assert acl.hosted_services("host-planner-nobody") is None
    with pytest.raises(ValueError):
        acl.host_identity(("planner",))
