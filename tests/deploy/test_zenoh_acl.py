"""The compose router's access control and authentication, on a real router.

deploy/zenoh/router.json5 is generated from CONTRACT.md's Roles table and keys.py
(common.contract.acl); the test checks that the committed file is that output, then opens a
router from it (the eclipse-zenoh package runs the same router code as zenohd, in-process:
only its listen endpoint and the path of its user/password dictionary are changed for the
test) and clients with each identity:

- a put an identity is allowed reaches a subscriber; one it is not never arrives. "Never":
  after the put under test, the same session puts a marker on a key it may use; messages of
  one session arrive in order, so once the marker is in, the put under test would be too;
- a client with no credentials, a wrong password or an unknown user gets no session.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh

from common import bus
from common.config import ZenohSettings
from common.contract import acl, keys
from common.contract.grants import BUS_IDENTITIES
from common.errors import ConnectionFailure
from common.testing import acl_router

ROUTER_CONFIG = Path(__file__).resolve().parents[2] / "deploy" / "zenoh" / "router.json5"
PASSWORDS = {name: f"pw-{name}-{i}" for i, name in enumerate(BUS_IDENTITIES)}


def test_the_committed_router_config_is_the_generated_one() -> None:
    assert ROUTER_CONFIG.read_text() == acl.render(), (
        "deploy/zenoh/router.json5 is stale: python -m common.contract.acl > "
        "deploy/zenoh/router.json5"
    )


class Heard:
    """Every (key, payload) a subscriber to pnav/** received."""

    def __init__(self) -> None:
        self.samples: list[tuple[str, bytes]] = []
        self.cond = threading.Condition()

    def __call__(self, sample: zenoh.Sample) -> None:
        with self.cond:
            self.samples.append((str(sample.key_expr), sample.payload.to_bytes()))
            self.cond.notify_all()

    def wait_for(self, key: str, payload: bytes, timeout_s: float = 10.0) -> None:
        deadline = time.monotonic() + timeout_s
        with self.cond:
            while (key, payload) not in self.samples:
                left = deadline - time.monotonic()
                assert left > 0, f"{key} {payload!r} never arrived"
                self.cond.wait(left)


class Fleet:
    def __init__(self, endpoint: str) -> None:
        self.endpoint = endpoint
        self.sessions: dict[str, zenoh.Session] = {}

    def settings(self, user: str | None, password: str | None) -> ZenohSettings:
        return ZenohSettings(mode="client", connect=(self.endpoint,), user=user, password=password)

    def session(self, identity: str) -> zenoh.Session:
        if identity not in self.sessions:
            settings = self.settings(identity, PASSWORDS[identity])
            self.sessions[identity] = bus.open_session(settings)
        return self.sessions[identity]


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Fleet]:
    # not 0.0.0.0:7447 and /run/secrets in a test: a free loopback port, a temporary file
    with acl_router(ROUTER_CONFIG, PASSWORDS, tmp_path_factory.mktemp("zenoh")) as endpoint:
        fleet = Fleet(endpoint)
        try:
            yield fleet
        finally:
            for session in fleet.sessions.values():
                session.close()


@pytest.fixture(scope="module")
def heard(fleet: Fleet) -> Iterator[Heard]:
    heard = Heard()
    listener = bus.open_session(fleet.settings("user", PASSWORDS["user"]))
    subscriber = listener.declare_subscriber(acl.EVERYTHING, heard)
    # the subscription has reached the router once a put of another session arrives
    sim = fleet.session("sim")
    deadline = time.monotonic() + 10
    while not heard.samples:
        assert time.monotonic() < deadline, "the listener never heard the sim"
        sim.put(keys.SIM_CLOCK, b"warm-up")
        time.sleep(0.05)
    try:
        yield heard
    finally:
        subscriber.undeclare()
        listener.close()


def marker_key(identity: str) -> str:
    """A key ``identity`` may put on."""
    return acl.put_keys(identity)[-1].replace("*", "marker")


CASES = [
    # the sim alone speaks for the robot's sensors
    ("sim", keys.robot_key("r1", keys.SCAN), True),
    ("sim", keys.robot_key("r1", keys.ODOM), True),
    ("planner", keys.robot_key("r1", keys.ODOM), False),
    ("user", keys.robot_key("r1", keys.BATTERY_MSG), False),
    ("bridge", keys.robot_key("r1", keys.COLLISION), False),
    ("controller", keys.robot_key("r1", keys.SCAN), False),
    ("decision", keys.SIM_CLOCK, False),
    # the bridge alone commands the robot
    ("bridge", keys.robot_key("r1", keys.CMD_VEL), True),
    ("decision", keys.robot_key("r1", keys.CMD_VEL), False),
    ("sim", keys.robot_key("r1", keys.CMD_VEL), False),
    # a notification only from a writer of the table
    ("decision", keys.notify_key(keys.COMMAND2ROBOT, "r1"), True),
    ("planner", keys.notify_key(keys.COMMAND2ROBOT, "r1"), False),
    ("planner", keys.notify_key(keys.GOAL, "r1"), True),
    ("user", keys.notify_key(keys.GOAL, "r1"), True),
    ("controller", keys.notify_key(keys.GOAL, "r1"), False),
    ("sim", keys.notify_key(keys.LASER_SCAN, "r1"), False),
    ("bridge", keys.notify_key(keys.LASER_SCAN, "r1"), True),
    ("user", keys.notify_key(keys.ACTIVE_STRATEGY, "r1"), False),
    ("strategy", keys.notify_key(keys.ACTIVE_STRATEGY, "r1"), True),
    # lockstep reports under one's own name only
    ("planner", keys.lockstep_key("planner", "p-1"), True),
    ("planner", keys.lockstep_key("decision", "d-1"), False),
]


@pytest.mark.parametrize(("identity", "key", "allowed"), CASES)
def test_each_identity_puts_only_its_own_keys(
    fleet: Fleet, heard: Heard, identity: str, key: str, allowed: bool
) -> None:
    session = fleet.session(identity)
    payload = f"{identity}->{key}".encode()
    session.put(key, payload)
    session.put(marker_key(identity), payload)
    heard.wait_for(marker_key(identity), payload)
    assert ((key, payload) in heard.samples) == allowed


def test_liveliness_tokens_only_under_ones_own_name(fleet: Fleet, heard: Heard) -> None:
    planner = fleet.session("planner")
    forged = planner.liveliness().declare_token(keys.alive_key("decision", "forged"))
    own = planner.liveliness().declare_token(keys.alive_key("planner", "p-1"))
    asker = fleet.session("user")
    deadline = time.monotonic() + 10
    while True:
        replies = asker.liveliness().get(keys.alive_watch(), timeout=2)
        found = {str(r.ok.key_expr) for r in replies if r.ok is not None}
        if "pnav/alive/planner/p-1" in found:
            break
        assert time.monotonic() < deadline, "the planner's own token never appeared"
        time.sleep(0.05)
    assert "pnav/alive/decision/forged" not in found
    own.undeclare()
    forged.undeclare()


@pytest.mark.parametrize(
    ("user", "password"),
    [(None, None), ("sim", "not-the-password"), ("intruder", "pw"), ("planner", PASSWORDS["sim"])],
)
def test_a_client_without_valid_credentials_gets_no_session(
    fleet: Fleet, user: str | None, password: str | None
) -> None:
    with pytest.raises(ConnectionFailure):
        bus.open_session(fleet.settings(user, password)).close()
