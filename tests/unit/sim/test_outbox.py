"""The sim's collision outbox: held until acknowledged, resent on time, bounded."""

from __future__ import annotations

from common.bus import pack
from common.contract import keys
from services.sim.outbox import CollisionOutbox


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def event(seq: int) -> dict[str, object]:
    return {"stamp": 1.0, "seq": seq, "other": "wall", "x": 0.0, "y": 0.0}


def test_an_unacknowledged_event_is_resent_every_resend_period_until_acked() -> None:
    clock = Clock()
    box = CollisionOutbox(run="r", resend_s=0.5, clock=clock)
    box.sent("r1", event(0))
    assert box.due() == []  # just sent
    clock.t += 0.49
    assert box.due() == []
    clock.t += 0.01
    assert [(robot, m["seq"]) for robot, m in box.due()] == [("r1", 0)]  # 0.5 s: again
    assert box.due() == []  # marked sent now
    clock.t += 0.5
    assert len(box.due()) == 1 and box.resent == 2
    box.on_ack(keys.robot_key("r1", keys.COLLISION_ACK), pack({"run": "r", "seq": 0}))
    clock.t += 5.0
    assert box.due() == [] and box.waiting() == 0 and box.acked == 1


def test_an_ack_of_another_run_or_robot_or_a_malformed_one_changes_nothing() -> None:
    box = CollisionOutbox(run="now")
    box.sent("r1", event(3))
    key = keys.robot_key("r1", keys.COLLISION_ACK)
    box.on_ack(key, pack({"run": "before", "seq": 3}))  # a previous run's event 3
    box.on_ack(keys.robot_key("r2", keys.COLLISION_ACK), pack({"run": "now", "seq": 3}))
    box.on_ack(key, pack({"run": "now", "seq": "3"}))
    box.on_ack(key, b"\xc1 not msgpack")
    box.on_ack("not/a/robot/key/at/all", pack({"run": "now", "seq": 3}))
    assert box.waiting() == 1
    box.on_ack(key, pack({"run": "now", "seq": 3}))
    assert box.waiting() == 0


def test_beyond_the_limit_the_oldest_event_is_given_up() -> None:
    box = CollisionOutbox(run="r", limit=2)
    for seq in range(3):
        box.sent("r1", event(seq))
    assert box.waiting() == 2 and box.given_up == 1
    assert not box.ack("r1", 0)  # given up
    assert box.ack("r1", 1) and box.ack("r1", 2)


def test_each_run_has_its_own_id() -> None:
    assert CollisionOutbox().run != CollisionOutbox().run
