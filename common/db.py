"""Postgres access for services: a pool, and writes that notify over Zenoh after commit.

The rule of the contract: a notification is published only after the write it announces has
committed, so a woken reader always finds the row. :meth:`Database.write` does that for one
statement; :meth:`Database.transaction` for several, publishing nothing if it rolls back.
"""

from __future__ import annotations

import asyncio
import functools
import json
import logging
import time
from collections.abc import AsyncIterator, Awaitable, Callable, Mapping, Sequence
from contextlib import asynccontextmanager
from typing import Any, Protocol, TypeVar

import asyncpg

from common.bus import Notifier
from common.errors import ConnectionFailure, InternalError, UsageError
from common.lane import Lane
from common.outage import DatabaseUnavailable, Outage, is_connection_error, outage_for

log = logging.getLogger(__name__)


async def _init_connection(conn: asyncpg.Connection) -> None:
    await conn.set_type_codec("jsonb", encoder=json.dumps, decoder=json.loads, schema="pg_catalog")
    await conn.set_type_codec("json", encoder=json.dumps, decoder=json.loads, schema="pg_catalog")


async def _init_then(
    on_connect: Callable[[asyncpg.Connection], Awaitable[None]], conn: asyncpg.Connection
) -> None:
    await _init_connection(conn)
    await on_connect(conn)


async def _keep_session(conn: asyncpg.Connection) -> None:
    """The pool's reset on release: nothing beyond asyncpg's own (which rolls back a
    transaction left open and drops listeners).

    asyncpg's default also sends ``SELECT pg_advisory_unlock_all(); CLOSE ALL; UNLISTEN *;
    RESET ALL`` on every release, before ``pool.fetch*`` returns: one more round trip per
    pooled query (a pooled ``SELECT`` took 0.12 ms p50 with it, 0.06 ms without, on the
    embedded Postgres; a scenario rule makes two to four of them per wake). Services keep
    no session state on pooled connections (leases use a dedicated connection, settings
    are fixed at connect), so there is nothing to reset.
    """


async def _connect(outage: Outage, *args: Any, **kwargs: Any) -> asyncpg.Connection:
    """Every pool's connect: through the process's outage state (common.outage), so that
    while Postgres is down the pools back off together and say so once."""
    if not outage.may_try():
        raise DatabaseUnavailable("the database is unreachable (backing off)")
    try:
        conn: asyncpg.Connection = await asyncpg.connect(*args, **kwargs)
    except Exception as exc:
        if is_connection_error(exc):
            outage.failed(exc)
        raise
    outage.recovered()
    return conn


async def create_pool(
    url: str,
    *,
    min_size: int = 1,
    max_size: int = 4,
    wait_s: float = 10.0,
    server_settings: dict[str, str] | None = None,
    max_inactive_connection_lifetime: float = 300.0,
    on_connect: Callable[[asyncpg.Connection], Awaitable[None]] | None = None,
) -> asyncpg.Pool:
    """Open a pool, retrying for ``wait_s`` while Postgres is still starting up.

    ``server_settings`` are session settings for every connection (e.g.
    ``{"synchronous_commit": "off"}`` for a writer of sensor rows that may lose the last
    few hundred milliseconds if Postgres itself crashes).

    The pool reconnects by itself when Postgres comes back (after a restart, say); while it
    is down, connecting backs off (common.outage). ``on_connect`` runs on every new
    connection, after the contract's codecs are set (the bridge's sensor writer learns from
    it that its connections were renewed).
    """
    init: Callable[[asyncpg.Connection], Awaitable[None]] = _init_connection
    if on_connect is not None:
        init = functools.partial(_init_then, on_connect)
    deadline = time.monotonic() + wait_s
    while True:
        try:
            pool: asyncpg.Pool = await asyncpg.create_pool(
                url,
                min_size=min_size,
                max_size=max_size,
                init=init,
                reset=_keep_session,
                server_settings=server_settings,
                max_inactive_connection_lifetime=max_inactive_connection_lifetime,
                connect=functools.partial(_connect, outage_for(url)),
            )
            return pool
        except (
            OSError,
            asyncpg.CannotConnectNowError,
            asyncpg.ConnectionDoesNotExistError,
            DatabaseUnavailable,
        ) as exc:
            if time.monotonic() >= deadline:
                raise ConnectionFailure(f"cannot reach Postgres at {_redact(url)}: {exc}") from exc
            await asyncio.sleep(0.2)
        except asyncpg.InvalidCatalogNameError as exc:
            raise ConnectionFailure(f"no such database at {_redact(url)}: {exc}") from exc


def lock_settings(lock_timeout_ms: int) -> dict[str, str]:
    """A service pool's ``server_settings`` for ``lock_timeout_ms`` (0: none, Postgres' own
    default: wait forever).

    Any role that may UPDATE a table may also LOCK it, or hold its rows with ``SELECT ... FOR
    UPDATE``, for as long as it likes; the people's role may UPDATE goal, strategy and
    retention_policy. With a lock timeout a service's statement blocked by such a lock fails
    with ``LockNotAvailableError`` (SQLSTATE 55P03) after that long instead of stalling the
    engine's activation; the rule's error is logged (common.engine.errorlog) and the rule
    runs again at the next activation (CONTRACT.md, *Roles*). Only the lock wait is bounded:
    a long query is not.
    """
    return {"lock_timeout": f"{lock_timeout_ms}ms"} if lock_timeout_ms > 0 else {}


async def connect(url: str) -> asyncpg.Connection:
    """One connection with the contract's codecs (for tools and tests)."""
    try:
        conn: asyncpg.Connection = await asyncpg.connect(url)
    except OSError as exc:
        raise ConnectionFailure(f"cannot reach Postgres at {_redact(url)}: {exc}") from exc
    await _init_connection(conn)
    return conn


def _redact(url: str) -> str:
    """Hide a password in a DSN before it goes into an error message."""
    if "@" not in url or "://" not in url:
        return url
    scheme, rest = url.split("://", 1)
    creds, host = rest.rsplit("@", 1)
    user = creds.split(":", 1)[0]
    return f"{scheme}://{user}:***@{host}" if ":" in creds else url


# What a batch refused as data (a robot deleted meanwhile, a value out of a column's
# range): its rows are written one by one instead, so one bad row costs only itself.
REFUSED_AS_DATA = (asyncpg.IntegrityConstraintViolationError, asyncpg.DataError)


class _OneRobots(Protocol):
    @property
    def robot_id(self) -> str: ...


R = TypeVar("R", bound=_OneRobots)


async def batch_or_each(
    rows: Sequence[R],
    batch: Callable[[], Awaitable[Sequence[int]]],
    each: Callable[[R], Awaitable[int]],
    what: str,
    logger: logging.Logger,
) -> list[int | None]:
    """``batch()`` (``rows`` in one statement: their ids in order), or, when the database
    refuses it as data (:data:`REFUSED_AS_DATA`), each row by ``each``: None for a row
    refused too. Every refusal is logged on ``logger``, naming ``what`` the rows are."""
    try:
        return list(await batch())
    except REFUSED_AS_DATA as exc:
        logger.warning("%s batch refused (%r): writing its rows one by one", what, exc)
    ids: list[int | None] = []
    for row in rows:
        try:
            ids.append(await each(row))
        except REFUSED_AS_DATA as exc:
            logger.warning("%s row refused for %s: %r", what, row.robot_id, exc)
            ids.append(None)
    return ids


class Changes:
    """The notifications a transaction will publish once it commits."""

    def __init__(self, conn: asyncpg.Connection) -> None:
        self.conn = conn
        self._pending: dict[tuple[str, str | None], tuple[int | None, Mapping[str, Any] | None]]
        self._pending = {}

    def changed(
        self,
        table: str,
        robot: str | None,
        row_id: int | None = None,
        row: Mapping[str, Any] | None = None,
    ) -> None:
        """Announce ``table`` changed for ``robot``; the newest id per (table, robot) wins,
        with its image ``row`` (if given)."""
        key = (table, robot)
        held = self._pending.get(key, (None, None))[0] if key in self._pending else -1
        # an id-less change keeps the newest id already announced (and its image)
        if held == -1 or (row_id is not None and (held is None or row_id > held)):
            self._pending[key] = (row_id, row)

    def items(self) -> list[tuple[str, str | None, int | None, Mapping[str, Any] | None]]:
        return [(t, robot, row_id, row) for (t, robot), (row_id, row) in self._pending.items()]


# A FROM item that makes the statement's own (implicit) transaction commit without waiting
# for its WAL to be flushed: ``set_config(..., true)`` lasts until that transaction ends,
# and Postgres reads ``synchronous_commit`` when it commits, before local settings are
# undone. One round trip, as the plain statement; the connection's other statements keep
# their synchronous commits. For rows nobody acts on until a synchronous commit cites them
# (recommendations, planned paths): WAL is written in order, so that later commit makes
# them durable first (CONTRACT.md, "Durability").
ASYNC_COMMIT = "(SELECT set_config('synchronous_commit', 'off', true)) AS async_commit"


class Database:
    """A service's pool plus its notifier.

    Its single statements (:meth:`fetch`, :meth:`fetchrow`, :meth:`fetchval`,
    :meth:`execute`, :meth:`write`, :meth:`write_rows`) run on a :class:`~common.lane.Lane`,
    one connection held between them, which saves the pool's checkout (about half the
    client's CPU of a statement); transactions and anything else needing a connection of its
    own go through ``pool.acquire()``. The store of a service passes the ``Database`` itself
    to ``common.contract.records`` as the executor. Close it with :meth:`close`, which
    gives the lane's connection back first: ``pool.close()`` alone would wait for it.
    """

    def __init__(self, pool: asyncpg.Pool, notifier: Notifier) -> None:
        self.pool = pool
        self.notifier = notifier
        self.lane = Lane(pool)

    async def fetch(self, sql: str, *args: Any) -> list[asyncpg.Record]:
        return await self.lane.fetch(sql, *args)

    async def fetchrow(self, sql: str, *args: Any) -> asyncpg.Record | None:
        return await self.lane.fetchrow(sql, *args)

    async def fetchval(self, sql: str, *args: Any) -> Any:
        return await self.lane.fetchval(sql, *args)

    async def execute(self, sql: str, *args: Any) -> str:
        return await self.lane.execute(sql, *args)

    async def write(
        self,
        table: str,
        robot: str | None,
        sql: str,
        *args: Any,
        image: Mapping[str, Any] | None = None,
    ) -> Any:
        """Run one statement (autocommit), then notify ``table``/``robot``.

        If the statement returns a value (``RETURNING id``) it is the notification's id and
        the return value; ``image``, the row's contract columns as written, then goes with
        the notification (with that ``id``), so readers may skip their query.
        """
        value = await self.lane.fetchval(sql, *args)
        row_id = value if isinstance(value, int) else None
        row = {**image, "id": row_id} if image is not None and row_id is not None else None
        self.notifier.notify(table, robot, row_id, row)
        return value

    async def write_rows(
        self,
        table: str,
        sql: str,
        *args: Any,
        images: Sequence[tuple[str, Mapping[str, Any]]],
        pair_on: tuple[str, ...] = ("robot_id",),
    ) -> list[int]:
        """Run one statement (autocommit) that inserts one row per ``(robot, image)`` of
        ``images`` and returns ``id`` and the ``pair_on`` columns per row; then notify
        ``table`` for each robot with its id and its image (the row's contract columns as
        written). One commit and one round trip for all the rows: batching across robots
        (docs/ARCHITECTURE.md, the data path).

        RETURNING's rows are paired with the images by their ``pair_on`` columns (the
        robot, by default), whatever order they come in, so those must be distinct across
        ``images``. The ids, in the order of ``images``.
        """
        wanted = [tuple(image[column] for column in pair_on) for _, image in images]
        if len(set(wanted)) != len(wanted):
            raise UsageError(f"write_rows on {table}: {pair_on} repeats in {wanted}")
        records = await self.lane.fetch(sql, *args)
        ids = {tuple(record[column] for column in pair_on): record["id"] for record in records}
        notify = self.notifier.notify
        for (robot, image), key in zip(images, wanted, strict=True):
            row_id = ids.get(key)
            if row_id is not None:
                notify(table, robot, row_id, {**image, "id": row_id})
        if len(records) != len(wanted) or any(key not in ids for key in wanted):
            raise InternalError(f"write_rows on {table}: {len(records)} rows returned for {wanted}")
        return [ids[key] for key in wanted]

    @asynccontextmanager
    async def transaction(self) -> AsyncIterator[Changes]:
        """``async with db.transaction() as tx: ... tx.changed(table, robot, id, row)``.

        Notifications go out after COMMIT, and not at all on rollback.
        """
        async with self.pool.acquire() as conn, conn.transaction():
            changes = Changes(conn)
            yield changes
        for table, robot, row_id, row in changes.items():
            self.notifier.notify(table, robot, row_id, row)

    async def close(self, timeout_s: float = 5.0) -> None:
        try:
            await asyncio.wait_for(self.lane.close(), timeout_s)  # the pool waits for it
            await asyncio.wait_for(self.pool.close(), timeout_s)
        except TimeoutError:
            log.warning("pool did not close in time; terminating connections")
            self.pool.terminate()
