"""FreshCache: a cached read is read again exactly when a hint says it may be stale."""

from __future__ import annotations

import asyncio

from common.freshness import FreshCache


class Source:
    """A table whose newest row id the test moves by hand; counts the reads."""

    def __init__(self) -> None:
        self.newest = 1
        self.reads = 0
        self.gate: asyncio.Event | None = None

    async def read(self) -> int:
        self.reads += 1
        value = self.newest  # what the query saw
        if self.gate is not None:
            await self.gate.wait()  # the query is in flight
        return value


def cache(now: list[float], recheck_s: float = 1.0) -> FreshCache[str, int]:
    return FreshCache(lambda: now[0], recheck_s, id_of=lambda row_id: row_id)


async def test_a_read_is_kept_until_a_hint_names_a_newer_id() -> None:
    now, src = [0.0], Source()
    c = cache(now)
    assert await c.get("r1", src.read) == 1  # never read: reads       reads=1
    assert await c.get("r1", src.read) == 1  # nothing announced: kept reads=1
    c.announce("r1", 1)
    assert await c.get("r1", src.read) == 1  # id 1 is what was read   reads=1
    src.newest = 2
    c.announce("r1", 2)
    assert c.stale("r1")
    assert await c.get("r1", src.read) == 2  # id 2 > 1: read again    reads=2
    assert src.reads == 2 and c.reads == 2


async def test_an_id_less_hint_or_the_recheck_period_reads_again() -> None:
    now, src = [0.0], Source()
    c = cache(now, recheck_s=0.5)
    await c.get("r1", src.read)  # reads=1
    c.announce("r1", None)
    await c.get("r1", src.read)  # "something changed": reads=2
    now[0] = 0.4
    await c.get("r1", src.read)  # within recheck: reads=2
    now[0] = 0.5
    await c.get("r1", src.read)  # recheck_s after the last read: reads=3
    c.announce("r2", None)  # another key's hint does not touch r1
    await c.get("r1", src.read)  # reads=3
    assert src.reads == 3


async def test_a_hint_during_a_read_is_not_lost() -> None:
    now, src = [0.0], Source()
    c = cache(now, recheck_s=60)
    src.gate = asyncio.Event()
    task = asyncio.create_task(c.get("r1", src.read))
    await asyncio.sleep(0)  # the read started and saw id 1
    src.newest = 2
    c.announce("r1", 2)  # row 2 committed while the read was in flight
    c.announce("r1", None)
    src.gate.set()
    assert await task == 1  # the in-flight read returns the older row...
    src.gate = None
    assert c.stale("r1")  # ...so the entry is stale at once
    assert await c.get("r1", src.read) == 2


async def test_unreadable_hints_forget_and_put() -> None:
    now, src = [0.0], Source()
    c = cache(now, recheck_s=60)
    await c.get("a", src.read)
    await c.get("b", src.read)
    c.announce_all()
    assert c.stale("a") and c.stale("b")
    c.put("a", 7)  # a row the store wrote itself: fresh, id 7
    assert not c.stale("a") and c.peek("a") == 7
    c.forget("a")
    assert c.stale("a") and c.peek("a") is None
