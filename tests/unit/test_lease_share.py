"""The share arithmetic of robot leases (common.lease.decide), without a database.

A small simulation plays Postgres' part: a dict of robot -> holder stands for the advisory
locks (a try-lock succeeds only on a free robot), and replicas run their cycles in turn.
"""

from __future__ import annotations

import hashlib
import random

import pytest

from common.lease import Snapshot, affinity, decide, fair_share, lease_key

SETTLE = 2


@pytest.mark.parametrize(
    ("robots", "replicas", "share"),
    [
        (6, 3, (2, 2)),
        (7, 3, (2, 3)),
        (2, 3, (0, 1)),
        (0, 2, (0, 0)),
        (5, 1, (5, 5)),
        (6, 0, (6, 6)),
    ],
)
def test_fair_share_is_floor_and_ceil(robots: int, replicas: int, share: tuple[int, int]) -> None:
    assert fair_share(robots, replicas) == share


def test_lease_key_is_the_contracts_31_bit_sha256_and_never_zero() -> None:
    expected = int.from_bytes(hashlib.sha256(b"controller").digest()[:4], "big") & 0x7FFFFFFF
    assert lease_key("controller") == expected
    keys = {lease_key(f"r{i}") for i in range(2000)}
    assert len(keys) == 2000 and all(0 < k < 2**31 for k in keys)
    services = ("strategy", "planner", "controller", "decision")
    assert len({lease_key(s) for s in services}) == 4


def view(holders: dict[str, int | None], members: set[int], me: int) -> Snapshot:
    robots = tuple(sorted(holders))
    return Snapshot(robots, dict(holders), frozenset(members), me)


def test_a_lone_replica_takes_every_robot_at_once() -> None:
    d = decide(view(dict.fromkeys(["r1", "r2", "r3"]), {1}, 1), frozenset(), "a", 0, SETTLE)
    assert d.want == 3 and set(d.acquire) == {"r1", "r2", "r3"} and d.release == ()
    assert d.share == (3, 3) and d.replicas == 1


def test_taking_is_immediate_and_giving_back_waits_for_the_settle_cycles() -> None:
    # a joined second replica: the first holds all 4, its share is now 2
    holders: dict[str, int | None] = {"r1": 1, "r2": 1, "r3": 1, "r4": 1}
    owned = frozenset(holders)
    first = decide(view(holders, {1, 2}, 1), owned, "a", 0, SETTLE)
    assert first.release == () and first.pending == 1  # not yet: hysteresis
    second = decide(view(holders, {1, 2}, 1), owned, "a", first.pending, SETTLE)
    assert len(second.release) == 2 and second.pending == 0
    # the excess went away in between (the newcomer left): the count starts again
    gone = decide(view(holders, {1}, 1), owned, "a", 1, SETTLE)
    assert gone.release == () and gone.pending == 0


def test_the_poorer_replicas_pick_free_robots_first() -> None:
    # 7 robots, 2 replicas (lo 3, hi 4): me 3, the other 2, two free
    holders: dict[str, int | None] = {f"r{i}": None for i in range(7)}
    for r in ("r0", "r1", "r2"):
        holders[r] = 1
    for r in ("r3", "r4"):
        holders[r] = 2
    owned = frozenset({"r0", "r1", "r2"})
    d = decide(view(holders, {1, 2}, 1), owned, "a", 0, SETTLE)
    assert d.share == (3, 4) and d.want == 1  # one for the other to reach 3, one for me
    # 7 robots, 3 replicas (lo 2, hi 3): me 2, others 3 and 1, one free: it is the poorer's
    holders = {"r0": 1, "r1": 1, "r2": 2, "r3": 2, "r4": 2, "r5": 3, "r6": None}
    d = decide(view(holders, {1, 2, 3}, 1), frozenset({"r0", "r1"}), "a", 0, SETTLE)
    assert d.share == (2, 3) and d.want == 0
    d = decide(view(holders, {1, 2, 3}, 3), frozenset({"r5"}), "c", 0, SETTLE)
    assert d.want == 1 and d.acquire == ("r6",)


def test_only_the_richest_gives_one_back_to_a_replica_below_the_floor() -> None:
    # 6 robots, 4 replicas (lo 1, hi 2): 2, 2, 2 and a newcomer with none, nothing free
    holders: dict[str, int | None] = {
        "r1": 10,
        "r2": 10,
        "r3": 20,
        "r4": 20,
        "r5": 30,
        "r6": 30,
    }
    members = {10, 20, 30, 40}
    results = {}
    for me in (10, 20, 30):
        owned = frozenset(r for r, pid in holders.items() if pid == me)
        d = decide(view(holders, members, me), owned, f"i{me}", SETTLE - 1, SETTLE)
        results[me] = len(d.release)
    assert results == {10: 1, 20: 0, 30: 0}  # ties go to the lowest backend pid


def test_release_gives_back_the_robots_of_least_affinity() -> None:
    holders: dict[str, int | None] = {f"r{i}": 1 for i in range(4)}
    owned = frozenset(holders)
    d = decide(view(holders, {1, 2}, 1), owned, "a", SETTLE - 1, SETTLE)
    ranked = sorted(owned, key=lambda r: affinity("a", r))
    assert d.release == tuple(ranked[:2])


class Fleet:
    """Replicas deciding in turn over a shared lock table, as Postgres would serialise them."""

    def __init__(self, robots: int, seed: int = 1) -> None:
        self.locks: dict[str, int | None] = {f"r{i}": None for i in range(robots)}
        self.replicas: dict[int, str] = {}
        self.pending: dict[int, int] = {}
        self.changes = 0
        self.random = random.Random(seed)

    def join(self, pid: int) -> None:
        self.replicas[pid] = f"inst-{pid}"
        self.pending[pid] = 0

    def die(self, pid: int) -> None:
        del self.replicas[pid]
        for robot, holder in self.locks.items():
            if holder == pid:
                self.locks[robot] = None  # the connection closed: Postgres frees its locks

    def owned(self, pid: int) -> frozenset[str]:
        return frozenset(r for r, h in self.locks.items() if h == pid)

    def cycle(self) -> None:
        order = list(self.replicas)
        self.random.shuffle(order)
        for pid in order:
            snap = view(self.locks, set(self.replicas), pid)
            d = decide(snap, self.owned(pid), self.replicas[pid], self.pending[pid], SETTLE)
            self.pending[pid] = d.pending
            for robot in d.release:
                self.locks[robot] = None
                self.changes += 1
            taken = 0
            for robot in d.acquire:
                if taken >= d.want:
                    break
                if self.locks[robot] is None:  # pg_try_advisory_lock
                    self.locks[robot] = pid
                    taken += 1
                    self.changes += 1

    def counts(self) -> list[int]:
        return sorted(len(self.owned(pid)) for pid in self.replicas)

    def unowned(self) -> int:
        return sum(1 for h in self.locks.values() if h is None)

    def run_until_balanced(self, limit: int = 20) -> int:
        lo, hi = fair_share(len(self.locks), len(self.replicas))
        for n in range(1, limit + 1):
            self.cycle()
            if self.unowned() == 0 and all(lo <= c <= hi for c in self.counts()):
                return n
        raise AssertionError(f"not balanced after {limit} cycles: {self.counts()}")

    def assert_stable(self, cycles: int = 30) -> None:
        before = (self.changes, dict(self.locks))
        for _ in range(cycles):
            self.cycle()
        assert (self.changes, self.locks) == before, "ownership flapped once balanced"


@pytest.mark.parametrize(("robots", "replicas"), [(6, 3), (7, 3), (2, 3), (10, 4), (1, 1)])
def test_replicas_joining_one_by_one_reach_a_fair_share_and_stay_there(
    robots: int, replicas: int
) -> None:
    fleet = Fleet(robots)
    for pid in range(1, replicas + 1):
        fleet.join(pid)
        fleet.run_until_balanced()
    lo, hi = fair_share(robots, replicas)
    assert all(lo <= c <= hi for c in fleet.counts()) and sum(fleet.counts()) == robots
    fleet.assert_stable()


def test_a_dead_replicas_robots_are_taken_over_in_one_cycle() -> None:
    fleet = Fleet(6)
    for pid in (1, 2, 3):
        fleet.join(pid)
    fleet.run_until_balanced()
    assert fleet.counts() == [2, 2, 2]
    fleet.die(2)
    fleet.cycle()
    assert fleet.unowned() == 0 and fleet.counts() == [3, 3]
    fleet.assert_stable()


def test_an_uneven_takeover_needs_no_give_back() -> None:
    fleet = Fleet(7)
    for pid in (1, 2, 3):
        fleet.join(pid)
    fleet.run_until_balanced()
    fleet.die(next(pid for pid in (1, 2, 3) if len(fleet.owned(pid)) == 3))
    fleet.cycle()
    assert fleet.unowned() == 0 and fleet.counts() == [3, 4]


def test_a_newcomer_gets_a_share_from_a_full_fleet() -> None:
    fleet = Fleet(6)
    for pid in (1, 2, 3):
        fleet.join(pid)
    fleet.run_until_balanced()
    fleet.join(4)
    cycles = fleet.run_until_balanced()
    assert cycles <= 2 * SETTLE + 2
    assert fleet.counts() == [1, 1, 2, 2]
    fleet.assert_stable()


def test_starting_together_converges_too() -> None:
    for seed in range(20):
        fleet = Fleet(9, seed=seed)
        for pid in (1, 2, 3):
            fleet.join(pid)
        fleet.run_until_balanced()
        assert fleet.counts() == [3, 3, 3]
        fleet.assert_stable()
