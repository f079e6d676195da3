"""The faults benchmark's "rows lost": keys committed before, looked for after; rows the
retention policy prunes anyway are not counted (pnav/bench/faults/committed_rows.py)."""

from __future__ import annotations

import asyncpg

from pnav.bench.faults import committed_rows


async def test_a_deleted_row_is_lost_and_a_row_retention_pruned_is_not(
    conn: asyncpg.Connection,
) -> None:
    await conn.execute("INSERT INTO robot (robot_id) VALUES ('r1')")
    await conn.execute(
        "UPDATE retention_policy SET keep_rows_per_robot = 3 WHERE table_name = 'battery'"
    )
    goals = [
        await conn.fetchval(
            "INSERT INTO goal (robot_id, x, y, status) VALUES ('r1', $1, 0, 'superseded') "
            "RETURNING id",
            float(i),
        )
        for i in range(3)
    ]
    battery = [
        await conn.fetchval(
            "INSERT INTO battery (robot_id, stamp, energy_wh, capacity_wh, percentage) "
            "VALUES ('r1', $1, 10, 20, 50) RETURNING id",
            float(i),
        )
        for i in range(3)
    ]
    before = await committed_rows.snapshot(conn)
    assert before.keys["goal"] == {str(g) for g in goals}
    assert before.keys["robot"] == {"r1"}
    assert await committed_rows.lost(conn, before) == {}

    await conn.execute("DELETE FROM goal WHERE id = $1", goals[1])
    # three newer battery rows: retention (3 per robot) would prune the first three
    for i in range(3):
        await conn.execute(
            "INSERT INTO battery (robot_id, stamp, energy_wh, capacity_wh, percentage) "
            "VALUES ('r1', $1, 10, 20, 50)",
            10.0 + i,
        )
    await conn.execute("DELETE FROM battery WHERE id = ANY($1::bigint[])", battery)
    assert await committed_rows.lost(conn, before) == {"goal": 1}

    await conn.execute("DELETE FROM battery WHERE id = (SELECT max(id) FROM battery)")
    newer = await committed_rows.snapshot(conn)
    await conn.execute("DELETE FROM battery WHERE id = (SELECT max(id) FROM battery)")
    assert await committed_rows.lost(conn, newer) == {"battery": 1}  # one of the kept ones: lost
