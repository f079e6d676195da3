"""The share arithmetic of robot leases: pure functions, no database, no clock.

Keys (the contract's ``lease_key``), the fair share of R robots among N live replicas, the
rendezvous order in which a replica tries free robots, and :func:`decide`: what one replica
takes and gives back in one cycle, from one :class:`Snapshot` of ``pg_locks``.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from dataclasses import dataclass


def lease_key(name: str) -> int:
    """The contract's ``lease_key(name)``: the first 31 bits of sha256(name), never 0."""
    digest = hashlib.sha256(name.encode()).digest()
    return max(1, int.from_bytes(digest[:4], "big") & 0x7FFFFFFF)


def fair_share(robots: int, replicas: int) -> tuple[int, int]:
    """``(floor, ceil)`` of robots per replica; every replica should own between the two."""
    n = max(1, replicas)
    return robots // n, -(-robots // n)


def affinity(instance: str, robot: str) -> int:
    """Rendezvous score: replicas try free robots in different orders (fewer collisions), and
    a replica that keeps its instance id (``controller-2``) tends to get its robots back."""
    return int.from_bytes(hashlib.sha256(f"{instance}\0{robot}".encode()).digest()[:8], "big")


@dataclass(frozen=True)
class Snapshot:
    """One cycle's view of Postgres: every robot, who holds it, who is a live replica."""

    robots: tuple[str, ...]
    holders: Mapping[str, int | None]  # robot -> backend pid holding its lock, or None
    members: frozenset[int]  # backend pids holding the membership lock
    me: int  # our lock connection's backend pid


@dataclass(frozen=True)
class Decision:
    acquire: tuple[str, ...] = ()  # free robots to try, best first
    want: int = 0  # how many of them to take
    release: tuple[str, ...] = ()  # robots to give back now
    pending: int = 0  # consecutive cycles the release condition has held
    share: tuple[int, int] = (0, 0)
    replicas: int = 1


def _counts(view: Snapshot, owned_count: int) -> dict[int, int]:
    """Robots held per live replica (backend pid); ours is what we know we own."""
    counts = dict.fromkeys(set(view.members) | {view.me}, 0)
    for robot in view.robots:
        holder = view.holders.get(robot)
        if holder is not None and holder in counts:
            counts[holder] += 1
    counts[view.me] = owned_count
    return counts


def _to_give(counts: dict[int, int], me: int, lo: int, hi: int, free: int, short: int) -> int:
    """How many robots we should give back, before hysteresis."""
    count = counts[me]
    if count > hi:
        return count - hi
    others_below = any(c < lo for pid, c in counts.items() if pid != me)
    if count > lo and others_below and free < short:
        richest = max(counts.values())
        if count == richest and me == min(p for p, c in counts.items() if c == richest):
            return 1
    return 0


def decide(
    view: Snapshot, owned: frozenset[str], instance: str, pending: int, settle_cycles: int
) -> Decision:
    """What this replica should take and give back this cycle.

    With R robots and N live replicas, ``lo, hi = fair_share(R, N)``:

    - take free robots up to ``lo``; beyond it, up to ``hi``, only those left once every
      other replica below ``lo`` could reach it (the poorer pick first);
    - give back robots above ``hi``; and, when another replica is below ``lo`` and no robot
      is free, the richest replica (ties: lowest backend pid) gives back one above ``lo``;
    - a give-back happens only when its condition has held ``settle_cycles`` cycles in a
      row (``pending`` counts them), so a replica that joins and leaves, or a transient
      view, does not make ownership flap. Taking is immediate: that is the takeover.
    """
    mine = [r for r in view.robots if r in owned]
    counts = _counts(view, len(mine))
    lo, hi = fair_share(len(view.robots), len(counts))
    count = len(mine)
    free = [
        r
        for r in view.robots
        if view.holders.get(r) is None or (view.holders.get(r) == view.me and r not in owned)
    ]
    short = sum(max(0, lo - c) for pid, c in counts.items() if pid != view.me)
    floor_need = max(0, lo - count)
    spare = len(free) - short - floor_need
    extra = max(0, min(hi - max(count, lo), spare))
    want = min(len(free), floor_need + extra)

    give = _to_give(counts, view.me, lo, hi, len(free), short)
    pending = pending + 1 if give else 0
    release: tuple[str, ...] = ()
    if give and pending >= settle_cycles:
        release = tuple(sorted(mine, key=lambda r: affinity(instance, r))[:give])
        pending = 0
    acquire = tuple(sorted(free, key=lambda r: affinity(instance, r), reverse=True))
    return Decision(acquire, want, release, pending, (lo, hi), len(counts))
