"""``GET /metrics``: the running stack in the Prometheus text format (docs/METRICS.md).

The dashboard mounts it on its own port. The API::

    metrics = Metrics(MetricsConfig.from_env())
    await metrics.start(pool, session)  # asyncpg pool; Zenoh session (supervisor reports)
    metrics.note(notification)          # for every change notification the dashboard receives
    routes = metrics.routes()           # [GET /metrics], for the Starlette app
    ...
    await metrics.close()               # stops its reads and its subscription

Where the numbers come from (a foreign client of the contract: notifications and SELECTs):

- engine statistics: the ``engine_stats`` table, read every ``refresh_s``;
- rows per table: the notifications handed to :meth:`note` (the advance of the table's ``id``,
  or one row per notification for tables without one);
- sense-to-act: the provenance of new ``command2robot`` rows (their recommendation's
  ``inputs`` name the sensor row); from the sensor row's insert to the decision's insert,
  Postgres' clock at both ends, once per recommendation (the first command that obeyed it);
- lease ownership: open ``robot_lease`` rows whose holder holds the advisory lock now;
- supervisor restarts: what ``pnav up`` publishes on ``pnav/supervisor/{launcher}``.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import time
from collections import OrderedDict, deque
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

import asyncpg
import zenoh
from prometheus_client import (
    CollectorRegistry,
    Counter,
    Histogram,
    disable_created_metrics,
    generate_latest,
)
from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, Metric
from prometheus_client.exposition import CONTENT_TYPE_PLAIN_0_0_4
from prometheus_client.registry import Collector
from starlette.requests import Request
from starlette.responses import Response
from starlette.routing import BaseRoute, Route

from common import bus
from common.config import env_number
from common.contract import keys
from common.tasks import cancel_and_wait
from services.dashboard.metrics_source import (
    ID_TABLES,
    EngineRow,
    Lease,
    MetricsSource,
    SqlMetricsSource,
    origin_of,
)

log = logging.getLogger("pnav.dashboard.metrics")

# 1 ms .. 2 s: the design's bar is 5 ms p99 at 20 Hz; one robot measured 12-20 ms p99
LATENCY_BUCKETS = (0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0)
_SEEN_CAP = 50_000  # recommendations remembered as already sampled


@dataclass(frozen=True)
class MetricsConfig:
    """``PNAV_METRICS_REFRESH_S`` (1.0): how often the tables are read;
    ``PNAV_METRICS_RATE_WINDOW_S`` (10.0): the window of ``pnav_table_rows_per_second``."""

    refresh_s: float = 1.0
    rate_window_s: float = 10.0

    @classmethod
    def from_env(cls, env: Mapping[str, str] | None = None) -> MetricsConfig:
        env = os.environ if env is None else env

        def seconds(name: str, default: float) -> float:
            return env_number(
                env,
                name,
                default,
                float,
                ok=lambda value: 0.05 <= value <= 3600,
                must="must be seconds from 0.05 to 3600",
            )

        return cls(
            seconds("PNAV_METRICS_REFRESH_S", cls.refresh_s),
            seconds("PNAV_METRICS_RATE_WINDOW_S", cls.rate_window_s),
        )


@dataclass
class _Snapshot:
    """What the last read of the tables and the supervisor reports said."""

    engine: list[EngineRow] = field(default_factory=list)
    leases: list[Lease] = field(default_factory=list)
    robots: int = 0
    # launcher key -> process name -> (restarts, running)
    supervisors: dict[str, dict[str, tuple[int, bool]]] = field(default_factory=dict)


class Metrics:
    """The registry behind ``GET /metrics`` and what fills it (module docstring)."""

    def __init__(
        self, config: MetricsConfig | None = None, *, source: MetricsSource | None = None
    ) -> None:
        self.config = config or MetricsConfig()
        self.source = source
        # a `_created` series per counter doubles the exposition for nothing Prometheus uses
        disable_created_metrics()
        self.registry = CollectorRegistry(auto_describe=True)
        self.notifications = Counter(
            "pnav_notifications", "Change notifications seen", ["table"], registry=self.registry
        )
        self.rows = Counter(
            "pnav_table_rows", "Rows written per contract table", ["table"], registry=self.registry
        )
        self.sense_to_act = Histogram(
            "pnav_sense_to_act_seconds",
            "Sensor row stored to the decision obeying it stored",
            ["robot", "origin"],
            buckets=LATENCY_BUCKETS,
            registry=self.registry,
        )
        self.stages = Histogram(
            "pnav_sense_to_act_stage_seconds",
            "Sense-to-act by stage",
            ["stage"],
            buckets=LATENCY_BUCKETS,
            registry=self.registry,
        )
        self.refresh_errors = Counter(
            "pnav_metrics_refresh_errors", "Failed reads of the tables", registry=self.registry
        )
        self.snapshot = _Snapshot()
        self._newest: dict[str, int] = {}
        self._recent: dict[str, deque[tuple[float, int]]] = {}
        self._seen: OrderedDict[int, None] = OrderedDict()
        self._last_command = 0
        self._first_recommendation = 0
        self._started = time.monotonic()
        self._task: asyncio.Task[None] | None = None
        self._subscriber: Any = None
        self._failing = False
        self.registry.register(_StackCollector(self))

    # -- lifecycle -------------------------------------------------------------------------
    async def start(self, pool: asyncpg.Pool, session: zenoh.Session | None = None) -> None:
        """Take the tables' newest ids as the baseline, subscribe to supervisor reports,
        start the periodic reads. Decisions made before now are not sampled."""
        if self.source is None:
            self.source = SqlMetricsSource(pool)
        newest = await self.source.newest_ids()
        for table, row_id in newest.items():
            self._newest[table] = max(self._newest.get(table, 0), row_id)
        self._last_command = newest.get(keys.COMMAND2ROBOT, 0)
        self._first_recommendation = newest.get(keys.COMMAND_RECOMMENDATION, 0)
        if session is not None:
            self._subscriber = bus.subscribe(session, keys.SUPERVISOR_WATCH, self._on_supervisor)
        await self.refresh()
        self._task = asyncio.create_task(self._loop(), name="metrics-refresh")

    async def close(self) -> None:
        if self._task is not None:
            await cancel_and_wait([self._task])
            self._task = None
        if self._subscriber is not None:
            with contextlib.suppress(Exception):
                self._subscriber.undeclare()
            self._subscriber = None

    def routes(self) -> list[BaseRoute]:
        return [Route("/metrics", self._endpoint, methods=["GET"], name="metrics")]

    def render(self) -> bytes:
        """The exposition, as ``GET /metrics`` serves it."""
        return generate_latest(self.registry)

    async def _endpoint(self, request: Request) -> Response:
        # the classic text format: what every Prometheus (2.x and 3.x) and agent scrapes
        return Response(self.render(), media_type=CONTENT_TYPE_PLAIN_0_0_4)

    # -- notifications ---------------------------------------------------------------------
    def note(self, n: bus.Notification) -> None:
        """Count one change notification (call it for every one, any table)."""
        self.notifications.labels(n.table).inc()
        written = 1
        if n.table in ID_TABLES and n.id is not None:
            before = self._newest.get(n.table)
            if before is not None and n.id <= before:
                return  # a late hint of rows already counted
            written = 1 if before is None else n.id - before
            self._newest[n.table] = n.id
        self.rows.labels(n.table).inc(written)
        self._recent.setdefault(n.table, deque()).append((time.monotonic(), written))

    def rows_per_second(self) -> dict[str, float]:
        """Rows written per table over the last ``rate_window_s`` (or since the start)."""
        now = time.monotonic()
        window = self.config.rate_window_s
        span = max(1e-3, min(window, now - self._started))
        out = {}
        for table, recent in self._recent.items():
            while recent and recent[0][0] < now - window:
                recent.popleft()
            out[table] = sum(count for _, count in recent) / span
        return out

    def _on_supervisor(self, key: str, payload: bytes) -> None:
        try:
            body = bus.unpack(payload)
            processes = body["processes"]
            report = {
                str(name): (int(p["restarts"]), bool(p["running"])) for name, p in processes.items()
            }
        except (ValueError, KeyError, TypeError, AttributeError):
            log.warning("ignored a malformed supervisor report on %s", key)
            return
        self.snapshot.supervisors[key] = report

    # -- reads -----------------------------------------------------------------------------
    async def _loop(self) -> None:
        while True:
            await asyncio.sleep(self.config.refresh_s)
            await self.refresh()

    async def refresh(self) -> None:
        """One read of the tables: engine stats, leases, robots, new decisions."""
        source = self.source
        if source is None:
            return
        try:
            engine, leases, robots = (
                await source.engine_stats(),
                await source.leases(),
                await source.robot_count(),
            )
            await self._sample_decisions(source)
        except (OSError, asyncpg.PostgresError, asyncpg.InterfaceError) as exc:
            self.refresh_errors.inc()
            if not self._failing:
                log.warning("metrics: cannot read the tables (%s); retrying", exc)
            self._failing = True
            return
        if self._failing:
            log.info("metrics: reading the tables again")
        self._failing = False
        self.snapshot.engine, self.snapshot.leases, self.snapshot.robots = engine, leases, robots

    async def _sample_decisions(self, source: MetricsSource) -> None:
        decided = await source.decided_since(self._last_command)
        wanted: dict[str, list[tuple[int, Any]]] = {}
        for d in decided:
            self._last_command = max(self._last_command, d.command_id)
            fresh = d.recommendation_id > self._first_recommendation
            if not fresh or d.recommendation_id in self._seen:
                continue  # a re-issue of a decision already sampled, or made before start
            self._seen[d.recommendation_id] = None
            if len(self._seen) > _SEEN_CAP:
                self._seen.popitem(last=False)
            origin = origin_of(d.inputs)
            if origin is not None:
                wanted.setdefault(origin[0], []).append((origin[1], d))
        for table, pairs in wanted.items():
            sensed = await source.sensed_at(table, [row_id for row_id, _ in pairs])
            for row_id, d in pairs:
                at = sensed.get(row_id)
                if at is None:
                    continue  # pruned already: too old to say anything about now
                self.sense_to_act.labels(d.robot, table).observe(max(0.0, d.decided - at))
                self.stages.labels("row_to_recommendation").observe(max(0.0, d.recommended - at))
                self.stages.labels("recommendation_to_decision").observe(
                    max(0.0, d.decided - d.recommended)
                )


class _StackCollector(Collector):
    """The metrics whose values live in the tables or the supervisor reports: built from the
    last snapshot on every scrape."""

    def __init__(self, metrics: Metrics) -> None:
        self.metrics = metrics

    def describe(self) -> list[Metric]:
        return []  # built at scrape time; nothing to check at registration

    def collect(self) -> Iterator[Metric]:
        snap = self.metrics.snapshot
        yield from _engine_families(snap.engine)
        rate = GaugeMetricFamily(
            "pnav_table_rows_per_second",
            f"Rows written per second over the last {self.metrics.config.rate_window_s:g} s",
            labels=["table"],
        )
        for table, value in sorted(self.metrics.rows_per_second().items()):
            rate.add_metric([table], value)
        yield rate
        owner = GaugeMetricFamily(
            "pnav_lease_owner",
            "1 for the replica that owns the robot for the service now",
            labels=["service", "robot", "instance"],
        )
        for lease in snap.leases:
            owner.add_metric([lease.service, lease.robot, lease.instance], 1)
        yield owner
        yield GaugeMetricFamily("pnav_robots", "Robots in the robot table", value=snap.robots)
        yield from _supervisor_families(snap.supervisors)


def _engine_families(rows: list[EngineRow]) -> Iterator[Metric]:
    labels = ["service", "instance", "scenario", "rule"]
    counters = {
        "executed": CounterMetricFamily("pnav_engine_rules_executed", "Rules run", labels=labels),
        "activated": CounterMetricFamily(
            "pnav_engine_rules_activated", "Rules whose guards held", labels=labels
        ),
        "acted": CounterMetricFamily(
            "pnav_engine_rules_acted", "Rules whose actions completed", labels=labels
        ),
        "errors": CounterMetricFamily(
            "pnav_engine_rule_errors", "Errors in any step of a rule", labels=labels
        ),
        "total_time_s": CounterMetricFamily(
            "pnav_engine_rule_seconds", "Wall time spent in rules", labels=labels
        ),
    }
    longest = GaugeMetricFamily(
        "pnav_engine_rule_max_seconds", "Longest single run of a rule", labels=labels
    )
    age = GaugeMetricFamily(
        "pnav_engine_stats_age_seconds",
        "Seconds since the instance last wrote its engine_stats",
        labels=["service", "instance"],
    )
    ages: dict[tuple[str, str], float] = {}
    for row in rows:
        values = [row.service, row.instance, row.scenario, row.rule_type]
        for column, family in counters.items():
            family.add_metric(values, float(getattr(row, column)))
        longest.add_metric(values, row.max_time_s)
        key = (row.service, row.instance)
        ages[key] = min(ages.get(key, row.age_s), row.age_s)
    for (service, instance), seconds in sorted(ages.items()):
        age.add_metric([service, instance], max(0.0, seconds))
    yield from counters.values()
    yield longest
    yield age


def _supervisor_families(reports: dict[str, dict[str, tuple[int, bool]]]) -> Iterator[Metric]:
    restarts = CounterMetricFamily(
        "pnav_supervisor_restarts",
        "Restarts of a process by the pnav up/demo supervisor",
        labels=["process"],
    )
    up = GaugeMetricFamily(
        "pnav_supervisor_process_up", "1 while the supervised process runs", labels=["process"]
    )
    for report in reports.values():
        for name, (count, running) in sorted(report.items()):
            restarts.add_metric([name], count)
            up.add_metric([name], 1 if running else 0)
    yield restarts
    yield up
