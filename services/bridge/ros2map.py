"""The map from a ROS 2 map server: ``/map`` (nav_msgs/OccupancyGrid) -> the world's map row.

With the robot-link file's ``map: /map`` the bridge's ROS 2 link subscribes that topic as a
map server publishes it (TRANSIENT_LOCAL, depth 1: a late subscription still gets the map,
through Zenoh's advanced subscriber, as rmw_zenoh's), and writes each grid into the row of
the world's map (``map_id`` = the world's name, the map the planner plans on), in place of
the grid the world's map file gave. The world's own row is written first, as always (its
charging stations refer to it); the ROS map then replaces its grid, and again whenever the
world is written anew. Only the newest grid is written; one that arrives while a write is
under way waits for it (a burst of maps costs one write, not one per map).

An OccupancyGrid becomes the contract's grid (CONTRACT.md, ``map``): the same layout (row-
major, row 0 at the origin's y), ``-1`` (unknown) -> 255, 0 to 100 kept. Refused, counted as
``malformed`` on ``ros2/map`` (reason): another frame than ``map`` (``wrong_frame``), a
resolution or origin that is not finite and positive, a size that is not width x height, a
value outside -1..100 (``out_of_range``), more than ``MAX_MAP_BYTES`` (``too_large``).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Final

import numpy as np

import services.bridge.sensor_payloads as messages
from common import ros2types
from common.contract import keys
from common.contract import rmw_zenoh as rz
from common.db import Database
from common.ros2node import Ros2Node, type_of_key
from common.tasks import cancel_and_wait
from services.bridge.sensor_payloads import MalformedMessage
from services.bridge.world_message import MAX_CELLS

logger = logging.getLogger("pnav.bridge.ros2")

TOPIC: Final = "ros2/map"
MAX_MAP_BYTES: Final = 64 * 1024 * 1024  # an 8000 x 8000 grid
WRONG_FRAME: Final = "wrong_frame"
MAP_FRAME: Final = "map"
UNKNOWN: Final = 255

UPDATE_SQL: Final = f"""
UPDATE {keys.MAP} SET resolution_m = $2, origin_x = $3, origin_y = $4, origin_yaw = $5,
    width = $6, height = $7, grid = $8, source = $9, loaded_at = now()
WHERE map_id = $1"""

OnMalformed = Callable[[str, str, str, str], None]  # topic, reason, detail, key


@dataclass(frozen=True)
class Grid:
    resolution: float
    origin_x: float
    origin_y: float
    origin_yaw: float
    width: int
    height: int
    grid: bytes


def grid_of(msg: Any) -> Grid:
    """An OccupancyGrid -> the contract's map columns, or MalformedMessage."""
    frame = msg.header.frame_id.strip("/")
    if frame not in ("", MAP_FRAME):
        raise MalformedMessage(WRONG_FRAME, f"frame {frame!r}: a map is in the map frame")
    info = msg.info
    # float32 on the wire: its shortest decimal (a map server's 0.05, not 0.0500000007)
    resolution = float(str(np.float32(info.resolution)))
    if not (math.isfinite(resolution) and 0 < resolution <= 1e3):
        raise MalformedMessage(messages.OUT_OF_RANGE, f"resolution {resolution}")
    width, height = int(info.width), int(info.height)
    if not (width >= 1 and height >= 1 and width * height <= MAX_CELLS):
        raise MalformedMessage(messages.OUT_OF_RANGE, f"{width} x {height} cells")
    data = np.asarray(msg.data, dtype=np.int8)
    if data.size != width * height:
        raise MalformedMessage(messages.OUT_OF_RANGE, f"{data.size} cells, not {width} x {height}")
    if data.size and (data.min() < -1 or data.max() > 100):
        raise MalformedMessage(messages.OUT_OF_RANGE, "a cell outside -1..100")
    pose = info.origin
    origin = (float(pose.position.x), float(pose.position.y), ros2types.yaw_of(pose.orientation))
    if not all(math.isfinite(v) and abs(v) <= messages.MAX_ABS_POSITION_M for v in origin):
        raise MalformedMessage(messages.NOT_FINITE, f"origin {origin}")
    cells = np.where(data < 0, UNKNOWN, data).astype(np.uint8)
    return Grid(resolution, *origin, width, height, cells.tobytes())


class Ros2Map:
    def __init__(self, node: Ros2Node, db: Database, topic: str, on_malformed: OnMalformed) -> None:
        self.node = node
        self.db = db
        self.topic = topic
        self.on_malformed = on_malformed
        self.world: str | None = None
        self.latest: Grid | None = None
        self.maps_written = 0
        self._written: tuple[str, Grid] | None = None
        self._wake = asyncio.Event()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._task: asyncio.Task[None] | None = None
        t = ros2types.ros_type(ros2types.OCCUPANCY_GRID)
        self._expected = (t.dds, t.hash)

    def start(self) -> None:
        self._loop = asyncio.get_running_loop()
        self.node.subscription(self.topic, ros2types.OCCUPANCY_GRID, self._from_zenoh, rz.LATCHED)
        self._task = asyncio.create_task(self._write_loop(), name="ros2-map")

    async def close(self) -> None:
        if self._task is not None:
            await cancel_and_wait([self._task])

    def world_applied(self, name: str) -> None:
        """The world's rows are written (again): its map row needs the ROS grid (again)."""
        self.world = name
        self._written = None
        self._wake.set()

    def _from_zenoh(self, key: str, payload: bytes, att: bytes | None) -> None:
        loop = self._loop
        if loop is None:
            return
        with contextlib.suppress(RuntimeError):  # the loop is closed: shutting down
            loop.call_soon_threadsafe(self._on_sample, key, payload)

    def _on_sample(self, key: str, payload: bytes) -> None:
        try:
            if type_of_key(key) != self._expected:
                raise MalformedMessage(messages.WRONG_TYPE, f"{key.rsplit('/', 2)[1]} on /map")
            if len(payload) > MAX_MAP_BYTES:
                raise MalformedMessage(messages.TOO_LARGE, f"{len(payload)} bytes")
            try:
                msg = ros2types.decode(ros2types.OCCUPANCY_GRID, payload)
            except Exception as exc:
                raise MalformedMessage("bad_cdr", str(exc)[:160]) from None
            self.latest = grid_of(msg)
        except MalformedMessage as exc:
            self.on_malformed(TOPIC, exc.reason, exc.detail, key)
            return
        self._wake.set()

    async def _write_loop(self) -> None:
        while True:
            await self._wake.wait()
            self._wake.clear()
            grid, world = self.latest, self.world
            if grid is None or world is None or self._written == (world, grid):
                continue
            try:
                await self._write(world, grid)
            except Exception as exc:
                logger.warning("ROS map not written: %s", exc)
                await asyncio.sleep(1.0)
                self._wake.set()  # try again

    async def _write(self, world: str, g: Grid) -> None:
        async with self.db.transaction() as tx:
            status = await tx.conn.execute(
                UPDATE_SQL,
                world,
                g.resolution,
                g.origin_x,
                g.origin_y,
                g.origin_yaw,
                g.width,
                g.height,
                g.grid,
                f"ros2:{self.node.topic(self.topic)}",
            )
            tx.changed(keys.MAP, None)
        if status.endswith(" 0"):
            raise RuntimeError(f"no map row {world!r} yet")
        self._written = (world, g)
        self.maps_written += 1
        logger.info("map %s from ROS %s: %d x %d cells", world, self.topic, g.width, g.height)
