"""The scenario_offer table (migration 12): the scenarios each live planner and controller
instance can run, published by them, read by the strategy service and the planner.

A strategy names scenarios by name; only the process that runs them knows which it has (the
entry points installed where it runs, common.plugins). Each planner and controller instance
publishes its names at its start (:func:`publish`), refreshes them every
:data:`OFFER_REFRESH_S` (:func:`publish` again, unannounced) and deletes them at a clean stop
(:func:`withdraw`). An offer counts while it is fresher than :data:`OFFER_TTL_S`: a dead
instance's rows stop counting by themselves, whatever killed it, and the next instance of its
family to publish deletes them. CONTRACT.md, *scenario_offer*, is the protocol.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Collection, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Final

from common.contract import keys
from common.contract.records import Executor
from common.db import Database

logger = logging.getLogger("pnav.offers")

PLANNER: Final = "planner"
CONTROLLER: Final = "controller"
FAMILIES: Final = (PLANNER, CONTROLLER)

OFFER_REFRESH_S: Final = 3.0
# An offer older than this is an instance's that stopped refreshing (dead, or stalled for
# five refreshes): not counted.
OFFER_TTL_S: Final = 15.0

# The live offers, as (service, scenario) rows: the strategy service's snapshot embeds it.
LIVE_OFFERS_SQL: Final = f"""
SELECT DISTINCT service, scenario FROM scenario_offer
WHERE updated_at > now() - make_interval(secs => {OFFER_TTL_S})
"""

# Stale rows of the family (dead instances: RLS lets a family delete only its own), then this
# instance's rows it no longer offers, then its offers, fresh.
_DELETE_STALE = f"""
DELETE FROM scenario_offer
WHERE service = $1 AND updated_at <= now() - make_interval(secs => {OFFER_TTL_S})
"""
_DELETE_DROPPED = """
DELETE FROM scenario_offer
WHERE service = $1 AND instance = $2 AND NOT (scenario = ANY($3::text[]))
"""
_UPSERT = """
INSERT INTO scenario_offer (service, instance, scenario, updated_at)
SELECT $1, $2, name, now() FROM unnest($3::text[]) AS name
ON CONFLICT (service, instance, scenario) DO UPDATE SET updated_at = now()
"""
_WITHDRAW = "DELETE FROM scenario_offer WHERE service = $1 AND instance = $2"


@dataclass(frozen=True)
class Offers:
    """What the live planner and controller instances offer, per family. A family with no
    live offer is absent: none of its instances is known to run (starting, stopped, or one
    that publishes no offers), so nothing is judged against it."""

    by_family: Mapping[str, frozenset[str]] = field(default_factory=dict)

    @classmethod
    def of(cls, rows: Iterable[tuple[str, str]]) -> Offers:
        """From (service, scenario) pairs, as :data:`LIVE_OFFERS_SQL` returns them."""
        found: dict[str, set[str]] = {}
        for service, scenario in rows:
            found.setdefault(service, set()).add(scenario)
        return cls({family: frozenset(names) for family, names in found.items()})

    def offered(self, family: str) -> frozenset[str] | None:
        """The names the family's live instances offer; None when none is live."""
        return self.by_family.get(family)

    def missing(self, family: str, names: Iterable[str]) -> list[str]:
        """Those of ``names`` no live instance of ``family`` offers, in order (none when no
        instance of the family is live: it cannot be judged)."""
        offered = self.offered(family)
        if offered is None:
            return []
        return [name for name in dict.fromkeys(names) if name not in offered]


def unoffered(code: str, family: str, names: Iterable[str], offers: Offers) -> str | None:
    """Why strategy ``code``, naming ``names`` of ``family``, cannot run now, or None (every
    one is offered, or the family cannot be judged): ``strategy X names controller scenario
    'foo' that no running controller offers; offered: a, b, c``."""
    missing = offers.missing(family, names)
    if not missing:
        return None
    offered = ", ".join(sorted(offers.offered(family) or ())) or "none"
    plural = "s" if len(missing) > 1 else ""
    quoted = ", ".join(repr(name) for name in missing)
    return (
        f"strategy {code} names {family} scenario{plural} {quoted} that no running {family} "
        f"offers; offered: {offered}"
    )


async def live_offers(db: Executor) -> Offers:
    """The live offers, read with ``db`` (a Database, a pool or a connection)."""
    rows = await db.fetch(LIVE_OFFERS_SQL)
    return Offers.of((r["service"], r["scenario"]) for r in rows)


async def publish(
    db: Database, service: str, instance: str, scenarios: Collection[str], *, announce: bool
) -> None:
    """Offer ``scenarios`` as ``service``/``instance`` (only those: a name dropped since the
    last call is withdrawn), fresh as of now, in one transaction; notify if ``announce``."""
    names = sorted(scenarios)
    async with db.transaction() as tx:
        await tx.conn.execute(_DELETE_STALE, service)
        await tx.conn.execute(_DELETE_DROPPED, service, instance, names)
        if names:
            await tx.conn.execute(_UPSERT, service, instance, names)
        if announce:
            tx.changed(keys.SCENARIO_OFFER, None)


async def withdraw(db: Database, service: str, instance: str) -> None:
    """Delete this instance's offers (a clean stop) and notify."""
    await db.write(keys.SCENARIO_OFFER, None, _WITHDRAW, service, instance)


class Publisher:
    """One instance's offers while it runs: :meth:`publish` at its start, :meth:`refresh`
    (a task) while it runs, :meth:`withdraw` at its clean stop. A failed write is logged and
    the instance carries on (its engine does not need the offers); the next refresh writes
    them again, announced, since readers may have missed them."""

    def __init__(
        self, db: Database, service: str, instance: str, scenarios: Collection[str]
    ) -> None:
        self.db, self.service, self.instance = db, service, instance
        self.scenarios = tuple(scenarios)
        self.published = False

    async def publish(self, *, announce: bool = True) -> None:
        try:
            await publish(self.db, self.service, self.instance, self.scenarios, announce=announce)
        except Exception:
            logger.warning("could not write scenario_offer", exc_info=True)
            self.published = False
        else:
            self.published = True

    async def refresh(self) -> None:
        """Every OFFER_REFRESH_S until cancelled: a reader counts only fresh offers."""
        while True:
            await asyncio.sleep(OFFER_REFRESH_S)
            await self.publish(announce=not self.published)

    async def withdraw(self) -> None:
        try:
            await withdraw(self.db, self.service, self.instance)
        except Exception:
            logger.warning("could not withdraw the scenario offers", exc_info=True)
