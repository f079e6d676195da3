"""The live recommendations the decision keeps in memory, from row images and table reads.

The decision arbitrates every robot's live (unexpired) command_recommendation rows. Reading
them all at every activation was one LIVE query per notification; with row images
(CONTRACT.md "Row images") each new row comes with its notification, so
:class:`LiveRecommendations` keeps them per robot:

- :meth:`add` a row from a usable image (the robot is then *changed*: decide for it);
- :meth:`expire` drops the rows whose ``expires_stamp`` passed (sim time), and marks their
  robots changed (the winner may be another now, or a stop is due);
- :meth:`treated` sets ``treated_by`` as the decision's own write just set it in the table;
- :meth:`replace` takes a whole read of the table (start, a gap, a missing image, the
  period), keeping the rows whose images came while that read was under way.

It holds no clock and no I/O: :class:`~services.decision.store.DecisionStore` says when to
read the table.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import replace

from common.contract.recommendations import Recommendation

KINDS = frozenset(("robot", "system"))


class LiveRecommendations:
    """Per robot, its live recommendations by id; which robots changed since the last look."""

    def __init__(self) -> None:
        self.robots: dict[str, dict[int, Recommendation]] = {}
        self.changed: set[str] = set()
        self._reading = False
        self._arrived: list[Recommendation] = []  # images heard while a read was under way

    def add(self, rec: Recommendation) -> None:
        """A row from its image. Robots not in the table (as last read) are added: the
        next read of the table says whether they exist."""
        if rec.kind not in KINDS:
            return
        self.robots.setdefault(rec.robot_id, {})[rec.id] = rec
        self.changed.add(rec.robot_id)
        if self._reading:
            self._arrived.append(rec)

    def expire(self, now: float) -> None:
        """Drop the rows no longer live at ``now``; their robots changed."""
        for robot_id, recs in self.robots.items():
            gone = [rec_id for rec_id, rec in recs.items() if rec.expires_stamp <= now]
            if gone:
                for rec_id in gone:
                    del recs[rec_id]
                self.changed.add(robot_id)

    def treated(self, robot_id: str, rec_ids: Iterable[int], decision_id: int) -> None:
        """``treated_by = decision_id`` for the rows the decision considered, as its write
        set it in the table."""
        recs = self.robots.get(robot_id)
        if recs is None:
            return
        for rec_id in rec_ids:
            rec = recs.get(rec_id)
            if rec is not None:
                recs[rec_id] = replace(rec, treated_by=decision_id)

    def reading(self) -> None:
        """A read of the table starts: images from now on are kept to merge into it."""
        self._reading = True
        self._arrived = []

    def replace(self, read: Mapping[str, list[Recommendation]]) -> None:
        """The table as just read (every robot, maybe with none); every robot changed."""
        robots = {robot_id: {r.id: r for r in recs} for robot_id, recs in read.items()}
        for rec in self._arrived:  # committed after the read looked: not in it
            robots.setdefault(rec.robot_id, {}).setdefault(rec.id, rec)
        self.robots = robots
        self.changed = set(robots)
        self._reading = False
        self._arrived = []

    def read_failed(self) -> None:
        self._reading = False
        self._arrived = []

    def forget(self, robot_ids: Iterable[str]) -> None:
        for robot_id in robot_ids:
            self.robots.pop(robot_id, None)
            self.changed.discard(robot_id)
