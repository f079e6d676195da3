"""The ``forge`` fault: forged row images, put with the identities the bus lets put them.

For ``seconds``, every 0.1 s, it publishes on r1's keys:

- a forged ``command_recommendation`` image, as the controller (the Zenoh ACL lets the
  planner and the controller put on ``pnav/db/command_recommendation/*``): priority 1000,
  0.22 m/s straight ahead, an id no row has;
- a forged ``command2robot`` image, as the decision (the only identity that may put on
  ``pnav/db/command2robot/*``): the command that recommendation would have made, ids no
  row has.

Each goes out through the identity's own Zenoh credentials (the bench made them for the run:
pnav.run.local_stack.BusCredentials); without them, through the bench's own session (as the tests
do, past the ACL). Then it checks what the readers did with them: no command2robot row
written meanwhile cites a recommendation the table does not have, and no cmd_vel carried a
forged command id (the robot moved on none of them). Either one is a breach.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any

import zenoh

from common import bus
from common.contract import keys
from common.errors import ConnectionFailure

if TYPE_CHECKING:
    from pnav.bench.faults.catalogue import Fault
    from pnav.bench.faults.context import Context, Injection

FORGED_ID = 10**12  # the forgeries' ids count up from here: no table gets near it in a run
PERIOD_S = 0.1

_CITING_NOTHING = f"""
SELECT count(*) FROM {keys.COMMAND2ROBOT} c
WHERE c.id > $1 AND c.recommendation_id IS NOT NULL AND NOT EXISTS (
    SELECT 1 FROM {keys.COMMAND_RECOMMENDATION} r WHERE r.id = c.recommendation_id)"""


@contextmanager
def _sessions(ctx: Context, *identities: str) -> Iterator[tuple[dict[str, zenoh.Session], str]]:
    """A session per identity, with its own credentials (the ACL lets it put its keys)."""
    opened: dict[str, zenoh.Session] = {}
    how = "their own credentials"
    try:
        for who in identities:
            opened[who] = bus.open_session(ctx.bus.apply(ctx.zenoh, who))
        yield opened, how
    finally:
        for session in opened.values():
            session.close()


def _recommendation(row_id: int, robot: str, now: float) -> dict[str, Any]:
    return {
        "id": row_id,
        "robot_id": robot,
        "kind": "robot",
        "source": "safety_stop",
        "priority": 1000,
        "linear_mps": 0.22,
        "angular_rps": 0.0,
        "system_command": None,
        "stamp": now,
        "expires_stamp": now + 0.5,
        "inputs": {},
        "reason": "forged",
    }


def _command(row_id: int, robot: str, now: float) -> dict[str, Any]:
    return {
        "id": row_id,
        "robot_id": robot,
        "stamp": now,
        "linear_mps": 0.22,
        "angular_rps": 0.0,
        "recommendation_id": row_id,
        "source": "safety_stop",
        "considered_ids": [row_id],
        "reason": "forged",
    }


async def forge(fault: Fault, ctx: Context, robot: str) -> Injection:
    from pnav.bench.faults.context import Injection

    out = Injection()
    pool = ctx.rt.database.pool
    before = await pool.fetchval(f"SELECT coalesce(max(id), 0) FROM {keys.COMMAND2ROBOT}")
    relayed: list[int] = []

    def on_cmd_vel(_key: str, payload: bytes) -> None:
        body = bus.unpack(payload)
        command_id = body.get("command_id") if isinstance(body, dict) else None
        if isinstance(command_id, int) and command_id >= FORGED_ID:
            relayed.append(command_id)

    watch = bus.subscribe(ctx.rt.zenoh, keys.robot_key(robot, keys.CMD_VEL), on_cmd_vel)
    try:
        with _sessions(ctx, "controller", "decision") as (sessions, how):
            recommender = bus.Notifier(sessions["controller"])
            decider = bus.Notifier(sessions["decision"])
            end, n = time.monotonic() + fault.seconds, 0
            while time.monotonic() < end:
                now, row_id = ctx.rt.clock.now(), FORGED_ID + n
                recommender.notify(
                    keys.COMMAND_RECOMMENDATION, robot, row_id, _recommendation(row_id, robot, now)
                )
                decider.notify(keys.COMMAND2ROBOT, robot, row_id, _command(row_id, robot, now))
                n += 1
                await asyncio.sleep(PERIOD_S)
        out.notes.append(
            f"{n} forged recommendation images (priority 1000, 0.22 m/s) as the controller and "
            f"{n} forged command images as the decision, through {how}"
        )
    except ConnectionFailure as exc:
        out.notes.append(f"the router refused a forger's session: {exc}")
    finally:
        await asyncio.sleep(1.0)  # what was relayed arrives; the decision writes on
        watch.undeclare()
    cited = await pool.fetchval(_CITING_NOTHING, before)
    out.notes.append(
        f"command2robot rows citing a nonexistent recommendation: {cited}; "
        f"cmd_vel sent from a forged command: {len(relayed)}"
    )
    if cited or relayed:
        out.breaches.append(
            f"{cited} command(s) cited a forgery, {len(relayed)} cmd_vel relayed one"
        )
    return out
