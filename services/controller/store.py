"""What the controller keeps of its reads and writes of the contract: its store.

- :class:`~services.controller.source.ControllerSource`: the raw typed reads and the one
  write, as a Protocol, and :class:`~services.controller.source.PgControllerSource`, them in
  Postgres (services/controller/source.py; re-exported here); pnav/monolith/memory_controller.py
  has them in memory;
- :class:`ControllerStore`: the one object the service holds. It implements the rules'
  :class:`~common.controller_core.scenario.Host`, keeps the caches, and learns from the
  change notifications (:meth:`ControllerStore.note`, on the event loop) when to read again
  (common.freshness): an activation woken by one robot's scan reads that robot's scan only,
  not every robot's, and the robots and strategies only after one of them changed.

Row images (CONTRACT.md "Row images"): a laser_scan notification with its row becomes the
robot's newest scan without a query; the odometry the scan is decided with is the newest
odometry image heard, if the service hears odometry (:attr:`ControllerStore.listens`: it
does not by default), else one query for the odometry alone. Either falls back to the table
as the contract says: no image, a ``seq`` gap (``common.freshness.Sequences``), or nothing
heard for ``recheck_s`` (the scan cache's period, as without images).

A people's lock (CONTRACT.md, *Roles*): the people's role may UPDATE, so lock, ``strategy``,
which the meta-controller reads with the robots. That read waits behind a lock for
:data:`~services.controller.source.STRATEGY_LOCK_WAIT_MS` at most (the service's other
statements: its ``lock_timeout``, common.db.lock_settings); the store then serves the robots
and strategies it read before, and reads them again in the background, never in an
activation, until a read gets through:
safety_stop, which reads scans and odometry only, waits behind a lock once, that long.

Batching across robots (docs/ARCHITECTURE.md): the odometry query asks, in the same round
trip, for every other robot served whose scan came as an image and has none yet (their rules
run later in the same activation); and in the service, recommendations are held until the
activation ends and written in one statement (:meth:`ControllerStore.defer_recommendations`,
common.writebehind).
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Awaitable, Callable, Iterable
from typing import Any

import asyncpg

from common import log
from common.bus import Notification
from common.contract import keys, records
from common.contract.models import RegisteredModel, pick
from common.contract.planned_path import PlannedPath, planned_path_of
from common.contract.recommendations import (
    Recommendation,
    recommendation_key,
)
from common.contract.records import ActiveStrategy, LaserScan, Odometry, Robot
from common.controller_core.scenario import Key
from common.freshness import FreshCache
from common.images import GuardedStore, ImageGuard
from common.writebehind import WriteBehind
from services.controller.source import (
    ControllerSource,
    ScanAndOdometry,
)

logger = logging.getLogger("pnav.controller")

# Notifications are hints: a row is read again after this long (store clock) even if none
# came, in case one was lost.
RECHECK_S = 0.25
MODELS_RECHECK_S = 2.0  # the model register, read whole for the learned scenarios (or notified)
ODOMETRY_LISTENS = frozenset((keys.ODOMETRY,))  # see ControllerStore.listens

Tables = tuple[list[Robot], dict[str, ActiveStrategy]]

_META = "robots and strategies"  # the one key of the meta cache: read together, stale together
_META_TABLES = frozenset((keys.ACTIVE_STRATEGY, keys.STRATEGY, keys.ROBOT))
LOCKED_LOG_S = 10.0  # a lock on the meta tables is logged at most this often (wall time)


def _scan_id(pair: ScanAndOdometry) -> int | None:
    return pair[0].id if pair[0] is not None else None


def _path_id(path: PlannedPath | None) -> int | None:
    return path.id if path is not None else None


def _announce(
    cache: FreshCache[str, Any], note: Notification, image: Callable[[str, Notification], bool]
) -> None:
    """A row of ``cache``'s table changed: every robot's entry is stale when the note names
    no robot, else that robot's, unless ``image`` took the row from the note."""
    if note.robot is None:
        cache.announce_all()
    elif not image(note.robot, note):
        cache.announce(note.robot, note.id)


class ControllerStore(GuardedStore):
    """The rules' :class:`~common.controller_core.scenario.Host` over a source, with caches.

    ``clock`` is what the caches count ``recheck_s`` in (wall time in a service, sim time in
    a lockstep or in-process run); ``sim_now`` is sim time for the rules (None before the
    first clock message; ``clock`` if not given).
    """

    # Tables the service should hear without waking the engine (ScenarioService.listens):
    # none. Hearing odometry (an image per row, 20-30 Hz per robot) would spare the one
    # odometry query per scan, and note() keeps those images if they come; measured on the
    # latency bench (10 robots, with the bridge sending images) it cost the controller about
    # 10 points of a core more than the query it saves, with no latency gain to see: each
    # notification crosses from Zenoh's thread to the loop (and takes the GIL) for a row
    # that only matters at the next scan. ODOMETRY_LISTENS is the set to hear it.
    # planned_path is heard (a row per plan: a few a minute per robot), for the local
    # controllers that score against the path (docs/CONTROLLER.md, dwa); read only by the
    # scenarios that ask for it (Host.planned_path). model: a new row is seen at once.
    listens: frozenset[str] = frozenset((keys.PLANNED_PATH, keys.MODEL))

    def __init__(
        self,
        source: ControllerSource,
        clock: Callable[[], float],
        sim_now: Callable[[], float | None] | None = None,
        recheck_s: float = RECHECK_S,
        serves: Callable[[str], bool] | None = None,
    ) -> None:
        """``serves(robot)``: whether this replica acts for the robot (its lease), so that
        one odometry query asks only for robots a rule here may decide on (default: all)."""
        self.source = source
        self._serves = serves or (lambda _robot: True)
        # recommendations held until the activation ends (defer_recommendations); None:
        # each one written when a rule asks
        self.outbox: WriteBehind[Recommendation] | None = None
        self._clock = clock
        self._sim_now = sim_now or clock
        self.recheck_s = recheck_s
        self.tables: FreshCache[str, Tables] = FreshCache(clock, recheck_s)
        # per robot: its newest scan with the odometry read in the same round trip (the
        # avoid scenarios and safety_stop want both, for the same scan)
        self.scans: FreshCache[str, ScanAndOdometry] = FreshCache(clock, recheck_s, _scan_id)
        # per robot: the path in force (planned_path), for the scenarios that ask for it
        self.paths: FreshCache[str, PlannedPath | None] = FreshCache(clock, recheck_s, _path_id)
        self.models: FreshCache[str, list[RegisteredModel]] = FreshCache(clock, MODELS_RECHECK_S)
        # per robot: (scan id, odometry) for a scan whose odometry the pair above does not
        # hold (an image's scan, or one the pair no longer holds)
        self._odometry: dict[str, tuple[int, Odometry | None]] = {}
        # robots whose cached pair came from a scan image: its odometry slot means nothing
        self._imaged: set[str] = set()
        # per robot: the newest odometry image and the store clock when it came (None: the
        # last one is unusable, a gap or no image: read the table)
        self._odometry_images: dict[str, tuple[Odometry, float] | None] = {}
        # images held to their table's rules before they stand in for a query
        self.images = ImageGuard(logger)
        # images that stood in for a query (tests, benchmarks)
        self.images_used = 0
        self.odometry_images_used = 0
        self.odometry_reads = 0
        # per (robot, scenario): the newest scan it recommended on, so that a scenario
        # restarted (or named again) never recommends twice on one scan
        self._recommended: dict[Key, int] = {}
        # a lock refused the last read of the robots and strategies: the ones held serve,
        # and _refresh reads them again off the activations
        self.meta_locked = False
        self.meta_lock_refusals = 0  # reads a lock refused (tests, logs)
        self._refresh: asyncio.Task[None] | None = None
        self._lock_logged_at = -LOCKED_LOG_S

    # -- what the service tells it ---------------------------------------------------------
    def note(self, note: Notification) -> None:
        """A change notification (on the event loop, before the engine wakes, if it does)."""
        if note.table == keys.LASER_SCAN:
            _announce(self.scans, note, self._scan_image)
        elif note.table == keys.ODOMETRY:
            if note.robot is not None:
                self._odometry_image(note.robot, note)
        elif note.table == keys.PLANNED_PATH:
            _announce(self.paths, note, self._path_image)
        elif note.table == keys.MODEL:
            self.models.announce(keys.MODEL)
        elif note.table in _META_TABLES or not note.table:
            self.tables.announce(_META)  # which row changed does not matter: read both again

    def _usable(self, note: Notification) -> bool:
        """Whether ``note``'s image may stand in for the query (CONTRACT.md "Row images");
        records the seq either way."""
        return not self.images.gap(note) and note.row is not None

    def _odometry_image(self, robot_id: str, note: Notification) -> None:
        odometry = self.images.record(note, records.odometry_of) if self._usable(note) else None
        if odometry is None:
            self._odometry_images[robot_id] = None  # no image the table's rules allow: read it
            return
        held = self._odometry_images.get(robot_id)
        if held is None or odometry.id > held[0].id:
            self._odometry_images[robot_id] = (odometry, self._clock())

    def _scan_image(self, robot_id: str, note: Notification) -> bool:
        """Keep a scan image as the robot's newest scan; False if it cannot stand in."""
        if not self._usable(note) or note.row is None:
            return False
        held = self.scans.peek(robot_id)
        if held is not None and held[0] is not None and held[0].id >= (note.id or 0):
            return True  # an older scan than the one held: nothing to do
        scan = self.images.record(note, records.laser_scan_of)
        if scan is None:
            return False
        self.scans.put(robot_id, (scan, None))
        self._imaged.add(robot_id)
        self.images_used += 1
        return True

    def _path_image(self, robot_id: str, note: Notification) -> bool:
        """Keep a planned_path image as the robot's path in force; False if it cannot."""
        if not self._usable(note) or note.row is None:
            return False
        held = self.paths.peek(robot_id)
        if held is not None and held.id >= (note.id or 0):
            return True
        path = self.images.record(note, planned_path_of)
        if path is None:
            return False
        self.paths.put(robot_id, path)
        return True

    def forget(self, robots: Iterable[str]) -> None:
        """Drop what was read and written for ``robots`` (they changed hands: another
        replica served, or will serve, them)."""
        gone = frozenset(robots)
        for robot_id in gone:
            self.scans.forget(robot_id)
            self.paths.forget(robot_id)
            self._odometry.pop(robot_id, None)
            self._odometry_images.pop(robot_id, None)
            self._imaged.discard(robot_id)
        for key in [k for k in self._recommended if k[0] in gone]:
            del self._recommended[key]

    # -- Host --------------------------------------------------------------------------------
    def sim_now(self) -> float | None:
        return self._sim_now()

    async def robots(self) -> list[Robot]:
        return (await self._tables())[0]

    async def active_strategies(self) -> dict[str, ActiveStrategy]:
        return (await self._tables())[1]

    async def _tables(self) -> Tables:
        """The robots and strategies; those held while a lock refuses reading them."""
        held = self.tables.peek(_META)
        if held is None or not self.meta_locked:
            try:
                return await self.tables.get(_META, self._read_tables)
            except asyncpg.LockNotAvailableError as exc:
                if held is None:
                    raise  # nothing to serve yet: the rule fails, and runs again
                self._refused(exc)
                return held
        refresh = self._refresh
        if (refresh is None or refresh.done()) and self.tables.stale(_META):
            self._refresh = asyncio.create_task(self._read_again(), name="controller-meta-read")
        return held

    async def _read_again(self) -> None:
        """Read the robots and strategies once, off the activations (a lock refused them)."""
        try:
            await self.tables.get(_META, self._read_tables)
        except asyncpg.LockNotAvailableError as exc:
            self._refused(exc)  # still locked: tried again once the held ones are stale
            return
        except Exception:
            # not a lock (the connection, say): the next activation reads, and the engine
            # reports what fails there as for any rule
            self.meta_locked = False
            return
        self.meta_locked = False
        log.event(logger, logging.INFO, "robots and strategies read again after a lock")

    def _refused(self, exc: Exception) -> None:
        self.meta_locked = True
        self.meta_lock_refusals += 1
        now = time.monotonic()
        if now - self._lock_logged_at >= LOCKED_LOG_S:
            self._lock_logged_at = now
            log.event(
                logger,
                logging.WARNING,
                "robots and strategies locked: serving those read before",
                refusals=self.meta_lock_refusals,
                error=repr(exc),
            )

    async def newest_scan(self, robot_id: str) -> LaserScan | None:
        async def read() -> ScanAndOdometry:
            pair = await self.source.newest_scan_and_odometry(robot_id)
            self._imaged.discard(robot_id)  # the pair's odometry was read with its scan
            return pair

        return (await self.scans.get(robot_id, read))[0]

    async def odometry_at(self, scan: LaserScan) -> Odometry | None:
        robot_id = scan.robot_id
        cached = self._odometry.get(robot_id)
        if cached is not None and cached[0] == scan.id:
            return cached[1]  # from an odometry image, or read for this scan before
        pair = self.scans.peek(robot_id)
        if (
            pair is not None
            and pair[0] is not None
            and pair[0].id == scan.id
            and robot_id not in self._imaged
        ):
            return pair[1]  # read with the scan: no round trip
        if pair is not None and pair[0] is not None and pair[0].id == scan.id:
            # a scan from its image: the newest odometry image, if one came within the
            # store's period, is what the query would read now (fixed for this scan)
            image = self._odometry_images.get(robot_id)
            if image is not None and self._clock() - image[1] < self.recheck_s:
                self.odometry_images_used += 1
                self._odometry[robot_id] = (scan.id, image[0])
                return image[0]
        return await self._read_odometry(robot_id, scan.id)

    async def _read_odometry(self, robot_id: str, scan_id: int) -> Odometry | None:
        """Read the robot's odometry for ``scan_id``, and in the same round trip that of
        every other robot served whose scan from an image has none yet: their rules, later
        in this activation, find it here (docs/ARCHITECTURE.md: one query for many robots).
        Read after every one of those scans was heard, it is what each robot's own query
        would have read."""
        wanted = {robot_id: scan_id}
        now = self._clock()
        for other in self._imaged:
            pair = self.scans.peek(other)
            if pair is None or pair[0] is None or other in wanted:
                continue
            other_scan = pair[0].id
            held = self._odometry.get(other)
            if held is not None and held[0] == other_scan:
                continue  # it has its odometry
            image = self._odometry_images.get(other)
            if image is not None and now - image[1] < self.recheck_s:
                continue  # an odometry image will stand in (when the service hears them)
            if self._serves(other):
                wanted[other] = other_scan
        if len(wanted) == 1:
            found = {robot_id: await self.source.newest_odometry(robot_id)}
        else:
            found = await self.source.newest_odometries(list(wanted))
        self.odometry_reads += 1
        for robot, for_scan in wanted.items():
            self._odometry[robot] = (for_scan, found.get(robot))
        return found.get(robot_id)

    async def planned_path(self, robot_id: str) -> PlannedPath | None:
        return await self.paths.get(robot_id, lambda: self.source.newest_planned_path(robot_id))

    async def registered_model(self, name: str, version: str | None) -> RegisteredModel | None:
        return pick(await self.models.get(keys.MODEL, self.source.models), name, version)

    def last_recommended_scan(self, robot_id: str, source: str) -> int | None:
        return self._recommended.get((robot_id, source))

    async def recommend(self, recommendation: Recommendation) -> None:
        if self.outbox is not None:
            self.outbox.add(recommendation, self._written)
            return
        self._written(recommendation, await self.source.recommend(recommendation))

    def defer_recommendations(self) -> Callable[[], Awaitable[None]]:
        """Hold every recommendation until the returned hook is awaited, then write them
        in one statement (``Engine.at_activation_end``: common.writebehind). Without it
        each is written when its rule asks."""
        if self.outbox is None:
            self.outbox = WriteBehind(
                self.source.recommend_many, recommendation_key, "command_recommendation"
            )
        return self.outbox.flush

    def _written(self, r: Recommendation, row_id: int | None) -> None:
        if row_id is None:
            return  # refused or lost (logged): the scenario may recommend on the scan again
        if r.scan_id is not None:
            self._recommended[(r.robot_id, r.source)] = r.scan_id
        log.event(
            logger,
            logging.DEBUG,
            "recommended",
            robot=r.robot_id,
            source=r.source,
            id=row_id,
            linear=round(r.linear_mps or 0.0, 3),
            angular=round(r.angular_rps or 0.0, 3),
            reason=r.reason,
        )

    async def _read_tables(self) -> Tables:
        return await self.source.robots(), await self.source.active_strategies()
