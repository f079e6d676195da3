"""The router's access control and authentication, on real routers: compose's and the local
stack's.

deploy/zenoh/router.json5 is generated from CONTRACT.md's Roles table and keys.py
(common.contract.acl); the test checks that the committed file is that output, then opens,
each in its turn:

- ``compose``: a router from that file (the eclipse-zenoh package runs the same router code
  as zenohd, in-process: only its listen endpoint and the path of its user/password
  dictionary are changed for the test);
- ``local``: the router of a local stack (``pnav up``), as pnav.run.local_stack.local_stack
  starts it: common.bus.start_router with the run's user/password file
  (pnav.run.local_stack.BusCredentials);

and clients with each identity and its password:

- a put an identity is allowed reaches a subscriber; one it is not never arrives. "Never":
  after the put under test, the same session puts a marker on a key it may use; messages of
  one session arrive in order, so once the marker is in, the put under test would be too;
- a client with no credentials, a wrong password or an unknown user gets no session.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh

from common import bus
from common.config import ZenohSettings
from common.contract import acl, keys
from common.contract.grants import BUS_IDENTITIES, USER, written_tables
from common.errors import ConnectionFailure
from pnav._testing import acl_router
from pnav.run.embedded_postgres import free_port
from pnav.run.local_stack import BusCredentials

ROUTER_CONFIG = Path(__file__).resolve().parents[2] / "deploy" / "zenoh" / "router.json5"
PASSWORDS = {name: f"pw-{name}-{i}" for i, name in enumerate((*BUS_IDENTITIES, *acl.DEFAULT_HOSTS))}
HOST = acl.DEFAULT_HOSTS[0]  # strategy, planner, controller and decision in one process


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
    def __init__(self, endpoint: str, passwords: dict[str, str]) -> None:
        self.endpoint = endpoint
        self.passwords = passwords
        self.sessions: dict[str, zenoh.Session] = {}

    def settings(self, user: str | None, password: str | None) -> ZenohSettings:
        return ZenohSettings(mode="client", connect=(self.endpoint,), user=user, password=password)

    def session(self, identity: str) -> zenoh.Session:
        if identity not in self.sessions:
            settings = self.settings(identity, self.passwords[identity])
            self.sessions[identity] = bus.open_session(settings)
        return self.sessions[identity]


@contextlib.contextmanager
def local_router(directory: Path) -> Iterator[tuple[str, dict[str, str], zenoh.Session]]:
    """The router of a local stack, started as pnav.run.local_stack.local_stack starts it."""
    creds = BusCredentials.create(directory)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = bus.start_router((endpoint,), str(creds.users_file))
    try:
        yield endpoint, dict(creds.passwords), router
    finally:
        router.close()


@pytest.fixture(scope="module", params=["compose", "local"])
def fleet(
    request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[Fleet]:
    directory = tmp_path_factory.mktemp("zenoh")
    with contextlib.ExitStack() as stack:
        if request.param == "compose":
            # not 0.0.0.0:7447 and /run/secrets in a test: a free loopback port, a temp file
            endpoint = stack.enter_context(acl_router(ROUTER_CONFIG, PASSWORDS, directory))
            passwords = PASSWORDS
        else:
            endpoint, passwords, _ = stack.enter_context(local_router(directory))
        fleet = Fleet(endpoint, passwords)
        try:
            yield fleet
        finally:
            for session in fleet.sessions.values():
                session.close()


@pytest.fixture(scope="module")
def heard(fleet: Fleet) -> Iterator[Heard]:
    heard = Heard()
    listener = bus.open_session(fleet.settings("user", fleet.passwords["user"]))
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
    ("bridge", keys.robot_key("r1", keys.COLLISION_ACK), True),
    ("sim", keys.robot_key("r1", keys.COLLISION_ACK), False),
    # people (the CLI, the dashboard, `pnav env user`): what people write, nothing a robot
    # or a service obeys
    ("user", keys.notify_key(keys.USER_COMMAND, "r1"), True),
    ("user", keys.notify_key(keys.STRATEGY), True),
    ("user", keys.notify_key(keys.RETENTION_POLICY), True),
    ("user", keys.robot_key("r1", keys.CMD_VEL), False),
    ("user", keys.robot_key("r1", keys.ODOM), False),
    ("user", keys.robot_key("r1", keys.SCAN), False),
    ("user", keys.robot_key("r1", keys.COLLISION), False),
    ("user", keys.robot_key("r1", keys.COLLISION_ACK), False),
    ("user", keys.SIM_CLOCK, False),
    ("user", keys.SIM_WORLD, False),
    # people hold and run a held sim (`pnav demo`); nobody else does
    ("user", keys.SIM_RUN, True),
    ("sim", keys.SIM_RUN, False),
    ("planner", keys.SIM_RUN, False),
    ("bridge", keys.SIM_RUN, False),
    ("user", keys.notify_key(keys.ODOMETRY, "r1"), False),
    ("user", keys.notify_key(keys.COMMAND_RECOMMENDATION, "r1"), False),
    ("user", keys.notify_key(keys.COMMAND2ROBOT, "r1"), False),
    ("user", keys.notify_key(keys.SYSTEM_COMMAND, "r1"), False),
    ("user", keys.notify_key(keys.ROBOT, "r1"), False),
    ("user", keys.supervisor_key("launcher-1"), False),
    # lockstep reports under one's own name only (people's: a benchmark runner's)
    ("planner", keys.lockstep_key("planner", "p-1"), True),
    ("planner", keys.lockstep_key("decision", "d-1"), False),
    ("sim", keys.lockstep_key("sim", "s-1"), True),
    ("user", keys.lockstep_key("navbench", "n-1"), True),
    ("user", keys.lockstep_key("planner", "p-1"), False),
    ("bridge", keys.lockstep_key("navbench", "n-1"), False),
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


@pytest.mark.parametrize("identity", BUS_IDENTITIES)
def test_each_identity_announces_exactly_the_tables_it_may_write(
    fleet: Fleet, heard: Heard, identity: str
) -> None:
    """Every table's notification, from every identity: it arrives if and only if the Roles
    table lets the identity write the table."""
    session = fleet.session(identity)
    payload = f"{identity} announces".encode()
    for table in keys.TABLES:
        session.put(keys.notify_key(table, "r1"), payload)
    session.put(marker_key(identity), payload)
    heard.wait_for(marker_key(identity), payload)
    arrived = {
        keys.parse_notify_key(key)[0]
        for key, body in heard.samples
        if body == payload and key.startswith("pnav/db/")
    }
    assert arrived == written_tables(identity)


def test_a_host_announces_exactly_the_tables_its_services_may_write(
    fleet: Fleet, heard: Heard
) -> None:
    """The host identity (pnav.run.host) may do what its services may together, and no more."""
    hosted = acl.hosted_services(HOST)
    assert hosted == ("strategy", "planner", "controller", "decision")
    session = fleet.session(HOST)
    payload = b"the host announces"
    for table in keys.TABLES:
        session.put(keys.notify_key(table, "r1"), payload)
    for name in (*hosted, "bridge", "sim"):
        session.put(keys.lockstep_key(name, "x-1"), payload)
    session.put(keys.robot_key("r1", keys.CMD_VEL), payload)
    session.put(marker_key(HOST), payload)
    heard.wait_for(marker_key(HOST), payload)
    arrived = {key for key, body in heard.samples if body == payload} - {marker_key(HOST)}
    tables = {keys.parse_notify_key(k)[0] for k in arrived if k.startswith("pnav/db/")}
    assert tables == set().union(*(written_tables(s) for s in hosted))
    assert {k for k in arrived if k.startswith("pnav/lockstep/")} == {
        keys.lockstep_key(name, "x-1") for name in hosted
    }
    assert keys.robot_key("r1", keys.CMD_VEL) not in arrived


def alive(fleet: Fleet, asker: str) -> set[str]:
    """The tokens ``asker`` sees through the router (a session sees its own tokens itself:
    the asker must not be the identity under test)."""
    replies = fleet.session(asker).liveliness().get(keys.alive_watch(), timeout=2)
    return {str(r.ok.key_expr) for r in replies if r.ok is not None}


def wait_alive(fleet: Fleet, key: str, asker: str) -> set[str]:
    deadline = time.monotonic() + 10
    while key not in (found := alive(fleet, asker)):
        assert time.monotonic() < deadline, f"{key} never appeared"
        time.sleep(0.05)
    return found


def test_liveliness_tokens_only_under_ones_own_name(fleet: Fleet, heard: Heard) -> None:
    planner = fleet.session("planner")
    forged = planner.liveliness().declare_token(keys.alive_key("decision", "forged"))
    own = planner.liveliness().declare_token(keys.alive_key("planner", "p-1"))
    found = wait_alive(fleet, "pnav/alive/planner/p-1", USER)
    assert "pnav/alive/decision/forged" not in found
    own.undeclare()
    forged.undeclare()


def test_people_are_alive_under_their_tools_names_never_a_services(
    fleet: Fleet, heard: Heard
) -> None:
    user = fleet.session(USER)
    forged = [user.liveliness().declare_token(keys.alive_key(s, "forged")) for s in BUS_IDENTITIES]
    own = [user.liveliness().declare_token(keys.alive_key(t, "u-1")) for t in acl.USER_SERVICES]
    for tool in acl.USER_SERVICES:
        found = wait_alive(fleet, keys.alive_key(tool, "u-1"), "bridge")
    assert not {keys.alive_key(s, "forged") for s in BUS_IDENTITIES} & found
    for token in own + forged:
        token.undeclare()


@pytest.mark.parametrize(
    ("user", "password"),
    [(None, None), ("sim", "not-the-password"), ("intruder", "pw"), ("planner", "sim's")],
)
def test_a_client_without_valid_credentials_gets_no_session(
    fleet: Fleet, user: str | None, password: str | None
) -> None:
    if password == "sim's":  # another identity's password
        password = fleet.passwords["sim"]
    with pytest.raises(ConnectionFailure):
        bus.open_session(fleet.settings(user, password)).close()


def test_the_launchers_report_is_put_by_the_local_routers_own_session(tmp_path: Path) -> None:
    """pnav/supervisor/<launcher> (pnav.run.supervisor_report) is put by the launcher on its
    router's own session, which is not a client: the access control, which lets no client
    put it, does not stop it."""
    with local_router(tmp_path) as (endpoint, passwords, router):
        heard = Heard()
        listener = bus.open_session(
            ZenohSettings(mode="client", connect=(endpoint,), user=USER, password=passwords[USER])
        )
        subscriber = listener.declare_subscriber(keys.SUPERVISOR_WATCH, heard)
        try:
            key = keys.supervisor_key("launcher-1")
            deadline = time.monotonic() + 10
            while (key, b"report") not in heard.samples:
                assert time.monotonic() < deadline, "the launcher's report never arrived"
                router.put(key, b"report")
                time.sleep(0.05)
        finally:
            subscriber.undeclare()
            listener.close()


def test_a_ros2_domain_is_spoken_only_by_the_ros2_identities_and_never_on_pnav_keys() -> None:
    control = acl.access_control(ros_domains=(7,))
    rules = {rule["id"]: rule for rule in control["rules"]}
    spoken = {k for rid in ("speak ROS 2", "hear ROS 2") for k in rules[rid]["key_exprs"]}
    assert spoken == {"7/**", "@ros2_lv/7/**"}
    subjects = [p["subjects"] for p in control["policies"] if "speak ROS 2" in p["rules"]]
    assert subjects == [["sim", "bridge", "user"]]
    # compose's router carries no ROS 2 domain
    assert "speak ROS 2" not in {rule["id"] for rule in acl.access_control()["rules"]}
