"""A local stack's Zenoh users (pnav.run.local_stack.BusCredentials): a process that was not given
this run's password cannot join; the stack's own processes hear each other through the
router that checks them; and that router lets each identity put only its own keys, as the
compose router does (every key family: tests/deploy/test_zenoh_acl.py)."""

from __future__ import annotations

import asyncio
import dataclasses
import os
import stat
import threading
from pathlib import Path

import pytest

from common import bus
from common.config import ZenohSettings
from common.contract import keys
from common.errors import ConnectionFailure, UsageError
from pnav._testing import eventually
from pnav.run.local_stack import BusCredentials, LocalZenoh, local_stack
from pnav.run.stackfile import StackInfo

pytestmark = pytest.mark.timeout(60)


def test_every_identity_gets_its_own_password_in_a_file_only_its_owner_reads(
    tmp_path: Path,
) -> None:
    creds = BusCredentials.create(tmp_path)
    mode = stat.S_IMODE(os.stat(creds.users_file).st_mode)
    assert mode == 0o600
    lines = creds.users_file.read_text().splitlines()
    assert sorted(line.split(":")[0] for line in lines) == sorted(creds.passwords)
    assert len(set(creds.passwords.values())) == len(creds.passwords)


def test_a_process_acts_as_its_service_and_anything_else_as_people(tmp_path: Path) -> None:
    creds = BusCredentials.create(tmp_path)
    assert creds.identity("planner") == "planner"
    assert creds.identity("planner-2") == "planner"  # a replica
    assert creds.identity("sim") == "sim"
    assert creds.identity("dashboard") == "user"
    assert creds.identity("recorder") == "user"
    settings = creds.apply(ZenohSettings(mode="peer"), "bridge")
    assert settings.user == "bridge" and settings.password == creds.passwords["bridge"]
    assert settings.users_file is None  # only the router checks the file


async def test_the_routers_door_is_shut_to_a_session_without_this_runs_password(
    db_url: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("PNAV_DATABASE_URL", db_url)
    async with local_stack() as stack:
        member = await asyncio.to_thread(bus.open_session, stack.zenoh_for("controller"))
        member.close()
        outsider = dataclasses.replace(stack.zenoh, mode="client", user=None, password=None)
        with pytest.raises(ConnectionFailure):
            await asyncio.to_thread(bus.open_session, outsider)
        wrong = dataclasses.replace(stack.zenoh, mode="client", password="not-the-password")
        with pytest.raises(ConnectionFailure):
            await asyncio.to_thread(bus.open_session, wrong)
        assert stack.bus is not None and stack.bus.users_file.exists()
        users_file = stack.bus.users_file
    assert not users_file.exists()  # this run's passwords go with it


async def test_the_stacks_processes_hear_each_other_through_the_authenticating_router(
    db_url: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("PNAV_DATABASE_URL", db_url)
    heard: list[str] = []
    lock = threading.Lock()

    def on(key: str, payload: bytes) -> None:
        with lock:
            heard.append(key)

    async with local_stack() as stack:
        assert stack.zenoh.mode == "client" and not stack.zenoh.listen  # no door but the router
        sim = await asyncio.to_thread(bus.open_session, stack.zenoh_for("sim"))
        reader = await asyncio.to_thread(bus.open_session, stack.zenoh_for("bridge"))
        sub = bus.subscribe_threaded(reader, "pnav/robot/r1/**", on)
        try:

            def got() -> bool:
                sim.put("pnav/robot/r1/scan", b"real")
                with lock:
                    return "pnav/robot/r1/scan" in heard

            await eventually(got, what="the sim's messages")
        finally:
            sub.undeclare()
            for session in (reader, sim):
                session.close()


async def test_on_the_stacks_router_people_put_goals_and_nothing_a_robot_obeys(
    db_url: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("PNAV_DATABASE_URL", db_url)
    heard: list[tuple[str, bytes]] = []
    lock = threading.Lock()

    def on(key: str, payload: bytes) -> None:
        with lock:
            heard.append((key, payload))

    def got(key: str, payload: bytes) -> bool:
        with lock:
            return (key, payload) in heard

    cmd_vel = keys.robot_key("r1", keys.CMD_VEL)
    async with local_stack() as stack:
        # people's: what `pnav env user` and the stack file give the CLI and the dashboard
        people = await asyncio.to_thread(bus.open_session, stack.zenoh)
        bridge = await asyncio.to_thread(bus.open_session, stack.zenoh_for("bridge"))
        sim = await asyncio.to_thread(bus.open_session, stack.zenoh_for("sim"))
        sub = bus.subscribe_threaded(sim, "pnav/**", on)
        try:

            def bridge_heard() -> bool:
                bridge.put(cmd_vel, b"the bridge's")
                return got(cmd_vel, b"the bridge's")

            await eventually(bridge_heard, what="the bridge's cmd_vel at the sim")
            forged = [
                cmd_vel,
                keys.robot_key("r1", keys.ODOM),
                keys.SIM_CLOCK,
                keys.notify_key(keys.COMMAND_RECOMMENDATION, "r1"),
                keys.notify_key(keys.COMMAND2ROBOT, "r1"),
            ]
            for key in forged:
                people.put(key, b"forged")
            # one session's puts arrive in order: once its goal is in, the rest would be
            people.put(keys.notify_key(keys.GOAL, "r1"), b"a goal")
            await eventually(
                lambda: got(keys.notify_key(keys.GOAL, "r1"), b"a goal"), what="people's goal"
            )
            with lock:
                assert [key for key, payload in heard if payload == b"forged"] == []
        finally:
            sub.undeclare()
            for session in (people, bridge, sim):
                session.close()


async def test_peer_mode_is_the_documented_exception_without_authentication(
    db_url: str, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    monkeypatch.setenv("PNAV_DATABASE_URL", db_url)
    async with local_stack(local_zenoh=LocalZenoh("peer")) as stack:
        assert stack.bus is None and stack.zenoh.user is None
        outsider = dataclasses.replace(stack.zenoh, mode="client", listen=())
        session = await asyncio.to_thread(bus.open_session, outsider)
        session.close()
    assert "runs without authentication and without access control" in caplog.text


def test_the_stack_file_gives_a_process_started_by_hand_its_identity() -> None:
    info = StackInfo(
        pid=1,
        database_url="postgresql://pnav_user@/db",
        zenoh_connect="tcp/127.0.0.1:7447",
        world="w",
        rate="1",
        log_dir="/tmp",
        role_urls={"controller": "postgresql://pnav_controller@/db", "user": "u"},
        zenoh_passwords={"controller": "c-pw", "user": "u-pw"},
    )
    assert info.zenoh().user == "user" and info.zenoh().password == "u-pw"
    env = info.env_for("controller")
    assert env["PNAV_DATABASE_URL"] == "postgresql://pnav_controller@/db"
    assert env["PNAV_ZENOH_USER"] == "controller" and env["PNAV_ZENOH_PASSWORD"] == "c-pw"
    assert env["PNAV_ZENOH_MODE"] == "client"
    with pytest.raises(UsageError, match="no role 'nobody' in this stack"):
        info.env_for("nobody")


def test_local_sessions_use_no_shared_memory() -> None:
    """Zenoh's shared-memory pools (16 MB per publishing process, mapped by the router and
    every receiver) are off unless a config file turns them on."""
    from common.bus import zenoh_config
    from common.config import ZenohSettings

    config = zenoh_config(ZenohSettings(mode="client", connect=("tcp/127.0.0.1:7447",)))
    assert config.get_json("transport/shared_memory/enabled") == "false"
