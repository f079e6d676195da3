"""The contract tables in memory: what Postgres is to the stack, for one process.

Each scenario service reaches the contract through its store (``services/<svc>/store.py``),
which reads and writes through a *source*: in the stack the SQL one, here the in-memory one of
``pnav/monolith/memory_<svc>.py``, over these tables. The store above the source (its caches, what
notifications told it) is the service's own and runs here unchanged.

Rows are dicts with the contract's column names. :meth:`MemoryContract.insert` gives a row
its id and then tells the listeners, as a commit followed by a Zenoh notification does in the
stack. Sensor tables keep as many rows per robot as the contract's retention policy
(schema.sql), so memory stays flat however long a run is.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Iterable, Iterator
from typing import Any

from common.contract import keys
from common.contract.offers import Offers
from common.contract.recommendations import Recommendation

Row = dict[str, Any]
# (table, robot, row id): what a write announces; the monolith's stand-in for Zenoh
Listener = Callable[[str, str | None, int | None], None]
# (table, robot, row id, the row's image or None): the same, with the committed row as a
# notification carries it (CONTRACT.md "Row images")
RowListener = Callable[[str, str | None, int | None, Row | None], None]

# schema.sql's retention_policy: rows kept per robot in the sensor tables
RETENTION = {
    keys.ODOMETRY: 900,
    keys.LASER_SCAN: 150,
    keys.BATTERY: 300,
    keys.COLLISION_EVENT: 1000,
    keys.PLANNED_PATH: 200,
}


class AdapterError(RuntimeError):
    """The monolith's own plumbing failed (not a scenario's logic): always fatal."""


def owns_every_robot(_robot_id: str) -> bool:
    """A store's ``owns`` in the monolith: its one process stands for every replica, so it
    holds every robot (the stack's leases split them)."""
    return True


class Table:
    """Rows of one contract table, in id order, indexed by robot (``None``: no robot_id)."""

    def __init__(self, name: str, keep: int | None = None) -> None:
        self.name = name
        self.keep = keep
        self._next_id = 1
        self._by_robot: dict[str | None, deque[Row]] = {}
        self.by_id: dict[int, Row] = {}  # only for tables that are not pruned

    def insert(self, row: Row) -> int:
        """Add ``row``, giving it the next id (bigserial) unless it has one; its id."""
        if "id" not in row:
            row["id"] = self._next_id
            self._next_id += 1
        rows = self._by_robot.get(row.get("robot_id"))
        if rows is None:
            rows = self._by_robot[row.get("robot_id")] = deque(maxlen=self.keep)
        rows.append(row)
        if self.keep is None:
            self.by_id[row["id"]] = row
        return int(row["id"])

    def rows(self, robot: str | None, *, newest_first: bool = False) -> Iterator[Row]:
        """The rows of ``robot`` (None: the rows without one), oldest first."""
        group = self._by_robot.get(robot, ())
        return reversed(group) if newest_first else iter(group)

    def all_rows(self) -> Iterator[Row]:
        """Every row, robot by robot (in name order), oldest first within each."""
        for robot in sorted(self._by_robot, key=lambda k: k or ""):
            yield from self._by_robot[robot]

    def newest(self, robot: str | None) -> Row | None:
        rows = self._by_robot.get(robot)
        return rows[-1] if rows else None

    def remove(self, doomed: Callable[[Row], bool]) -> int:
        """Delete every row ``doomed`` says (people's tables: a zone removed); how many."""
        removed = 0
        for robot, rows in self._by_robot.items():
            kept = [r for r in rows if not doomed(r)]
            removed += len(rows) - len(kept)
            self._by_robot[robot] = deque(kept, maxlen=self.keep)
        self.by_id = {i: r for i, r in self.by_id.items() if not doomed(r)}
        return removed


class MemoryContract:
    """Every contract table the navigation services use, plus the change listeners."""

    def __init__(self) -> None:
        self.tables = {
            name: Table(name, RETENTION.get(name))
            for name in (
                keys.ROBOT,
                keys.MAP,
                keys.CHARGING_STATION,
                keys.STRATEGY,
                keys.ACTIVE_STRATEGY,
                keys.GOAL,
                keys.GOAL_WAYPOINT,
                keys.ODOMETRY,
                keys.LASER_SCAN,
                keys.BATTERY,
                keys.COLLISION_EVENT,
                keys.COMMAND_RECOMMENDATION,
                keys.COMMAND2ROBOT,
                keys.SYSTEM_COMMAND,
                keys.USER_COMMAND,
                keys.PLANNED_PATH,
                keys.SCENARIO_OFFER,
                keys.ZONE,
            )
        }
        self.listeners: list[Listener] = []
        self.row_listeners: list[RowListener] = []
        # command_recommendation rows not yet expired, per robot: the decision asks for the
        # live ones 30+ times a sim second; sim time only goes forward within a run, so a row
        # found expired once is dropped from here for good (the table keeps it).
        self._live: dict[str, list[Row]] = {}
        self._live_now = float("-inf")

    def __getitem__(self, table: str) -> Table:
        return self.tables[table]

    def insert(self, table: str, row: Row, *, notify: bool = True) -> int:
        row_id = self.tables[table].insert(row)
        if table == keys.COMMAND_RECOMMENDATION:
            self._live.setdefault(row["robot_id"], []).append(row)
        if notify:
            self.changed(table, row.get("robot_id"), row_id, row)
        return row_id

    def insert_recommendation(self, recommendation: Recommendation) -> int:
        """Write a command_recommendation row (not yet treated) and announce it, as
        ``write_recommendation`` does in the stack; its id."""
        image = recommendation.image()
        row = {**image, "inputs": dict(image["inputs"]), "treated_by": None}
        return self.insert(keys.COMMAND_RECOMMENDATION, row)

    def changed(
        self, table: str, robot: str | None, row_id: int | None, row: Row | None = None
    ) -> None:
        """What a Zenoh notification does in the stack: tell whoever watches ``table``;
        ``row`` (the row ``row_id`` as committed) goes to the row listeners as its image."""
        for listener in self.listeners:
            listener(table, robot, row_id)
        if self.row_listeners:
            # a copy: the table's row changes in place later (treated_by, a goal's status),
            # an image is the row as it was committed
            image = dict(row) if row is not None and row_id is not None else None
            for row_listener in self.row_listeners:
                row_listener(table, robot, row_id, image)

    def offer(self, service: str, scenarios: Iterable[str]) -> None:
        """What a planner's or controller's start writes in scenario_offer: the scenarios it
        can run. The monolith's services live as long as it does: its offers stay live."""
        for name in scenarios:
            row = {"service": service, "instance": "monolith", "scenario": name}
            self.insert(keys.SCENARIO_OFFER, row, notify=False)
        self.changed(keys.SCENARIO_OFFER, None, None)  # announced once, as the service does

    def offers(self) -> Offers:
        """The live offers (common.contract.offers.LIVE_OFFERS_SQL's answer)."""
        rows = self[keys.SCENARIO_OFFER].all_rows()
        return Offers.of((row["service"], row["scenario"]) for row in rows)

    def live_recommendations(self, robot: str, now: float) -> list[Row]:
        """The robot's command_recommendation rows with ``expires_stamp > now``, id order."""
        if now < self._live_now:  # time went back (never within one run): start over
            for robot_id in list(self._live):
                self._live[robot_id] = list(self[keys.COMMAND_RECOMMENDATION].rows(robot_id))
        self._live_now = now
        live = [r for r in self._live.get(robot, ()) if r["expires_stamp"] > now]
        self._live[robot] = live
        return live
