"""The Zenoh router's access control, derived from CONTRACT.md's *Roles* table and keys.py.

In compose every service authenticates to the router with its own user name (its service
name; PNAV_ZENOH_USER/PNAV_ZENOH_PASSWORD, checked against the router's user/password
dictionary) and the router lets it put only its own keys:

- the change notifications ``pnav/db/{table}/*`` of the tables CONTRACT.md lets it write
  (common.contract.grants.written_tables), so nobody can announce a row it could not write;
- its liveliness token ``pnav/alive/{name}/*`` and lockstep report ``pnav/lockstep/{name}/*``
  (``user``: under the names of people's tools, :data:`USER_SERVICES`);
- the ``sim`` alone: sensor messages, the clock, the world (and answers on its queryable);
- the ``bridge`` alone: ``cmd_vel`` and the acknowledgements of collision events.

Everyone may subscribe to, and receive, everything under ``pnav/``: reading is open, as in
Postgres. Anything else is denied; a client with no valid user/password is refused its
session. ``python -m common.contract.acl`` prints the router's whole config
(deploy/zenoh/router.json5, which a test compares with this output).

The local stack's router (``pnav up``: common.stack, common.bus.start_router) is opened from
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
from common.contract.grants import BUS_IDENTITIES, USER, written_tables

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


def put_keys(identity: str) -> list[str]:
    """The key expressions ``identity`` may put on."""
    own = [keys.notify_watch(t) for t in sorted(written_tables(identity))]
    if identity == "sim":
        own = [keys.robot_watch(t) for t in keys.SENSOR_TOPICS]
        own += [keys.SIM_CLOCK, keys.SIM_WORLD]
    elif identity == "bridge":
        own += [keys.robot_watch(keys.CMD_VEL), keys.robot_watch(keys.COLLISION_ACK)]
        # a ROS 2 robot with no pybullet sim: the bridge gives the stack ROS time
        own.append(keys.SIM_CLOCK)
    own += [keys.lockstep_key(name, "*") for name in _names(identity)]
    return own


def _names(identity: str) -> tuple[str, ...]:
    """The service names ``identity``'s processes go by on the bus."""
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


def access_control(ros_domains: tuple[int, ...] = ()) -> dict[str, Any]:
    """The ``access_control`` section of the router's config; with ``ros_domains``, the
    ROS 2 identities may also speak ROS 2 in those domains (never a pnav/ key)."""
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
            "subjects": list(BUS_IDENTITIES),
        },
        {"rules": ["serve the world"], "subjects": ["sim"]},
    ]
    if ros_domains:
        ros2 = [k for d in ros_domains for k in ros2_keys(d)]
        rules.append(_rule("speak ROS 2", _ROS2_MESSAGES, "ingress", ros2))
        rules.append(_rule("hear ROS 2", _ROS2_MESSAGES, "egress", ros2))
        policies.append({"rules": ["speak ROS 2", "hear ROS 2"], "subjects": list(ROS2_IDENTITIES)})
    for identity in BUS_IDENTITIES:
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
        "subjects": [{"id": name, "usernames": [name]} for name in BUS_IDENTITIES],
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
//   dashboards) and password, checked against the dictionary the compose file mounts as a
//   secret (one `user:password` a line; `pnav secrets` writes it). No valid password: no
//   session.
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
) -> dict[str, Any]:
    """The router's whole config: compose's by default; the local stack's router gives its
    loopback endpoint, its run's user/password file, its queue size and the ROS 2 domains it
    carries (``pnav up --robot-link ros2`` with no ``--ros-router``)."""
    return {
        "mode": "router",
        "listen": {"endpoints": list(listen)},
        "scouting": {"multicast": {"enabled": False}},
        "transport": {
            "auth": {"usrpwd": {"dictionary_file": dictionary_file}},
            "link": {"tx": {"queue": {"size": {"data": data_queue}}}},
        },
        "access_control": access_control(ros_domains),
    }


def render() -> str:
    """The text of deploy/zenoh/router.json5."""
    return HEADER + json.dumps(router_config(), indent=2) + "\n"


def main() -> int:
    sys.stdout.write(render())
    return 0


if __name__ == "__main__":
    sys.exit(main())
