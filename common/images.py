"""Row images judged before a reader acts on them: the table's rules, or the table itself.

A change notification may carry the committed row's image (CONTRACT.md "Row images"), and a
reader may act on it instead of reading the table. But anyone allowed to put on the key can
publish any image, so an image is held to the rules the table holds its rows to
(common.contract.tables: the CHECK bounds, declared once; the robot of the key) before it
stands in for a read. :class:`ImageGuard` is that judgement, for every reader:

- :meth:`ImageGuard.fresh` is "use the row image or read the table", for every store: the
  reader's record of a note's image, or None when a notification was lost before it on its
  stream (a ``seq`` gap, common.freshness.Sequences, counted in :attr:`ImageGuard.lost`),
  when the note has no image, or when its image breaks the table's rules or does not parse:
  the reader then reads the table. :meth:`ImageGuard.gap` and :meth:`ImageGuard.record` are
  its two halves, for a reader with something to decide between them;
- a refused image is counted per table (:attr:`ImageGuard.refused`, which each service
  reports with its other counters) and logged at most once per table per ``period_s``,
  with how many were refused since the last line and why the last one was.
"""

from __future__ import annotations

import logging
import time
from collections import Counter
from collections.abc import Callable, Mapping
from typing import Any, TypeVar

from common import log
from common.bus import Notification
from common.contract.tables import IMAGED
from common.freshness import Sequences

T = TypeVar("T")

LOG_PERIOD_S = 10.0


class ImageGuard:
    """Judges the images one reader acts on; counts and logs the refused ones."""

    def __init__(
        self,
        logger: logging.Logger,
        *,
        refused: Counter[str] | None = None,
        period_s: float = LOG_PERIOD_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        """``refused``: the counter to count into (a service's own, reported with its other
        counters); a new one if None."""
        self.logger = logger
        self.refused: Counter[str] = refused if refused is not None else Counter()
        self.period_s = period_s
        self._clock = clock
        self._logged: dict[str, tuple[float, int]] = {}  # table -> (when, refused then)
        self._sequences = Sequences()

    @property
    def sequences(self) -> Sequences:
        """The numbering seen per publisher and stream (tests)."""
        return self._sequences

    @property
    def lost(self) -> int:
        """Notifications known lost on the way here (seq gaps, common.freshness.Sequences)."""
        return self._sequences.lost

    def gap(self, note: Notification, stream: str | None = None) -> bool:
        """Whether a notification was lost before ``note`` on its stream (``stream``: its
        key; by default its table and robot). Every notification counts toward the
        numbering, so call it for each, even one the reader will not act on."""
        return self._sequences.gap(stream or f"{note.table}/{note.robot}", note.src, note.seq)

    def fresh(
        self,
        note: Notification,
        parse: Callable[[Mapping[str, Any]], T],
        stream: str | None = None,
    ) -> T | None:
        """The record ``parse`` makes of ``note``'s image when it may stand in for reading
        the table; None: read the table (a notification lost before it, no image, or one
        refused)."""
        if self.gap(note, stream):
            return None
        return self.record(note, parse)

    def image(self, note: Notification) -> Mapping[str, Any] | None:
        """``note``'s image if it keeps its table's rules; None if it has none, or breaks
        them (then counted and logged)."""
        row = note.row
        if row is None:
            return None
        table = IMAGED.get(note.table)
        if table is not None:
            why = table.refusal(row, note.robot)
            if why is not None:
                self.refuse(note.table, why)
                return None
        return row

    def record(self, note: Notification, parse: Callable[[Mapping[str, Any]], T]) -> T | None:
        """The record ``parse`` makes of ``note``'s image, or None: read the table instead
        (no image, or one refused: broke the table's rules, or did not parse)."""
        row = self.image(note)
        if row is None:
            return None
        try:
            return parse(row)
        except (KeyError, TypeError, ValueError) as exc:
            self.refuse(note.table, f"unreadable: {exc!r}")
            return None

    def refuse(self, table: str, why: str) -> None:
        """Count an image of ``table`` refused for ``why``; one log line per period."""
        self.refused[table] += 1
        now = self._clock()
        last = self._logged.get(table)
        if last is not None and now - last[0] < self.period_s:
            return
        since = self.refused[table] - (last[1] if last is not None else 0)
        self._logged[table] = (now, self.refused[table])
        log.event(
            self.logger,
            logging.WARNING,
            "row images refused: the table is read instead",
            table=table,
            refused=since,
            total=self.refused[table],
            last_why=why[:200],
        )


class GuardedStore:
    """What a store that reads images through an :class:`ImageGuard` says of them (tests,
    logs, the service's health): the notifications known lost, the images refused."""

    images: ImageGuard

    @property
    def notifications_lost(self) -> int:
        """Notifications known lost on the way here (seq gaps: common.images.ImageGuard.gap)."""
        return self.images.lost

    @property
    def images_refused(self) -> dict[str, int]:
        """Row images refused per table (broke the table's rules): the table was read."""
        return dict(self.images.refused)
