"""Which charging station a robot drives to under CHARGE: the nearest by path length."""

from __future__ import annotations

import logging
import math

from common import log
from services.planner.routes import Router
from services.planner.world_model import RobotState, Station, World

logger = logging.getLogger("pnav.planner")

STATIONS_BY_PATH = 3  # nearest stations (straight line) whose path length is compared


def choose_station(
    world: World, router: Router, state: RobotState, x: float, y: float
) -> Station | None:
    """The nearest charger by path length (among the few nearest in a straight line),
    chosen once per CHARGE session so the target cannot flip while the robot drives."""
    if state.station is not None:
        return state.station
    data = world.map_for(state.info)
    here = [s for s in world.stations if data is None or s.map_id in (None, data.map_id)]
    if not here:
        here = list(world.stations)
    if not here:
        world.warn_once("no-station", "no charging station to go to", robot=state.info.robot_id)
        return None
    here.sort(key=lambda s: math.hypot(s.x - x, s.y - y))
    candidates = here[:STATIONS_BY_PATH] if data is not None else here[:1]
    state.station = min(candidates, key=lambda s: router.distance(state, (x, y), (s.x, s.y)))
    log.event(
        logger,
        logging.INFO,
        "charger chosen",
        robot=state.info.robot_id,
        station=state.station.station_id,
    )
    return state.station
