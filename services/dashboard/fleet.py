"""Each robot's newest rows, as the page shows them: the dashboard store's robot cache.

Rows come from notification images (:meth:`Fleet.apply`) or from the tables
(:meth:`Fleet.set_row`); a row older than the one held (a lower id) is ignored, so an image
and a re-read may arrive in any order. A decision is shown with the recommendations it
weighed: they are taken from the recommendation images seen, and read from the table when
missing (:meth:`Fleet.resolve`, one query for every robot).
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Awaitable, Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Final

import services.dashboard.scene as scene
from common.bus import Notification
from common.contract import keys

Row = Mapping[str, Any]
FetchRecommendations = Callable[[Sequence[int]], Awaitable[list[Row]]]

# tables whose image the page uses as it comes (CONTRACT.md, "Row images"), with the columns
# it needs: an image without them (a writer that sends fewer) is not used, the table is read
IMAGE_COLUMNS: Final[dict[str, frozenset[str]]] = {
    keys.ODOMETRY: frozenset({"id", "stamp", "x", "y", "yaw", "linear_mps", "angular_rps"}),
    keys.LASER_SCAN: frozenset(
        {"id", "stamp", "angle_min", "angle_increment", "range_min", "range_max", "ranges"}
    ),
    keys.BATTERY: frozenset({"id", "stamp", "percentage", "energy_wh", "charging", "power_w"}),
    keys.COMMAND2ROBOT: frozenset(
        {"id", "stamp", "linear_mps", "angular_rps", "recommendation_id", "source"}
        | {"considered_ids", "reason"}
    ),
    keys.PLANNED_PATH: frozenset({"id", "stamp", "target", "xs", "ys", "length_m"}),
    keys.COMMAND_RECOMMENDATION: frozenset(
        {"id", "kind", "source", "priority", "stamp", "expires_stamp", "reason"}
    ),
}
# recommendation images kept per robot to explain its decisions (a decision weighs the live
# ones: a few per scenario, renewed at 5-30 Hz)
KEEP_RECOMMENDATIONS: Final = 256


@dataclass
class RobotState:
    limits: Row | None = None
    rows: dict[str, Row] = field(default_factory=dict)
    # the pose when the newest scan came: its points are drawn from there
    scan_pose: Row | None = None
    decision: dict[str, Any] | None = None
    undecided: Row | None = None  # a decision row whose recommendations are not read yet
    recommendations: OrderedDict[int, Row] = field(default_factory=OrderedDict)
    # the newest scan's points, by (scan id, pose id): a robot is sent at 10 Hz, its scan
    # changes at 5
    points: tuple[tuple[Any, Any], list[float]] | None = None
    # the newest goal's route (goal_waypoint rows as the page draws them), and its goal id
    route: list[dict[str, Any]] = field(default_factory=list)
    route_goal: int | None = None

    def scan_points(self, scan: Row, pose: Row) -> list[float]:
        key = (scan.get("id"), pose.get("id"))
        if self.points is None or self.points[0] != key:
            self.points = (key, scene.lidar_points(scan, pose))
        return self.points[1]


class Fleet:
    def __init__(self) -> None:
        self.robots: dict[str, RobotState] = {}
        self._changed: set[str] = set()

    def _state(self, robot: str) -> RobotState:
        state = self.robots.get(robot)
        if state is None:
            state = self.robots[robot] = RobotState()
        return state

    def set_robots(self, rows: Sequence[Row]) -> None:
        known = {row["robot_id"]: row for row in rows}
        for gone in set(self.robots) - set(known):
            del self.robots[gone]
        for robot, row in known.items():
            state = self._state(robot)
            if state.limits != row:
                state.limits = row
                self._changed.add(robot)

    def known(self, robot: str) -> bool:
        state = self.robots.get(robot)
        return state is not None and state.limits is not None

    def apply(self, note: Notification) -> bool:
        """Use ``note``'s image; False when it has none the page can use (read the table)."""
        needed = IMAGE_COLUMNS.get(note.table)
        if note.robot is None or note.row is None or needed is None:
            return False
        if not needed <= note.row.keys():
            return False
        if note.table == keys.COMMAND_RECOMMENDATION:
            recs = self._state(note.robot).recommendations
            recs[int(note.row["id"])] = note.row
            while len(recs) > KEEP_RECOMMENDATIONS:
                recs.popitem(last=False)
            return True
        self.set_row(note.table, {**note.row, "robot_id": note.robot})
        return True

    def set_row(self, table: str, row: Row) -> None:
        robot = str(row["robot_id"])
        state = self._state(robot)
        held = state.rows.get(table)
        held_id = None if held is None else held.get("id")
        new_id = row.get("id")
        if held_id is not None and new_id is not None and int(new_id) < int(held_id):
            return
        state.rows[table] = row
        if table == keys.LASER_SCAN:
            state.scan_pose = state.rows.get(keys.ODOMETRY)
        elif table == keys.COMMAND2ROBOT:
            state.undecided = row
        self._changed.add(robot)

    def goal_ids(self, robots: set[str] | None) -> dict[str, int]:
        """robot -> the id of its newest goal row held (of these robots; None: every one)."""
        out = {}
        for name, state in self.robots.items():
            goal = state.rows.get(keys.GOAL)
            if goal is not None and (robots is None or name in robots):
                out[name] = int(goal["id"])
        return out

    def set_route(self, robot: str, goal_id: int, rows: Sequence[Row]) -> None:
        state = self._state(robot)
        route = [scene.waypoint(row) for row in rows]
        if (state.route_goal, state.route) != (goal_id, route):
            state.route, state.route_goal = route, goal_id
            self._changed.add(robot)

    async def resolve(self, fetch: FetchRecommendations) -> None:
        """Build the decisions not shown yet, with the recommendations each one weighed."""
        waiting = {r: s for r, s in self.robots.items() if s.undecided is not None}
        if not waiting:
            return
        missing = [
            int(i)
            for state in waiting.values()
            for i in (state.undecided or {}).get("considered_ids") or ()
            if int(i) not in state.recommendations
        ]
        found: dict[int, Row] = {}
        if missing:
            found = {int(row["id"]): row for row in await fetch(missing)}
        for robot, state in waiting.items():
            row = state.undecided
            if row is None:
                continue
            ids = [int(i) for i in row.get("considered_ids") or ()]
            weighed = [state.recommendations.get(i) or found.get(i) for i in ids]
            state.decision = scene.decision(row, [r for r in weighed if r is not None])
            state.undecided = None
            self._changed.add(robot)

    def take_changed(self) -> set[str]:
        changed, self._changed = self._changed, set()
        return changed

    def as_json(self, robots: set[str] | None) -> dict[str, Any]:
        names = sorted(self.robots if robots is None else robots & set(self.robots))
        return {name: robot_json(name, self.robots[name]) for name in names}


def robot_json(name: str, state: RobotState) -> dict[str, Any]:
    rows = state.rows
    odom, scan = rows.get(keys.ODOMETRY), rows.get(keys.LASER_SCAN)
    strategy, goal = rows.get(keys.ACTIVE_STRATEGY), rows.get(keys.GOAL)
    batt, path = rows.get(keys.BATTERY), rows.get(keys.PLANNED_PATH)
    scan_pose = state.scan_pose or odom
    return {
        "id": name,
        "limits": None if state.limits is None else scene.robot_limits(state.limits),
        "pose": None if odom is None else scene.pose(odom),
        "scan": None
        if scan is None or scan_pose is None
        else {
            "id": scan["id"],
            "stamp": scene.jsonable(scan["stamp"]),
            "points": state.scan_points(scan, scan_pose),
        },
        "battery": None if batt is None else scene.battery(batt),
        "strategy": None if strategy is None else scene.strategy_state(strategy),
        "goal": None if goal is None else scene.goal(goal),
        "route": state.route if goal is not None and state.route_goal == goal["id"] else [],
        "path": None if path is None else scene.path(path),
        "decision": state.decision,
    }
