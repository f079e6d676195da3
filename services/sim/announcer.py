"""The world without the physics, for a real robot (``--world-only``; `pnav up --no-sim`).

A real robot publishes its own readings (the ROS 2 link, docs/ROS2.md). What it cannot tell
the stack is what the bridge needs before the first of them: which robots there are, with
their models, the map and the charging stations. With ``--world-only`` the sim's process says
only that, from the world file, exactly as the full sim does: it publishes the world message
on ``pnav/sim/world`` at start and every ``period_s`` after, answers every query on it (the
bridge asks until it has one), and announces itself alive. It runs no physics and no
lidar, publishes no clock (the bridge takes ROS time, ``clock: ros``) and takes no cmd_vel:
the robot does.
"""

from __future__ import annotations

import logging
import threading

import zenoh

from common.bus import pack
from common.contract import keys
from common.log import event
from services.sim.world_spec import World

log = logging.getLogger(__name__)


def announce(
    world: World, session: zenoh.Session, stop: threading.Event, alive_key: str, period_s: float
) -> None:
    """Announce ``world`` on ``session`` until ``stop`` is set."""
    payload = pack(world.message())

    def on_query(query: zenoh.Query) -> None:
        query.reply(keys.SIM_WORLD, payload)

    publisher = session.declare_publisher(
        keys.SIM_WORLD, congestion_control=zenoh.CongestionControl.BLOCK
    )
    queryable = session.declare_queryable(keys.SIM_WORLD, on_query)
    token = session.liveliness().declare_token(alive_key)
    try:
        publisher.put(payload)
        event(
            log,
            logging.INFO,
            "world announced, no physics (--world-only): the robots publish their own readings",
            world=world.name,
            robots=",".join(spec.robot_id for spec in world.robots),
        )
        while not stop.wait(period_s):
            publisher.put(payload)
    finally:
        token.undeclare()
        queryable.undeclare()
        publisher.undeclare()
