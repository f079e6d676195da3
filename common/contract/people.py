"""People's writes: the goal and user_command rows a person's tool writes, with their
notifications, in one place for every client that acts for people (the CLI, the dashboard).

The contract makes these rows people's (CONTRACT.md, *Roles*: ``pnav_user``); the SQL here
is the contract's meaning of "set a goal" (the robot's active goal superseded in the same
transaction) and "cancel", so two clients cannot drift apart on it. Checking the values
first, and answering a refusal in the client's own words, stays with each client.
"""

from __future__ import annotations

from common.contract import keys
from common.db import Database

DEFAULT_TOLERANCE_M = 0.15  # the goal table's default, for a goal given without one

SUPERSEDE_SQL = (
    "UPDATE goal SET status = 'superseded', reason = 'replaced by a new goal' "
    "WHERE robot_id = $1 AND status = 'active'"
)
INSERT_GOAL_SQL = (
    "INSERT INTO goal (robot_id, x, y, tolerance_m) "
    f"VALUES ($1, $2, $3, coalesce($4, {DEFAULT_TOLERANCE_M})) RETURNING id"
)
CANCEL_SQL = (
    "UPDATE goal SET status = 'cancelled', reason = 'cancelled by user' "
    "WHERE robot_id = $1 AND status = 'active' RETURNING id"
)
INSERT_USER_COMMAND_SQL = (
    "INSERT INTO user_command (robot_id, command, argument) VALUES ($1, $2, $3) RETURNING id"
)


async def set_goal(db: Database, robot: str, x: float, y: float, tolerance: float | None) -> int:
    """Supersede ``robot``'s active goal and set a new one, in one transaction; its id."""
    async with db.transaction() as tx:
        await tx.conn.execute(SUPERSEDE_SQL, robot)
        goal_id = await tx.conn.fetchval(INSERT_GOAL_SQL, robot, x, y, tolerance)
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
