"""The Zenoh router's access control, derived from CONTRACT.md's *Roles* table and keys.py.

In compose every service authenticates to the router with its own user name (its service
name; PNAV_ZENOH_USER/PNAV_ZENOH_PASSWORD, checked against the router's user/password
dictionary) and the router lets it put only its own keys:

- the change notifications ``pnav/db/{table}/*`` of the tables CONTRACT.md lets it write
  (common.contract.grants.written_tables), so nobody can announce a row it could not write;
- its liveliness token ``pnav/alive/{name}/*`` and lockstep report ``pnav/lockstep/{name}/*``
  (``user``: under the names of people's tools, :data:`USER_SERVICES`);
- the ``sim`` alone: sensor messages, the clock, the world (and answers on its queryable);
- the ``bridge`` alone: ``cmd_vel`` and the acknowledgements of collision events;
- ``user`` alone: ``pnav/sim/run``, which lets a held sim run (services/sim/hold.py).

A host process running several services in one Zenoh session (pnav.run.host, docs/ARCHITECTURE.md
"Processes") authenticates as a host identity named after them (:func:`host_identity`:
``host-strategy-planner-controller-decision``) whose permissions are derived, never written:
exactly the union of its services' (:func:`hosted_services`).

Everyone may subscribe to, and receive, everything under ``pnav/``: reading is open, as in
Postgres. Anything else is denied; a client with no valid user/password is refused its
session. ``python -m common.contract.acl`` prints the router's whole config
(deploy/zenoh/router.json5, which a test compares with this output).

The local stack's router (``pnav up``: pnav.run.local_stack, common.bus.start_router) is opened from
the same :func:`router_config`, only its endpoint, dictionary file and queue size being its
own, so one access control holds in compose and on one machine. A router's own session (the
launcher's supervisor report) is not a client of it and is not checked.
"""

from __future__ import annotations

import json
import sys
from typing import Any

from common.config import DATA_QUEUE_BATCHES
from common.contract import keys
from common.contract.grants import BUS_IDENTITIES, SERVICES, USER, written_tables

# Where the compose file mounts the router's user/password dictionary (a secret).
DICTIONARY_FILE = "/run/secrets/zenoh_users"
# The names the processes acting for people go by under the user identity: their liveliness
# tokens (pnav/alive/cli/...) and, for a benchmark runner taking part in a lockstep run,
# their lockstep reports. The CLI, the dashboard, the demo, the recorder, the benchmarks
# (pnav bench latency / startup, pnav bench nav, pnav bench faults) and the end-to-end
# tests. No service's name: people cannot pass for a service.
USER_SERVICES = (
    *("cli", "dashboard", "demo", "recorder", "bench", "navbench", "faults", "e2e"),
    "rviz",  # pnav.ros2: RViz's goals in, each robot's plan out (docs/ROS2.md)
)
# The identities that take part in a ROS 2 graph carried by this router (a robot link with
# no rmw_zenoh router of its own, docs/ROS2.md): the sim as a ROS 2 robot, the bridge as its
# driver, people's RViz process. ROS 2's keys live outside pnav/, under the domain id.
ROS2_IDENTITIES = ("sim", "bridge", USER)
EVERYTHING = f"{keys.PREFIX}/**"
# every kind of message: what anyone may receive under pnav/, and all a ROS 2 node speaks
_EGRESS = [
    "put",
    "delete",
    "declare_subscriber",
    "query",
    "declare_queryable",
    "reply",
    "liveliness_token",
    "declare_liveliness_subscriber",
    "liveliness_query",
]
_ROS2_MESSAGES = _EGRESS
HOST_PREFIX = "host-"
# The services a host runs unless told otherwise (pnav.run.launcher, --processes composed): its
# identity is in compose's router config, so a composed deployment needs no other ACL.
DEFAULT_HOSTED = ("strategy", "planner", "controller", "decision")


def host_identity(services: tuple[str, ...] | list[str]) -> str:
    """The Zenoh identity of a host running ``services`` (in CONTRACT.md's order, so one
    set has one name): ``host-strategy-planner-controller-decision``."""
    unknown = sorted(set(services) - set(SERVICES))
    if unknown or len(set(services)) < 2:
        raise ValueError(f"a host runs two or more of {', '.join(SERVICES)}, not {services}")
    return HOST_PREFIX + "-".join(s for s in SERVICES if s in services)


DEFAULT_HOSTS = (host_identity(DEFAULT_HOSTED),)


def hosted_services(identity: str) -> tuple[str, ...] | None:
    """The services a host identity stands for, or None when ``identity`` names no host."""
    if not identity.startswith(HOST_PREFIX):
        return None
    names = tuple(identity[len(HOST_PREFIX) :].split("-"))
    try:
        return names if host_identity(names) == identity else None
    except ValueError:
        return None


def put_keys(identity: str) -> list[str]:
    """The key expressions ``identity`` may put on (a host's: its services', and no more)."""
    hosted = hosted_services(identity)
    if hosted is not None:
        return list(dict.fromkeys(k for name in hosted for k in put_keys(name)))
    own = [keys.notify_watch(t) for t in sorted(written_tables(identity))]
    if identity == "sim":
        own = [keys.robot_watch(t) for t in keys.SENSOR_TOPICS]
        own += [keys.SIM_CLOCK, keys.SIM_WORLD]
    elif identity == "bridge":
        own += [keys.robot_watch(keys.CMD_VEL), keys.robot_watch(keys.COLLISION_ACK)]
        # a ROS 2 robot with no pybullet sim: the bridge gives the stack ROS time
        own.append(keys.SIM_CLOCK)
    elif identity == USER:
        # a held sim (--held) runs only as far as people let it: `pnav demo` drives its
        # mission's steps at the sim times it chose this way
        own.append(keys.SIM_RUN)
    own += [keys.lockstep_key(name, "*") for name in _names(identity)]
    return own


def _names(identity: str) -> tuple[str, ...]:
    """The service names ``identity``'s processes go by on the bus."""
    hosted = hosted_services(identity)
    if hosted is not None:
        return hosted
    return USER_SERVICES if identity == USER else (identity,)


def alive_keys(identity: str) -> list[str]:
    return [keys.alive_key(name, "*") for name in _names(identity)]


def _rule(rule_id: str, messages: list[str], flow: str, key_exprs: list[str]) -> dict[str, Any]:
    return {
        "id": rule_id,
        "permission": "allow",
        "flows": [flow],
        "messages": messages,
        "key_exprs": key_exprs,
    }


def ros2_keys(domain: int) -> list[str]:
    """What a ROS 2 node of ``domain`` speaks on (rmw_zenoh: topics, services and the
    advanced pub/sub's caches under the domain id; the graph's liveliness tokens)."""
    return [f"{domain}/**", f"@ros2_lv/{domain}/**"]


def access_control(
    ros_domains: tuple[int, ...] = (), hosts: tuple[str, ...] = DEFAULT_HOSTS
) -> dict[str, Any]:
    """The ``access_control`` section of the router's config; with ``ros_domains``, the
    ROS 2 identities may also speak ROS 2 in those domains (never a pnav/ key); ``hosts``:
    the host identities (:func:`host_identity`) besides the one per service."""
    for host in hosts:
        if hosted_services(host) is None:
            raise ValueError(f"{host!r} is not a host identity (acl.host_identity)")
    identities = (*BUS_IDENTITIES, *dict.fromkeys(h for h in hosts if h not in BUS_IDENTITIES))
    ros_speakers = [
        i for i in identities if i in ROS2_IDENTITIES or "bridge" in (hosted_services(i) or ())
    ]
    rules = [
        _rule("receive everything", _EGRESS, "egress", [EVERYTHING]),
        _rule(
            "subscribe to everything",
            ["declare_subscriber", "declare_liveliness_subscriber", "liveliness_query"],
            "ingress",
            [EVERYTHING],
        ),
        _rule("ask the sim for the world", ["query"], "ingress", [keys.SIM_WORLD]),
        _rule("serve the world", ["declare_queryable", "reply"], "ingress", [keys.SIM_WORLD]),
    ]
    policies = [
        {
            "rules": ["receive everything", "subscribe to everything", "ask the sim for the world"],
            "subjects": list(identities),
        },
        {"rules": ["serve the world"], "subjects": ["sim"]},
    ]
    if ros_domains:
        ros2 = [k for d in ros_domains for k in ros2_keys(d)]
        rules.append(_rule("speak ROS 2", _ROS2_MESSAGES, "ingress", ros2))
        rules.append(_rule("hear ROS 2", _ROS2_MESSAGES, "egress", ros2))
        policies.append({"rules": ["speak ROS 2", "hear ROS 2"], "subjects": ros_speakers})
    for identity in identities:
        rules.append(_rule(f"{identity} puts", ["put"], "ingress", put_keys(identity)))
        rules.append(
            _rule(f"{identity} is alive", ["liveliness_token"], "ingress", alive_keys(identity))
        )
        policies.append(
            {"rules": [f"{identity} puts", f"{identity} is alive"], "subjects": [identity]}
        )
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": [{"id": name, "usernames": [name]} for name in identities],
        "policies": policies,
    }


HEADER = """\
// Eclipse Zenoh router (zenohd) of the proactive-nav fleet, for the official image
// eclipse/zenoh pinned in deploy/docker-compose.yml (1.x, the same protocol as the
// eclipse-zenoh 1.x Python package the services use).
//
// GENERATED by `python -m common.contract.acl > deploy/zenoh/router.json5` from
// CONTRACT.md's "Roles" table and common/contract/keys.py: edit those, not this file
// (tests/deploy/test_zenoh_acl.py checks that it matches, and tries it on a real router).
//
// - listen: every interface of the container (the compose network, and the host through
//   the port published on its loopback in docker-compose.yml).
// - scouting: nothing is discovered by multicast; clients are told where the router is.
// - transport.auth.usrpwd: every client authenticates with its user name (its service:
//   sim, bridge, strategy, planner, controller, decision; `user` for the CLI and
//   dashboards; host-strategy-planner-controller-decision for those four composed in one
//   process, with exactly their permissions together) and password, checked against the
//   dictionary the compose file mounts as a secret (one `user:password` a line; `pnav
//   secrets` writes it). No valid password: no session.
// - access_control: deny by default; each user may put only its own keys (docs/DEPLOY.md,
//   "Zenoh access control"); everyone may subscribe to and receive everything under pnav/.
// - transport.link.tx.queue.size.data: room for 16 batches a link at the data priority, as
//   every pnav session has (common/config.py DATA_QUEUE_BATCHES: with Zenoh's 2, a busy
//   router drops notifications).
// - No "plugins" section: the REST plugin (port 8000) and every other plugin stay off.
"""


def router_config(
    listen: tuple[str, ...] = ("tcp/0.0.0.0:7447",),
    dictionary_file: str = DICTIONARY_FILE,
    data_queue: int = DATA_QUEUE_BATCHES,
    ros_domains: tuple[int, ...] = (),
    hosts: tuple[str, ...] = DEFAULT_HOSTS,
) -> dict[str, Any]:
    """The router's whole config: compose's by default; the local stack's router gives its
    loopback endpoint, its run's user/password file, its queue size, the ROS 2 domains it
    carries (``pnav up --robot-link ros2`` with no ``--ros-router``) and its host
    identities."""
    return {
        "mode": "router",
        "listen": {"endpoints": list(listen)},
        "scouting": {"multicast": {"enabled": False}},
        "transport": {
            "auth": {"usrpwd": {"dictionary_file": dictionary_file}},
            "link": {"tx": {"queue": {"size": {"data": data_queue}}}},
        },
        "access_control": access_control(ros_domains, hosts),
    }


def render() -> str:
    """The text of deploy/zenoh/router.json5."""
    return HEADER + json.dumps(router_config(), indent=2) + "\n"


def main() -> int:
    sys.stdout.write(render())
    return 0


if __name__ == "__main__":
    sys.exit(main())
