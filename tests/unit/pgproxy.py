"""A Postgres wire proxy for tests that need the network to misbehave in one precise way.

:class:`PgProxy` listens on loopback TCP and relays every byte to the server of a DSN (a
unix socket, as the embedded Postgres uses, or TCP). It reads the server's messages as they
pass, and when one is an ErrorResponse of severity ``FATAL`` (the server ending the session,
e.g. after ``pg_terminate_backend``), it forwards it but keeps the client's socket open for
``hold_after_fatal_s`` before closing it. That is what a client sees when the FATAL reaches
it while it is idle and the end of the stream comes late (a loaded machine, a slow network):
asyncpg then stays "connected", its termination listeners do not run, and only its next
query fails (MagicStack/asyncpg#1069, #784).
"""

from __future__ import annotations

import asyncio
import contextlib
import struct
from urllib.parse import parse_qs, urlencode, urlsplit, urlunsplit

_SSL_REQUEST = 80877103
_GSSENC_REQUEST = 80877104


def _upstream(dsn: str) -> tuple[str | None, str, int]:
    """``(unix socket path or None, host, port)`` of the server a DSN names."""
    parts = urlsplit(dsn)
    query = parse_qs(parts.query)
    host = query.get("host", [parts.hostname or "localhost"])[0]
    port = int(query.get("port", [parts.port or 5432])[0])
    if host.startswith("/"):
        return f"{host}/.s.PGSQL.{port}", host, port
    return None, host, port


def fatal_message(message: bytes) -> bool:
    """Whether one backend message (type byte, length, body) is an ErrorResponse whose
    severity is FATAL (or PANIC: the session ends either way)."""
    if message[:1] != b"E":
        return False
    for field in message[5:].split(b"\0"):
        if field[:1] in (b"S", b"V") and field[1:] in (b"FATAL", b"PANIC"):
            return True
    return False


class PgProxy:
    """Relays connections to one Postgres server; see the module docstring.

    ``fatals`` counts the FATAL messages forwarded; ``holding`` is how many client sockets
    are being kept open after one.
    """

    def __init__(self, dsn: str, hold_after_fatal_s: float = 5.0) -> None:
        self.dsn = dsn
        self.hold_after_fatal_s = hold_after_fatal_s
        self.fatals = 0
        self.holding = 0
        self._server: asyncio.Server | None = None
        self._tasks: set[asyncio.Task[None]] = set()
        self._writers: set[asyncio.StreamWriter] = set()
        self._closed = asyncio.Event()
        self.port = 0

    def url(self, dsn: str | None = None) -> str:
        """``dsn`` (the proxied server's, another database allowed) pointed at the proxy."""
        parts = urlsplit(dsn or self.dsn)
        query = {k: v[0] for k, v in parse_qs(parts.query).items() if k not in ("host", "port")}
        query["sslmode"] = "disable"  # the proxy reads the stream: it must stay plain
        user = parts.username or "postgres"
        auth = f"{user}:{parts.password or ''}@"
        netloc = f"{auth}127.0.0.1:{self.port}"
        return urlunsplit((parts.scheme, netloc, parts.path, urlencode(query), ""))

    async def __aenter__(self) -> PgProxy:
        self._server = await asyncio.start_server(self._serve, "127.0.0.1", 0)
        self.port = self._server.sockets[0].getsockname()[1]
        return self

    async def __aexit__(self, *exc: object) -> None:
        # End every relay by closing its sockets (a cancelled connection handler is logged
        # as an error by asyncio's stream server)
        self._closed.set()
        if self._server is not None:
            self._server.close()
        for writer in list(self._writers):
            writer.close()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        if self._server is not None:
            await self._server.wait_closed()

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        assert task is not None
        self._tasks.add(task)
        self._writers.add(writer)
        try:
            await self._relay(reader, writer)
        except (OSError, asyncio.IncompleteReadError):
            pass
        finally:
            self._tasks.discard(task)
            self._writers.discard(writer)
            writer.close()

    async def _relay(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        path, host, port = _upstream(self.dsn)
        if path is not None:
            up_reader, up_writer = await asyncio.open_unix_connection(path)
        else:
            up_reader, up_writer = await asyncio.open_connection(host, port)
        self._writers.add(up_writer)
        try:
            # The first client packet has no type byte; an SSL or GSSAPI request gets a
            # one-byte answer before the server's messages begin.
            head = await reader.readexactly(8)
            length, code = struct.unpack("!ii", head)
            up_writer.write(head + await reader.readexactly(length - 8))
            if code in (_SSL_REQUEST, _GSSENC_REQUEST):
                answer = await up_reader.readexactly(1)
                writer.write(answer)
                if answer != b"N":
                    raise AssertionError("the proxy cannot read an encrypted stream")
            to_server = asyncio.create_task(self._pipe(reader, up_writer))
            try:
                fatal = await self._messages(up_reader, writer)
            finally:
                to_server.cancel()
                with contextlib.suppress(asyncio.CancelledError, OSError):
                    await to_server
            if fatal:
                # The server has ended the session; the client learns of it only from the
                # FATAL it already has, not from the stream's end, until the hold is over.
                self.holding += 1
                try:
                    with contextlib.suppress(TimeoutError):
                        await asyncio.wait_for(self._closed.wait(), self.hold_after_fatal_s)
                finally:
                    self.holding -= 1
        finally:
            self._writers.discard(up_writer)
            up_writer.close()

    async def _messages(self, up: asyncio.StreamReader, client: asyncio.StreamWriter) -> bool:
        """Forward the server's messages until its stream ends; whether a FATAL came."""
        while True:
            try:
                head = await up.readexactly(5)
            except asyncio.IncompleteReadError:
                return False
            body = await up.readexactly(struct.unpack("!i", head[1:])[0] - 4)
            client.write(head + body)
            await client.drain()
            if fatal_message(head + body):
                self.fatals += 1
                return True

    @staticmethod
    async def _pipe(source: asyncio.StreamReader, sink: asyncio.StreamWriter) -> None:
        while data := await source.read(65536):
            sink.write(data)
            await sink.drain()
