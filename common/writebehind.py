"""Writes a service's rules ask for during an activation, sent at its end in one call.

An engine runs its rules one after another, so a store that wrote each rule's row when the
rule asked paid a round trip (and a commit) per row, and every robot later in the activation
waited for the ones before. A :class:`WriteBehind` holds the rows instead and
:meth:`WriteBehind.flush` writes them with one call of ``write_many`` (one multi-row INSERT
in Postgres, docs/ARCHITECTURE.md: batching across robots). The service awaits ``flush`` at
the end of every activation (``Engine.at_activation_end``), so every row is committed and
notified before the activation counts as ended: whoever waits for the activation under way
(robot leases, a lockstep quiet report) still sees the rows written.

What changes for a rule: its ``actions`` step returns before its row exists (its statistics
time the rule, not the write), and a write that fails is the store's to report (``on_written``
is told None), not an error of the rule's.
"""

from __future__ import annotations

import logging
from collections.abc import Awaitable, Callable, Hashable, Sequence
from typing import Generic, TypeVar

from common import log

logger = logging.getLogger("pnav.writebehind")

T = TypeVar("T")
Written = Callable[[T, "int | None"], None]


class WriteBehind(Generic[T]):
    """Rows of type ``T`` held until :meth:`flush`.

    ``write_many(rows)`` writes rows whose ``key(row)`` are distinct and returns their ids
    in order (None: refused). A flush holding two rows with one key (a rule that asked twice
    for one robot and source) writes them in successive calls, in the order asked, so ids
    keep that order too.
    """

    def __init__(
        self,
        write_many: Callable[[Sequence[T]], Awaitable[Sequence[int | None]]],
        key: Callable[[T], Hashable],
        name: str,
    ) -> None:
        self._write_many = write_many
        self._key = key
        self.name = name
        self._pending: list[tuple[T, Written[T] | None]] = []
        # statements sent and rows written (tests, benchmarks)
        self.calls = 0
        self.written = 0
        self.failed = 0

    def __len__(self) -> int:
        return len(self._pending)

    def add(self, row: T, on_written: Written[T] | None = None) -> None:
        """Hold ``row`` until the next flush; then ``on_written(row, id)`` (id None: not
        written)."""
        self._pending.append((row, on_written))

    async def flush(self) -> None:
        """Write every row held, in as few calls as their keys allow. A failed call's rows
        are reported not written (``on_written(row, None)``, logged) and the rest still go."""
        pending, self._pending = self._pending, []
        while pending:
            batch, pending = _distinct(pending, self._key)
            rows = [row for row, _ in batch]
            self.calls += 1
            try:
                ids: Sequence[int | None] = await self._write_many(rows)
            except Exception as exc:
                ids = [None] * len(rows)
                log.event(
                    logger, logging.WARNING, "deferred writes failed", what=self.name,
                    rows=len(rows), error=repr(exc),
                )  # fmt: skip
            for (row, on_written), row_id in zip(batch, ids, strict=True):
                if row_id is None:
                    self.failed += 1
                else:
                    self.written += 1
                if on_written is not None:
                    on_written(row, row_id)


def _distinct(
    pending: list[tuple[T, Written[T] | None]], key: Callable[[T], Hashable]
) -> tuple[list[tuple[T, Written[T] | None]], list[tuple[T, Written[T] | None]]]:
    """The longest run from the head with distinct keys, and the rest."""
    seen: set[Hashable] = set()
    for i, (row, _) in enumerate(pending):
        k = key(row)
        if k in seen:
            return pending[:i], pending[i:]
        seen.add(k)
    return pending, []
