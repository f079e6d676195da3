"""The skeleton every scenario service (strategy, planner, controller, decision) runs on.

Lifecycle of a :class:`ScenarioService`:

1. ``Runtime.open``: Postgres pool, Zenoh session, sim clock, liveliness token.
2. :meth:`ScenarioService.seed`: the subclass adds its meta rules (``engine.add_meta``).
3. The service subscribes to the change notifications of every table the meta rules watch;
   each one is handed to :meth:`ScenarioService.on_notification` and wakes the engine, both
   on the loop (:meth:`ScenarioService.watch`). The tables of
   :attr:`ScenarioService.listens` are handed to ``on_notification`` too, without waking
   the engine (row images a store keeps for later, e.g. odometry for a controller's next
   scan: services/controller/store.py says why the shipped one does not).
   In a lockstep run (PNAV_LOCKSTEP, common.lockstep) the runtime's ledger counts every
   subscription, and the engine (:meth:`ScenarioService.make_engine`) counts F in sim time
   and reports the service quiet whenever no activation is due.
4. Robot leases (common.lease, PNAV_LEASES=on by default): the service opens its lock
   connection and takes its share of the robots *before* the first activation (a lone
   replica owns every robot from the start). Rules act only for robots the replica owns:
   ``self.service.owns(robot_id)``. Every change of ownership wakes the engine
   (:meth:`ScenarioService.on_ownership_change`).
5. The engine runs; every ``stats_period_s`` its statistics are upserted into engine_stats.
   A service that runs scenarios a strategy names (planner, controller:
   :meth:`ScenarioService.offered_scenarios`) publishes them in scenario_offer before the
   engine starts and refreshes them every few seconds (common.contract.offers).
6. On SIGINT/SIGTERM: the engine finishes the activation under way (it is never cut in the
   middle of a rule), the offers are withdrawn, the robots are given back, the statistics
   are written one last time, the connections close.

A service module ends with ``if __name__ == "__main__": sys.exit(MyService.main())``.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from abc import ABC, abstractmethod
from collections.abc import Collection
from typing import ClassVar

import zenoh

from common import bus, log
from common.bus import Notification
from common.config import ServiceConfig
from common.contract import keys, offers
from common.engine import Engine
from common.lease import LeaseManager
from common.lockstep import Ledger, LockstepTrigger
from common.runtime import Runtime, run_service

logger = logging.getLogger("pnav.service")

_UPSERT_STATS = """
INSERT INTO engine_stats AS s (service, instance, rule_type, scenario, executed, activated,
                               acted, errors, total_time_s, max_time_s, updated_at)
VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, now())
ON CONFLICT (service, instance, rule_type) DO UPDATE SET
    scenario = EXCLUDED.scenario, executed = EXCLUDED.executed,
    activated = EXCLUDED.activated, acted = EXCLUDED.acted, errors = EXCLUDED.errors,
    total_time_s = EXCLUDED.total_time_s, max_time_s = EXCLUDED.max_time_s,
    updated_at = now()
"""


def wake_on_notifications(
    session: zenoh.Session,
    engine: Engine,
    tables: tuple[str, ...],
    observer: bus.Handler | None = None,
    *,
    ledger: Ledger | None = None,
) -> list[zenoh.Subscriber[None]]:
    """Subscribe to ``tables``' notifications; each one wakes ``engine`` from Zenoh's thread
    (``Engine.wake_threadsafe``: one loop iteration to the activation). No store is told:
    for an engine without one (pnav bench engine). ``observer(key, payload)``, if given, runs
    first on Zenoh's thread (instrumentation: it must be quick and thread-safe). With a
    ``ledger`` (lockstep) a notification counts as handled once the engine's flag is set.
    """
    wake = engine.wake_threadsafe

    def on_notification(key: str, payload: bytes) -> None:
        if observer is not None:
            observer(key, payload)
        wake()

    return [
        bus.subscribe_threaded(session, keys.notify_watch(table), on_notification, ledger=ledger)
        for table in tables
    ]


class ScenarioService(ABC):
    """A service made of scenarios run by one Proactive Engine."""

    service: ClassVar[str] = ""
    # Tables whose notifications go to on_notification without waking the engine: a store
    # keeps their row images for the rules a watched table wakes (e.g. each robot's newest
    # odometry image for the controller's next scan). Tables the meta rules watch wake.
    listens: frozenset[str] = frozenset()

    def __init__(self, runtime: Runtime) -> None:
        self.runtime = runtime
        self.config: ServiceConfig = runtime.config
        self.engine = self.make_engine(runtime)
        self.leases: LeaseManager | None = None

    @staticmethod
    def make_engine(runtime: Runtime) -> Engine:
        """The service's engine: F on the wall clock, or in a lockstep run (common.lockstep)
        on sim time with the lockstep trigger (which reports the service quiet)."""
        config, ledger = runtime.config, runtime.ledger
        if ledger is None:
            return Engine(config.engine, name=config.service)
        trigger = LockstepTrigger(ledger)
        return Engine(config.engine, name=config.service, trigger=trigger, clock=runtime.clock.now)

    @abstractmethod
    def seed(self) -> None:
        """Add this service's meta rules to ``self.engine`` with ``engine.add_meta``."""

    def offered_scenarios(self) -> Collection[str] | None:
        """The scenarios this service can run, published in scenario_offer while it runs
        (common.contract.offers; the planner and the controller), after :meth:`seed`;
        None: it offers none."""
        return None

    def notifications_lost(self) -> int | None:
        """How many change notifications from other processes never reached this one (a skip
        in a publisher's ``seq``: its reader read the table instead), for the "engine
        stopped" line; None for a service that does not follow the numbering."""
        return None

    def images_refused(self) -> dict[str, int] | None:
        """Row images refused per table because they broke the table's rules (common.images:
        the table was read instead), for the "engine stopped" line; None for a service that
        acts on no image."""
        return None

    # -- robot ownership (replicas) ---------------------------------------------------------
    def owns(self, robot_id: str) -> bool:
        """Whether this replica handles ``robot_id`` now: act (recommend, decide, plan) for a
        robot only while this is true.

        Replicas of one service split the robots through Postgres advisory locks
        (common.lease); each robot is owned by exactly one live replica. A lone replica owns
        every robot. Always true when leases are off (PNAV_LEASES=off) or before
        :meth:`run` has started them (a service object used directly in a test).
        """
        leases = self.leases
        return True if leases is None else leases.owns(robot_id)

    def owned_robots(self) -> frozenset[str] | None:
        """The robots this replica owns now, or None when it handles every robot (leases
        off or not started)."""
        leases = self.leases
        return None if leases is None else leases.owned

    def on_ownership_change(self, gained: frozenset[str], lost: frozenset[str]) -> None:
        """Called on the loop when this replica takes robots (``gained``, after their locks
        are held) or gives them up (``lost``, before their locks are released, or at once
        when the lock connection is lost). Wakes the engine, so a taken-over robot is served
        in the next activation.

        A service that keeps per-robot state in memory overrides this to drop the ``lost``
        robots' state and to rebuild the ``gained`` ones' from the contract tables (another
        replica served them until now); it must call ``super().on_ownership_change``.
        """
        self.engine.wake()

    async def start_leases(self) -> None:
        """Open the lease manager and take this replica's share before the engine runs;
        wake it early when a replica of this service comes or goes (Zenoh liveliness) or
        a robot is registered (robot notifications)."""
        settings = self.config.leases
        if not settings.enabled:
            log.event(logger, logging.INFO, "leases off: this replica handles every robot")
            return
        leases = LeaseManager(
            self.config.database_url,
            self.config.service,
            self.config.instance,
            settings,
            on_change=self.on_ownership_change,
            under_way=self.engine.under_way,
            notify=self.runtime.database.notifier.notify,
            connect_wait_s=self.config.db_wait_s,
        )
        await leases.start()
        self.leases = leases
        poke = leases.poke_threadsafe

        def on_liveliness(sample: zenoh.Sample) -> None:
            poke()

        try:
            session = self.runtime.zenoh
            alive = session.liveliness().declare_subscriber(
                keys.alive_watch(self.config.service), on_liveliness
            )
            self.runtime.on_close(alive.undeclare)
            robots = bus.subscribe_threaded(
                session,
                keys.notify_watch(keys.ROBOT),
                lambda _key, _payload: poke(),
                ledger=self.runtime.ledger,
            )
            self.runtime.on_close(robots.undeclare)
        except BaseException:
            await self.stop_leases()
            raise
        log.event(
            logger,
            logging.INFO,
            "leases on",
            owned=len(leases.owned),
            replicas=leases.replicas,
            backend_pid=leases.backend_pid,
        )

    async def stop_leases(self) -> None:
        """Give every robot back (the engine has drained: nothing acts for them any more)."""
        if self.leases is not None:
            try:
                await self.leases.stop()
            except Exception:
                logger.warning("could not release the robot leases", exc_info=True)

    def on_notification(self, note: Notification) -> None:
        """A change notification of a table the meta rules watch, on the event loop, just
        before it wakes the engine (or of a table of :attr:`listens`, which wakes nothing).
        A service hands it to its store, which keeps what the notifications told it
        (common.freshness); the default does nothing.

        ``note.id`` is None when the notification named no row or its payload was
        unreadable: then anything of ``note.table`` (for ``note.robot``) may have changed.
        """
        return None

    def watch(self) -> None:
        """On every notification of a table the meta rules watch: :meth:`on_notification`,
        then wake the engine for the notification's robot (docs/ENGINE.md, "Per-robot
        wake-ups": the meta rules and that robot's rules run). Both run on the event loop
        (one hop from Zenoh's thread), so a store needs no locks; in a lockstep run the
        message counts as handled after both. A table of :attr:`listens` only (the meta
        rules do not watch it): on_notification alone."""
        engine, note = self.engine, self.on_notification

        def decode(key: str, payload: bytes) -> Notification:
            try:
                decoded = Notification.decode(key, payload)
            except ValueError:
                try:
                    table, robot = keys.parse_notify_key(key)
                except ValueError:
                    table, robot = "", None
                decoded = Notification(table, robot, None)
            return decoded

        def on_message(key: str, payload: bytes) -> None:
            decoded = decode(key, payload)
            if decoded.table:
                note(decoded)
            # focused on the notification's robot (a robot-less one wakes for anything)
            engine.wake(decoded.robot)

        def on_listened(key: str, payload: bytes) -> None:
            decoded = decode(key, payload)
            if decoded.table:
                note(decoded)

        session, ledger = self.runtime.zenoh, self.runtime.ledger
        watched = tuple(engine.watched_tables)
        handlers = [(t, on_message) for t in watched]
        handlers += [(t, on_listened) for t in sorted(self.listens) if t not in watched]
        for table, handler in handlers:
            key_expr = keys.notify_watch(table)
            subscriber = bus.subscribe(session, key_expr, handler, ledger=ledger)
            self.runtime.on_close(subscriber.undeclare)

    async def publish_stats(self) -> None:
        """Upsert this engine's statistics into engine_stats and notify."""
        rows = [
            (
                self.config.service,
                self.config.instance,
                s.rule_type,
                s.scenario,
                s.executed,
                s.activated,
                s.acted,
                s.errors,
                s.total_time_s,
                s.max_time_s,
            )
            for s in self.engine.stats()
        ]
        if not rows:
            return
        db = self.runtime.database
        async with db.pool.acquire() as conn:
            await conn.executemany(_UPSERT_STATS, rows)
        db.notifier.notify(keys.ENGINE_STATS, None, None)

    async def _stats_loop(self) -> None:
        while True:
            await asyncio.sleep(self.config.stats_period_s)
            try:
                await self.publish_stats()
            except Exception:
                logger.warning("could not write engine_stats", exc_info=True)

    async def run(self, stop: asyncio.Event) -> None:
        """Seed, watch, lease, and run the engine until ``stop`` is set; then drain."""
        self.seed()
        self.watch()
        offered, config = self.offered_scenarios(), self.config
        offer = None
        if offered is not None:
            offer = offers.Publisher(
                self.runtime.database, config.service, config.instance, offered
            )
            await offer.publish()  # before the engine runs: switches are judged on them
        await self.start_leases()
        log.event(
            logger,
            logging.INFO,
            "engine started",
            rules=len(self.engine),
            watches=",".join(self.engine.watched_tables),
            period_ms=self.config.engine.period_s * 1000,
            max_rules=self.config.engine.max_rules,
        )
        engine_task = asyncio.create_task(self.engine.run(), name="engine")
        stats_task = asyncio.create_task(self._stats_loop(), name="engine-stats")
        offers_task = None if offer is None else asyncio.create_task(offer.refresh())
        stop_task = asyncio.create_task(stop.wait(), name="stop")
        try:
            done, _ = await asyncio.wait(
                {engine_task, stop_task}, return_when=asyncio.FIRST_COMPLETED
            )
            if engine_task in done:
                engine_task.result()  # the engine only returns early on a bug: raise it
        finally:
            self.engine.stop()
            stop_task.cancel()
            stats_task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await stats_task
            if offers_task is not None:
                offers_task.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await offers_task
            if not engine_task.done():
                # Drain: let the activation under way finish, within a bound.
                try:
                    await asyncio.wait_for(engine_task, self.config.engine.period_s * 4 + 5.0)
                except TimeoutError:
                    logger.error("engine did not drain in time; cancelled")
            if not self.engine.running:
                self.engine.close()  # the running behaviours end ("the service stopped")
            if offer is not None:
                await offer.withdraw()
            await self.stop_leases()
            lost = self.notifications_lost()
            extra: dict[str, object] = {} if lost is None else {"notifications_lost": lost}
            refused = self.images_refused()
            if refused is not None:
                extra["images_refused"] = sum(refused.values())
                extra.update({f"images_refused_{t}": n for t, n in sorted(refused.items())})
            log.event(
                logger, logging.INFO, "engine stopped", **self.engine.counters.as_dict(), **extra
            )
            try:
                await self.publish_stats()
            except Exception:
                logger.warning("final engine_stats write failed", exc_info=True)

    @classmethod
    async def serve(
        cls, config: ServiceConfig, stop: asyncio.Event, session: zenoh.Session | None = None
    ) -> None:
        """Run until ``stop`` is set; ``session``: a host's shared Zenoh session (pnav.run.host,
        which finds this entry by the service's name in the ``pnav.services`` entry points)."""
        runtime = await Runtime.open(config, session=session)
        try:
            await cls(runtime).run(stop)
        finally:
            await runtime.close()

    @classmethod
    def main(cls, argv: list[str] | None = None) -> int:
        """Process entry point: ``sys.exit(MyService.main())``."""
        return run_service(cls.service, cls.serve, argv)
