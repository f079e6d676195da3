"""People's writes: the goal and user_command rows a person's tool writes, with their
notifications, in one place for every client that acts for people (the CLI, the dashboard).

The contract makes these rows people's (CONTRACT.md, *Roles*: ``pnav_user``); the SQL here
is the contract's meaning of "set a goal" (the robot's active goal superseded in the same
transaction) and "cancel", so two clients cannot drift apart on it. Checking the values
first, and answering a refusal in the client's own words, stays with each client.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from common.contract import keys, limits
from common.db import Database
from common.errors import ContractError

DEFAULT_TOLERANCE_M = 0.15  # the goal table's default, for a goal given without one


@dataclass(frozen=True)
class Pose:
    """A pose a person gives: a goal's, or a waypoint's on the way to it. ``yaw`` (rad, map
    frame) None: any heading; its tolerance None with a yaw: DEFAULT_YAW_TOLERANCE_RAD.
    ``tolerance_m`` None: the table's default (a goal's 0.15 m, a waypoint's 0.3 m);
    ``stop``: a waypoint the robot halts at (a waypoint with a yaw halts anyway)."""

    x: float
    y: float
    yaw: float | None = None
    yaw_tolerance_rad: float | None = None
    tolerance_m: float | None = None
    stop: bool = False

    def check(self, what: str) -> None:
        """ContractError naming the first value (of ``what``: "goal", "waypoint 2") the goal
        and goal_waypoint tables would refuse."""
        try:
            limits.check_goal(self.x, self.y, self.tolerance_m)
        except ContractError as e:
            raise ContractError(str(e).replace("goal", what, 1)) from None
        limits.check_heading(what, self.yaw, self.yaw_tolerance_rad)

    @property
    def heading_tolerance(self) -> float | None:
        """The tolerance written: the given one, the default with a yaw, NULL without."""
        if self.yaw is None:
            return None
        return self.yaw_tolerance_rad or limits.DEFAULT_YAW_TOLERANCE_RAD


def check_route(goal: Pose, waypoints: Sequence[Pose] = ()) -> None:
    """ContractError naming the first value a goal with these waypoints would be refused for."""
    limits.check_waypoint_count(len(waypoints))
    for seq, waypoint in enumerate(waypoints, start=1):
        waypoint.check(f"waypoint {seq}")
    goal.check("goal")


SUPERSEDE_SQL = (
    "UPDATE goal SET status = 'superseded', reason = 'replaced by a new goal' "
    "WHERE robot_id = $1 AND status = 'active'"
)
INSERT_GOAL_SQL = (
    "INSERT INTO goal (robot_id, x, y, tolerance_m, yaw, yaw_tolerance_rad) "
    f"VALUES ($1, $2, $3, coalesce($4, {DEFAULT_TOLERANCE_M}), $5, $6) RETURNING id"
)
# the route in one statement, whatever its length (seq from 1, in the list's order)
INSERT_WAYPOINTS_SQL = (
    "INSERT INTO goal_waypoint (goal_id, seq, x, y, tolerance_m, yaw, yaw_tolerance_rad, stop) "
    "SELECT $1, w.seq, w.x, w.y, "
    f"coalesce(w.tolerance_m, {limits.DEFAULT_WAYPOINT_TOLERANCE_M}), w.yaw, w.yaw_tol, w.stop "
    "FROM unnest($2::int[], $3::float8[], $4::float8[], $5::float8[], $6::float8[], "
    "$7::float8[], $8::bool[]) AS w(seq, x, y, tolerance_m, yaw, yaw_tol, stop)"
)
CANCEL_SQL = (
    "UPDATE goal SET status = 'cancelled', reason = 'cancelled by user' "
    "WHERE robot_id = $1 AND status = 'active' RETURNING id"
)
INSERT_USER_COMMAND_SQL = (
    "INSERT INTO user_command (robot_id, command, argument) VALUES ($1, $2, $3) RETURNING id"
)


async def set_goal(
    db: Database,
    robot: str,
    x: float,
    y: float,
    tolerance: float | None,
    *,
    yaw: float | None = None,
    yaw_tolerance_rad: float | None = None,
    waypoints: Sequence[Pose] = (),
) -> int:
    """:func:`set_route` to the pose (x, y), ``yaw`` in radians."""
    return await set_route(db, robot, Pose(x, y, yaw, yaw_tolerance_rad, tolerance), waypoints)


async def set_route(db: Database, robot: str, goal: Pose, waypoints: Sequence[Pose] = ()) -> int:
    """Supersede ``robot``'s active goal and set a new one (with its heading, and the route's
    waypoints before it), in one transaction; its id. The planner hears the goal's
    notification and reads the waypoints with it."""
    async with db.transaction() as tx:
        await tx.conn.execute(SUPERSEDE_SQL, robot)
        goal_id = await tx.conn.fetchval(
            INSERT_GOAL_SQL,
            robot,
            goal.x,
            goal.y,
            goal.tolerance_m,
            goal.yaw,
            goal.heading_tolerance,
        )
        if waypoints:
            await tx.conn.execute(
                INSERT_WAYPOINTS_SQL,
                goal_id,
                list(range(1, len(waypoints) + 1)),
                [w.x for w in waypoints],
                [w.y for w in waypoints],
                [w.tolerance_m for w in waypoints],
                [w.yaw for w in waypoints],
                [w.heading_tolerance for w in waypoints],
                [w.stop for w in waypoints],
            )
            tx.changed(keys.GOAL_WAYPOINT, robot, goal_id)
        tx.changed(keys.GOAL, robot, goal_id)
    return int(goal_id)


async def cancel_goal(db: Database, robot: str) -> int | None:
    """Cancel ``robot``'s active goal; its id, or None when it had none."""
    async with db.transaction() as tx:
        goal_id = await tx.conn.fetchval(CANCEL_SQL, robot)
        if goal_id is not None:
            tx.changed(keys.GOAL, robot, goal_id)
    return None if goal_id is None else int(goal_id)


async def user_command(db: Database, robot: str, command: str, argument: str | None) -> int:
    """Insert a user_command for the strategy service to judge; its id."""
    value = await db.write(
        keys.USER_COMMAND, robot, INSERT_USER_COMMAND_SQL, robot, command, argument
    )
    return int(value)
