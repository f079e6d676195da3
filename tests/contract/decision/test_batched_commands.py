"""Several robots' commands in one statement (services/decision/source.py), on Postgres.

The decision writes the commands of every robot it decided in one activation with ONE
statement: one commit for all of them. What must hold for each robot all the same: its row
names its own winner and what it considered, exactly those recommendations are marked
``treated_by`` that row, and its notification carries that row's id and image (the bridge
sends from it). A row the database refuses costs only itself.
"""

from __future__ import annotations

from typing import Any

from common import bus
from common.bus import Notification
from common.contract import keys, recommendations
from common.runtime import Runtime
from pnav._testing import eventually
from services.decision.arbitration import RobotDecision
from services.decision.source import PgDecisionSource
from tests.contract.decision.test_decision_service import add_robot

NOT_IN_THE_IMAGE = ("created_at", "safety", "sent_linear_mps", "sent_angular_rps")


async def recommend(client: Runtime, robot_id: str, source: str, priority: int) -> int:
    return await recommendations.recommend_velocity(
        client.database,
        robot_id,
        source=source,
        priority=priority,
        linear=0.1 * priority,
        angular=0.0,
        stamp=10.0,
        ttl_s=5.0,
        reason=f"{source} for {robot_id}",
    )


def decision(robot_id: str, winner: int | None, considered: tuple[int, ...]) -> RobotDecision:
    return RobotDecision(
        robot_id, 10.0, 0.2, 0.1, winner, None if winner is None else "s", considered, "why"
    )


async def rows(client: Runtime, sql: str, *args: Any) -> list[dict[str, Any]]:
    return [dict(r) for r in await client.database.pool.fetch(sql, *args)]


async def test_each_robot_keeps_its_own_provenance_in_one_commit(client: Runtime) -> None:
    heard: list[Notification] = []
    watch = bus.subscribe(
        client.zenoh,
        keys.notify_watch(keys.COMMAND2ROBOT),
        lambda key, payload: heard.append(Notification.decode(key, payload)),
    )
    try:
        for robot_id in ("r1", "r2", "r3"):
            await add_robot(client, robot_id)
        r1 = (await recommend(client, "r1", "a", 10), await recommend(client, "r1", "b", 50))
        r2 = (await recommend(client, "r2", "a", 30),)
        decisions = [
            decision("r1", r1[1], r1),
            decision("r2", r2[0], r2),
            decision("r3", None, ()),  # a stop: it considered nothing
        ]
        ids = await PgDecisionSource(client.database).write_robot_commands(decisions)
        assert len(set(ids)) == 3 and None not in ids
        written = await rows(client, "SELECT *, xmin::text AS tx FROM command2robot ORDER BY id")
        assert [r["id"] for r in written] == sorted(i for i in ids if i is not None)
        assert len({r["tx"] for r in written}) == 1  # one statement, one transaction
        by_robot = {r["robot_id"]: r for r in written}
        for d, row_id in zip(decisions, ids, strict=True):
            row = by_robot[d.robot_id]
            assert row["id"] == row_id
            assert (row["recommendation_id"], row["considered_ids"]) == (
                d.recommendation_id,
                list(d.considered_ids),
            )
        treated = await rows(
            client, "SELECT id, treated_by FROM command_recommendation ORDER BY id"
        )
        assert treated == [
            {"id": r1[0], "treated_by": ids[0]},
            {"id": r1[1], "treated_by": ids[0]},
            {"id": r2[0], "treated_by": ids[1]},
        ]

        def all_heard() -> bool:
            return {n.robot for n in heard} == {"r1", "r2", "r3"}

        await eventually(all_heard, what="one command2robot notification per robot")
        for note in heard:
            row = by_robot[note.robot or ""]
            assert note.id == row["id"]
            image = {k: v for k, v in row.items() if k not in (*NOT_IN_THE_IMAGE, "tx")}
            assert note.row == image
    finally:
        watch.undeclare()


async def test_a_refused_row_costs_only_itself(client: Runtime) -> None:
    await add_robot(client, "r1")
    rec = await recommend(client, "r1", "a", 10)
    # "gone" is no robot (deleted meanwhile, say): its row breaks the foreign key
    ids = await PgDecisionSource(client.database).write_robot_commands(
        [decision("r1", rec, (rec,)), decision("gone", None, ())]
    )
    assert ids[1] is None and ids[0] is not None
    written = await rows(client, "SELECT id, robot_id FROM command2robot")
    assert written == [{"id": ids[0], "robot_id": "r1"}]
    treated = await rows(client, "SELECT treated_by FROM command_recommendation")
    assert treated == [{"treated_by": ids[0]}]
