"""common.writebehind: rows held until a flush, written in as few calls as their keys allow,
each caller told its row's id (None when it was not written)."""

from __future__ import annotations

from collections.abc import Sequence

from common.writebehind import WriteBehind

Row = tuple[str, str, int]  # (robot, source, value)


class Table:
    """An append-only table that hands out ids, recording each call's rows."""

    def __init__(self, refuse: frozenset[str] = frozenset(), fail_calls: int = 0) -> None:
        self.rows: list[tuple[int, Row]] = []
        self.calls: list[list[Row]] = []
        self.refuse = refuse  # robots whose rows it refuses (None for them)
        self.fail_calls = fail_calls  # the first N calls raise (a lost connection)

    async def write_many(self, rows: Sequence[Row]) -> list[int | None]:
        self.calls.append(list(rows))
        if len(self.calls) <= self.fail_calls:
            raise ConnectionError("connection lost")
        ids: list[int | None] = []
        for row in rows:
            if row[0] in self.refuse:
                ids.append(None)
                continue
            self.rows.append((len(self.rows) + 1, row))
            ids.append(len(self.rows))
        return ids


def key(row: Row) -> tuple[str, str]:
    return row[0], row[1]


async def test_rows_are_held_until_the_flush_and_go_in_one_call() -> None:
    table = Table()
    behind = WriteBehind(table.write_many, key, "t")
    told: list[tuple[Row, int | None]] = []
    behind.add(("r1", "a", 1), lambda row, row_id: told.append((row, row_id)))
    behind.add(("r2", "a", 2), lambda row, row_id: told.append((row, row_id)))
    behind.add(("r1", "b", 3))  # nobody to tell: written all the same
    assert (len(behind), table.calls) == (3, [])  # nothing written yet
    await behind.flush()
    assert table.calls == [[("r1", "a", 1), ("r2", "a", 2), ("r1", "b", 3)]]  # one call
    assert told == [(("r1", "a", 1), 1), (("r2", "a", 2), 2)]
    assert (len(behind), behind.calls, behind.written, behind.failed) == (0, 1, 3, 0)
    await behind.flush()  # nothing held: no call
    assert len(table.calls) == 1


async def test_a_key_asked_twice_goes_in_a_later_call_in_the_order_asked() -> None:
    table = Table()
    behind = WriteBehind(table.write_many, key, "t")
    for row in [("r1", "a", 1), ("r2", "a", 2), ("r1", "a", 3), ("r2", "b", 4)]:
        behind.add(row)
    await behind.flush()
    # the first run of distinct keys, then the rest from the repeat on
    assert table.calls == [[("r1", "a", 1), ("r2", "a", 2)], [("r1", "a", 3), ("r2", "b", 4)]]
    assert [row for _, row in table.rows] == [("r1", "a", 1), ("r2", "a", 2), ("r1", "a", 3),
                                              ("r2", "b", 4)]  # fmt: skip


async def test_a_failed_call_tells_its_rows_none_and_the_rest_still_go() -> None:
    table = Table(refuse=frozenset({"gone"}), fail_calls=1)
    behind = WriteBehind(table.write_many, key, "t")
    told: dict[int, int | None] = {}
    for value, robot in enumerate(["r1", "r1", "gone"]):
        behind.add((robot, "a", value), lambda row, row_id: told.update({row[2]: row_id}))
    await behind.flush()
    # call 1 (r1's first row) lost; call 2 (r1's second, gone's): gone's refused
    assert told == {0: None, 1: 1, 2: None}
    assert (behind.calls, behind.written, behind.failed) == (2, 1, 2)
