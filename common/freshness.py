"""What a store learned from notifications, against what it last read: when to read again.

A change notification is a hint ("table T changed for robot R, newest id K"). A service's
store keeps the rows it read and must read again only when a hint says something newer
exists, or when a hint could not say which row (no id), or after ``recheck_s`` in case a
hint was lost. :class:`FreshCache` is that bookkeeping, one entry per key (a robot id, a
table, whatever the store reads as one unit), in one place for every service:

- :meth:`FreshCache.announce` records a hint (call it on the event loop, where the store
  lives: no locks);
- :meth:`FreshCache.get` returns the cached value while it is fresh, and otherwise reads it
  through the coroutine it is given.

A hint that arrives while a read is under way is never lost: an id-less hint marks the
entry stale *before* the read starts, so one that comes during it marks it again, and an
announced id is compared with the id the read returned (a read that returned an older row
than announced is stale at once).
"""

from __future__ import annotations

import math
from collections.abc import Awaitable, Callable, Hashable
from dataclasses import dataclass
from typing import Generic, TypeVar

K = TypeVar("K", bound=Hashable)
T = TypeVar("T")


@dataclass
class _Entry(Generic[T]):
    value: T | None = None
    has_value: bool = False
    read_id: int | None = None  # the id of the row the last read returned
    read_at: float = -math.inf  # the clock when the last read started
    announced: int | None = None  # the newest id a hint named
    dirty: bool = True  # a hint without an id came (or nothing was read yet)


class FreshCache(Generic[K, T]):
    """Cached reads per key, read again when a hint names something newer.

    ``clock`` is the store's clock (wall time in a service, sim time in a lockstep or
    in-process run, so the result does not depend on the machine's speed); ``id_of`` gives
    the row id a read value stands for (None: the value has no id, e.g. a whole table), so
    hints naming ids up to it are known to be answered.
    """

    def __init__(
        self,
        clock: Callable[[], float],
        recheck_s: float,
        id_of: Callable[[T], int | None] | None = None,
    ) -> None:
        self.clock = clock
        self.recheck_s = recheck_s
        self.id_of = id_of
        self._entries: dict[K, _Entry[T]] = {}
        self.reads = 0  # how many reads went to the source (for tests and benchmarks)

    def announce(self, key: K, row_id: int | None = None) -> None:
        """A hint about ``key``: ``row_id`` is the newest id it names, None if it named none."""
        entry = self._entries.get(key)
        if entry is None:
            entry = self._entries[key] = _Entry()
        if row_id is None:
            entry.dirty = True
        elif entry.announced is None or row_id > entry.announced:
            entry.announced = row_id

    def announce_all(self) -> None:
        """A hint that could not be read: every key may have changed."""
        for entry in self._entries.values():
            entry.dirty = True

    def stale(self, key: K) -> bool:
        """Whether :meth:`get` would read ``key`` again now."""
        entry = self._entries.get(key)
        if entry is None or entry.dirty or not entry.has_value:
            return True
        if self.clock() - entry.read_at >= self.recheck_s:
            return True
        announced = entry.announced
        if announced is None:
            return False
        return entry.read_id is None or announced > entry.read_id

    def hinted(self, key: K) -> bool:
        """Whether a hint came for ``key`` since it was last read (``recheck_s`` aside);
        False if it was never read."""
        entry = self._entries.get(key)
        if entry is None or not entry.has_value:
            return False
        if entry.dirty:
            return True
        announced = entry.announced
        return announced is not None and (entry.read_id is None or announced > entry.read_id)

    def peek(self, key: K) -> T | None:
        """The value last read for ``key`` (None if never read), fresh or not."""
        entry = self._entries.get(key)
        return entry.value if entry is not None else None

    async def get(self, key: K, read: Callable[[], Awaitable[T]]) -> T:
        """The cached value of ``key`` if fresh, else ``await read()`` (and keep it)."""
        entry = self._entries.get(key)
        if entry is None:
            entry = self._entries[key] = _Entry()
        elif not self.stale(key):
            return entry.value  # type: ignore[return-value]  # has_value holds
        entry.dirty = False  # before the read: a hint that comes during it marks it again
        entry.read_at = self.clock()
        value = await read()
        self.reads += 1
        entry.value, entry.has_value = value, True
        entry.read_id = self.id_of(value) if self.id_of is not None else None
        return value

    def put(self, key: K, value: T) -> None:
        """Keep ``value`` as read now (e.g. a row the store wrote itself, or read with another)."""
        entry = self._entries.get(key)
        if entry is None:
            entry = self._entries[key] = _Entry()
        entry.dirty = False
        entry.read_at = self.clock()
        entry.value, entry.has_value = value, True
        entry.read_id = self.id_of(value) if self.id_of is not None else None

    def forget(self, key: K) -> None:
        """Drop ``key`` (its robot left this replica, say): the next get reads it."""
        self._entries.pop(key, None)

    def clear(self) -> None:
        self._entries.clear()


class Sequences:
    """Which notifications were lost: per (key, publisher), the ``seq`` seen last.

    A publisher numbers its notifications per key (``common.bus.Notifier``); a skip in that
    numbering means one never arrived, and whatever a reader holds from images may be missing
    a row: read the table. The first notification from a publisher is no gap (the reader
    read the table when it started, or reads it at its period F anyway).
    """

    def __init__(self) -> None:
        self._last: dict[tuple[str, str], int] = {}
        # notifications known lost: the numbers skipped (one arriving late after its
        # successor is counted lost too, as its reader has read the table meanwhile)
        self.lost = 0

    def newest(self, key: str, src: str) -> int | None:
        """The highest ``seq`` seen from ``src`` on ``key`` (None: nothing yet)."""
        return self._last.get((key, src))

    def gap(self, key: str, src: str | None, seq: int | None) -> bool:
        """Record this notification; whether one from the same publisher was skipped (a
        notification without numbering counts as a gap: nothing can be known)."""
        if src is None or seq is None:
            return True
        last = self._last.get((key, src))
        self._last[(key, src)] = seq if last is None else max(last, seq)
        if last is not None and seq > last + 1:
            self.lost += seq - last - 1
        return last is not None and seq != last + 1
