"""What the planner's rules see of the store: two small Protocols, never a pool or a service.

``PlannerStore`` (store.py) implements them over Postgres in the service and over the
in-memory contract in the monolith (pnav/monolith/memory_planner.py); a test may implement them
however it likes. Target rules (the move scenarios, the battery rules) take a
:class:`PlannerView`; the meta-planner a :class:`MetaView`.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any, Protocol, Unpack

from common.contract import records
from common.contract.offers import Offers
from common.contract.recommendations import SystemFields, VelocityFields
from common.planner_core.scenario import RobotInfo
from services.planner.published_path import PathRow
from services.planner.routes import Target
from services.planner.tracking import Progress
from services.planner.world_model import MapData, RobotState, Station


class Clocks(Protocol):
    def now(self) -> float:
        """Sim time."""

    def started(self) -> bool:
        """Whether sim time is known yet."""

    def clock(self) -> float:
        """The clock of the planner's own gates: wall s in a service, sim s in lockstep."""


class Rows(Protocol):
    """The newest sensor rows and the goal writes, as the rules see them and the source
    (source.py) has them: the store answers from a row image where a fresh one came with a
    notification, and from its source otherwise."""

    async def newest_odometry(self, robot_id: str) -> records.Odometry | None: ...

    async def newest_scan(self, robot_id: str) -> records.LaserScan | None: ...

    async def newest_battery(self, robot_id: str) -> records.Battery | None: ...

    async def mark_reached(self, goal_id: int, robot_id: str, stamp: float) -> bool:
        """Set the goal 'reached' and notify; False if it was no longer active."""

    async def mark_failed(
        self, goal_id: int, robot_id: str, reason: str, stamp: float, strategy: str | None = None
    ) -> bool:
        """Set the goal 'failed' with ``reason`` and notify; False if it was no longer active
        (or, with ``strategy``, if the robot's active strategy is no longer that one: a rule
        failing goals for its strategy never fails one given after a switch it has not seen
        yet)."""

    async def mark_waypoint(
        self, goal_id: int, seq: int, robot_id: str, status: str, reason: str | None, stamp: float
    ) -> bool:
        """Set a route's waypoint ``status`` (reached, failed) if it is pending and its goal
        active, and notify; whether it was."""


class Contract(Clocks, Rows, Protocol):
    """The rows the target rules read and write, and what notifications told the store."""

    def odometry_notes(self, robot_id: str) -> int:
        """How many odometry notifications named the robot so far."""

    def goal_news(self, robot: RobotState) -> bool:
        """Whether a goal notification for the robot came since its goal was last read."""

    async def active_goal(self, robot: RobotState) -> records.Goal | None:
        """The robot's active goal, read again only after a goal notification for it (or
        FAST_REFRESH_S after the last read)."""

    async def live_system(self, robot_id: str, command: str) -> float | None:
        """Expiry of this robot's newest unexpired ``command`` recommendation, if any."""

    async def recommend_velocity(self, robot_id: str, **row: Unpack[VelocityFields]) -> None:
        """Write a velocity recommendation (the service's store holds it until the end of
        the activation and writes the activation's rows in one statement)."""

    async def recommend_system(self, robot_id: str, **row: Unpack[SystemFields]) -> int: ...

    async def publish_path(self, path: PathRow) -> int:
        """Write a planned_path row and notify (CONTRACT.md, planned_path); its id."""


class Planning(Protocol):
    """The world and the routes on it."""

    def robot(self, robot_id: str) -> RobotState | None: ...

    def map_for(self, info: RobotInfo) -> MapData | None: ...

    def see(self, robot: RobotState, scan: records.LaserScan) -> None:
        """Note the scan's unmapped obstacles (obstacles.py)."""

    def route_for(
        self, robot: RobotState, x: float, y: float, target: Target, now: float | None = None
    ) -> Progress: ...

    def distance(self, robot: RobotState, a: tuple[float, float], b: tuple[float, float]) -> float:
        """Path length on the robot's map (a straight line without one)."""

    def choose_station(self, robot: RobotState, x: float, y: float) -> Station | None: ...


class PlannerView(Contract, Planning, Protocol):
    """Everything a target rule sees."""


class MetaView(Protocol):
    """What the meta-planner sees."""

    async def refresh(self) -> None:
        """Read what changed: robots, maps and stations; the active strategies."""

    def robots(self) -> Iterable[RobotState]: ...

    def offers(self) -> Offers:
        """What the live planners and controllers offer (scenario_offer), as last read."""

    def warn_once(self, what: str, message: str, **fields: Any) -> None: ...


class PlannerStoreView(MetaView, PlannerView, Protocol):
    """Both views: what the planner's store (store.PlannerStore) is."""
