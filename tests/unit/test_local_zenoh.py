"""Zenoh between the processes of a local stack (pnav.run.local_stack.LocalZenoh), on loopback.

By default every local process is a client of the launcher's router, which checks its user
and password (tests/unit/test_bus_credentials.py). With ``PNAV_LOCAL_ZENOH=peer`` it
connects to the router, learns the other peers' endpoints from it (gossip scouting) and then
sends to them directly, so a notification crosses one link instead of two and the router
forwards none of it.
"""

from __future__ import annotations

import asyncio
import threading

import pytest

from common import bus
from common.bus import Notification, Notifier
from common.config import ZenohSettings
from common.contract import keys
from common.errors import ConfigError
from pnav._testing import eventually, loopback_zenoh
from pnav.run.local_stack import PEER_LISTEN, LocalZenoh


def test_local_processes_are_authenticated_clients_unless_told_to_be_peers() -> None:
    assert LocalZenoh.from_env({}).mode == "client"
    assert LocalZenoh.from_env({"PNAV_LOCAL_ZENOH": "peer"}).mode == "peer"
    router = "tcp/127.0.0.1:7447"
    assert LocalZenoh("peer").settings(router) == ZenohSettings(
        mode="peer", connect=(router,), listen=PEER_LISTEN, multicast=False
    )
    assert LocalZenoh().settings(router) == ZenohSettings(mode="client", connect=(router,))
    assert LocalZenoh().authenticated and not LocalZenoh("peer").authenticated
    # the data queue the launcher is told is every local process's (and its router's)
    told = LocalZenoh.from_env({"PNAV_ZENOH_DATA_QUEUE": "2"})
    assert told.data_queue == 2 and told.settings(router).data_queue == 2
    assert LocalZenoh.from_env({}).settings(router).data_queue == 16
    with pytest.raises(ConfigError, match="PNAV_LOCAL_ZENOH='router' must be peer or client"):
        LocalZenoh.from_env({"PNAV_LOCAL_ZENOH": "router"})


async def test_peers_deliver_notifications_directly_once_the_router_introduced_them() -> None:
    heard: list[Notification] = []
    lock = threading.Lock()

    def on(key: str, payload: bytes) -> None:
        with lock:
            heard.append(Notification.decode(key, payload))

    def count() -> int:
        with lock:
            return len(heard)

    with loopback_zenoh() as client_settings:
        settings = LocalZenoh("peer").settings(client_settings.connect[0])
        writer = await asyncio.to_thread(bus.open_session, settings)
        reader = await asyncio.to_thread(bus.open_session, settings)
        sub = bus.subscribe_threaded(reader, keys.notify_watch(keys.GOAL), on)
        notifier = Notifier(writer)

        def introduced() -> bool:
            # the router told each about the other: they hold a session of their own
            return reader.info.zid() in list(writer.info.peers_zid())

        await eventually(introduced, what="the two peers connected to each other")

        def first_heard() -> bool:
            notifier.notify(keys.GOAL, "r1", 1, {"id": 1, "robot_id": "r1"})
            return count() > 0

        # a subscription takes a moment to reach the other peer: put until one arrives
        await eventually(first_heard, what="a notification from one peer at the other")
    # The router is closed now: what follows can only go from peer to peer, once each has
    # dropped the routes through it (a put in that moment may find no route, so probe first).
    probes = iter(range(1000, 10**6))
    try:
        before = count()

        def heard_without_router() -> bool:
            notifier.notify(keys.GOAL, "r1", next(probes), {"id": 0, "robot_id": "r1"})
            return count() > before

        await eventually(heard_without_router, what="a notification with no router")
        before = count()
        for row_id in range(2, 22):
            notifier.notify(keys.GOAL, "r1", row_id, {"id": row_id, "robot_id": "r1"})
        sent = set(range(2, 22))

        def ids_since() -> set[int | None]:
            with lock:
                return {n.id for n in heard[before:]}

        await eventually(lambda: sent <= ids_since(), what="20 notifications, no router")
        with lock:
            tail = [n for n in heard[before:] if n.id in sent]  # a late probe may come between
        assert [n.id for n in tail] == list(range(2, 22))  # every one, once, in order
        assert all(n.row == {"id": n.id, "robot_id": "r1"} for n in tail)
    finally:
        sub.undeclare()
        writer.close()
        reader.close()
